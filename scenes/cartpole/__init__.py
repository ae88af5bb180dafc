"""CartPole scene, agent side: registers ``remoteenv/CartPole-v0``.

The sim side is ``cartpole_scene.py`` next to this file, with its model in
``cartpole.xml``.
"""

import os

import gymnasium

ENV_ID = "remoteenv/CartPole-v0"
SCENE_SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "cartpole_scene.py")

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="remoteenv.remote_env:OpenAIRemoteEnv",
        vector_entry_point="remoteenv.vector_env:RemoteVectorEnv",
        max_episode_steps=500,
        reward_threshold=475.0,
        kwargs={"scene": SCENE_SCRIPT},
    )
