"""Hexapod scene, agent side: registers ``remoteenv/Hexapod-v0``.

The sim side is ``hexapod_scene.py`` next to this file (its docstring gives
the observation layout, units, reward and limits), with its model in
``hexapod.xml``. ``remoteenv.controllers.hexapod_tripod`` walks it.
"""

import os

import gymnasium

ENV_ID = "remoteenv/Hexapod-v0"
SCENE_SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "hexapod_scene.py")

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="remoteenv.remote_env:OpenAIRemoteEnv",
        vector_entry_point="remoteenv.vector_env:RemoteVectorEnv",
        max_episode_steps=1000,
        kwargs={"scene": SCENE_SCRIPT},
    )
