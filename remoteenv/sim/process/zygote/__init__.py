"""The zygote: a pre-imported Python process that forks a fresh sim for each launch.

Runs as its own process, started by the agent's launcher
(:mod:`remoteenv.agent.launch.zygote`) with ``python start.py``. It imports what a
sim needs (numpy, MuJoCo, Gymnasium, pyzmq, :mod:`remoteenv.sim`, and what
each scene script it serves imports at its top, see :mod:`.preload`), then
waits on its control channel (:mod:`remoteenv.wire.messages.zygote_channel`). For
each fork request it forks a child that becomes the sim exactly as
``python <scene script> <arguments>`` would (:mod:`.child`): its own
session, the launcher's stdout, its log as stderr, the launcher's pipe, the
agent's working directory, the scene's folder first on ``sys.path``, and the
script run as ``__main__``. The child builds its own ``MjModel``/``MjData``,
seeds its own RNGs and binds its own sockets: the zygote holds none of
these, so sims share nothing but the modules imported before the fork.

The zygote forks only while it is safe to: no Python thread but its own,
and no module it imported shadowed by a file in the scene's folder (which a
fresh interpreter would import instead); otherwise it refuses and the
launcher starts the sim the plain way. It is the sims' parent, but they
watch the agent (``--parent-pid``, :mod:`remoteenv.sim.process.orphan`) through the
zygote's pidfd of it, which they inherit: a sim ends with its agent, not
with the zygote. The zygote exits as soon as the agent process does (a
pidfd, not ``PR_SET_PDEATHSIG``, which fires when the launching *thread*
ends) or closes the channel.
"""
