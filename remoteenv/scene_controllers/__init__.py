"""Hand-written controllers for the shipped scenes: fixed, known-good policies (agent side).

Used by the demo, the benchmarks, the latency tools, the tests and the
examples. One module per scene: :mod:`~remoteenv.scene_controllers.cartpole`
(the LQR and its model facts), :mod:`~remoteenv.scene_controllers.reacher`,
:mod:`~remoteenv.scene_controllers.hexapod`. The delay-aware CartPole
controllers build on them in :mod:`remoteenv.latency.predictors`;
:mod:`remoteenv.controllers` offers both under one name.
"""
