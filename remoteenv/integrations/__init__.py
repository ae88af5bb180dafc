"""remoteenv in other libraries' hands: runs in the agent process.

- :mod:`~remoteenv.integrations.sb3`: Stable-Baselines3's ``VecEnv`` over a vector env;
- :mod:`~remoteenv.integrations.torchrl`: a batched TorchRL env;
- :mod:`~remoteenv.integrations.rllib`: the ids in RLlib's env runners;
- :mod:`~remoteenv.integrations.frame_dataset`: rendered frames streamed into a torch ``DataLoader``;
- :mod:`~remoteenv.integrations.ray`: an env's sims placed on a Ray cluster (a ``SimGroup``).

Each imports its library on import; nothing here is imported by ``import remoteenv``.
"""
