"""Zygotes on the agent side: pre-imported processes that fork this agent's sims.

Runs in the agent process. Starting a sim the plain way (``python <scene
script>``) spends most of its time importing numpy, MuJoCo, Gymnasium and
pyzmq. A zygote (:mod:`remoteenv.sim.process.zygote`) has imported them once; the
launcher asks it to fork each sim instead, and a forked sim is serving in
milliseconds. Each sim is still a fresh process with its own ``MjModel``,
``MjData``, RNGs and sockets.

- :mod:`.registry`: the zygotes of this process, one per sim environment
  (:func:`~.registry.zygote_for`, :func:`~.registry.prestart`; the
  ``REMOTEENV_ZYGOTE=0`` switch).
- :mod:`.process`: one zygote process and its fork requests.
- :mod:`.forked`: the handle of a forked sim (a ``Popen`` look-alike).
"""

from remoteenv.agent.launch.zygote.forked import ForkedProcess
from remoteenv.agent.launch.zygote.process import Zygote, ZygoteUnavailable
from remoteenv.agent.launch.zygote.registry import SWITCH, enabled, prestart, zygote_for

__all__ = ["SWITCH", "ForkedProcess", "Zygote", "ZygoteUnavailable", "enabled", "prestart", "zygote_for"]
