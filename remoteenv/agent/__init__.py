"""Agent-process machinery under the env classes: connections to sims, the
:class:`~remoteenv.agent.launch.sim_group.SimGroup` seam and its local and attach
implementations, the session (launch or attach, handshake, restarts, close),
and the agent's errors. Imports :mod:`remoteenv.wire`, never :mod:`remoteenv.sim`.
"""
