"""The agent-side latency tools: runs in the agent process.

- :mod:`~remoteenv.latency.action_history`: the delay-aware observation wrappers
  (the actions in flight, alpha, omega);
- :mod:`~remoteenv.latency.predictors`: CartPole controllers that predict
  through the actions in flight;
- :mod:`~remoteenv.latency.twin`: a real-time run's exact twin (record, save, replay, compare);
- :mod:`~remoteenv.latency.study`: the delay-effect study behind ``python -m remoteenv latency-study``;
- :mod:`~remoteenv.latency.sweep`: a policy's return across delays, behind ``python -m remoteenv latency-sweep``.

The delay specs and the lock-step delay engine are shared by both processes and
live in :mod:`remoteenv.wire.delays` (public face: :mod:`remoteenv.delays`); the
run options that carry them to a sim in :mod:`remoteenv.wire.run_options`.
"""
