"""Reacher scene, agent side: registers ``remoteenv/Reacher-v0``.

The sim side is ``reacher_scene.py`` next to this file, with its model in
``reacher.xml``.
"""

import os

import gymnasium

ENV_ID = "remoteenv/Reacher-v0"
SCENE_SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "reacher_scene.py")

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="remoteenv.remote_env:OpenAIRemoteEnv",
        vector_entry_point="remoteenv.vector_env:RemoteVectorEnv",
        max_episode_steps=50,
        kwargs={"scene": SCENE_SCRIPT},
    )
