"""How many CPU threads torch keeps in a process whose vector env's sims use its CPUs.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`). Torch's
intra-op pool (OpenMP) has one thread per CPU by default, and after each
parallel operation its idle threads keep spinning for a while (milliseconds)
before they sleep. In a training loop every policy inference is followed by
a vector step, so while the sims step, those spinning threads hold CPUs the
sims need: with as many sim processes as CPUs the vector step takes about a
third longer. With ``torch_threads="auto"`` (the default) the vector env
lowers torch's thread count, once, to the CPUs its local sims leave free
(at least one), and says so in a :class:`TorchThreadsNotice` warning; it
never sets more threads than torch had, and leaves torch alone when the user set
``OMP_NUM_THREADS`` or asked for ``torch_threads=None``. Where it lowered
them it gives them back for the learner's update, when that measures faster
(:mod:`remoteenv.agent.vector.update_threads`), and the warning says so too.
An int sets that many threads (the user's explicit choice, applied without
a warning). Measured gain: docs/performance.md ("The learner beside the sims").
"""

from __future__ import annotations

import os
import sys
import types
import warnings
from collections.abc import Callable

from remoteenv.agent.vector.update_threads import UpdateThreads, openmp_pause
from remoteenv.wire.shared_memory.hot_wait import usable_cpus

#: ``torch_threads`` values besides an int.
AUTO = "auto"


class TorchThreadsNotice(UserWarning):
    """remoteenv changed torch's thread count (see :mod:`remoteenv.agent.vector.torch_threads`)."""


class _Applied:
    """Process-wide: whether "auto" lowered torch's threads already (it acts once)."""

    done = False


def check_torch_threads(value: object) -> int | str | None:
    """``value`` if it is a valid ``torch_threads`` (``"auto"``, None or an int >= 1), else a ValueError."""
    if value is None or value == AUTO:
        return value
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"torch_threads must be 'auto', None or an int >= 1, got {value!r:.80}")
    return value


class TorchThreads:
    """The ``torch_threads`` choice of one vector env whose sims step on
    ``local_sims`` of this machine's CPUs (a process each, or the threads of
    a process that steps its physics on several); :meth:`apply` acts on it
    when torch is loaded (at the env's construction and at each ``reset``)."""

    def __init__(self, choice: int | str | None, local_sims: int, away: Callable[[], None] | None = None) -> None:
        self.choice = check_torch_threads(choice)
        self.local_sims = local_sims
        self._pending = choice is not None and not (choice == AUTO and local_sims == 0)
        #: Tells the local sims the caller's update has begun (the doorbell's ``AGENT_AWAY``).
        self._away = away
        #: The update's threads, once "auto" lowered torch's (None: not managed).
        self.update: UpdateThreads | None = None

    def apply(self) -> None:
        """Set torch's threads as chosen, if torch is loaded and it was not done yet."""
        if not self._pending:
            return
        torch = sys.modules.get("torch")
        if torch is None or not hasattr(torch, "set_num_threads"):
            return  # not loaded (yet): looked at again at the next reset
        self._pending = False
        if isinstance(self.choice, int):
            torch.set_num_threads(self.choice)
            return
        if _Applied.done or os.environ.get("OMP_NUM_THREADS"):
            return
        _Applied.done = True
        cpus = usable_cpus()
        now = torch.get_num_threads()
        target = max(1, cpus - self.local_sims)
        if now <= target:
            return
        torch.set_num_threads(target)
        torch_file = getattr(torch, "__file__", None)
        pause = openmp_pause(os.path.dirname(torch_file) if torch_file else None) if self._away is not None else None
        back = ""
        if pause is not None and self._away is not None:
            self.update = UpdateThreads(torch, target, now, pause, self._away)
            back = (
                f"; it gives them back ({now}) for your learner's update (the long pause after as many "
                "steps as the last two rollouts) when that runs faster"
            )
        warnings.warn(
            f"remoteenv set torch's CPU threads to {target} (was {now}): this vector env's sims step on "
            f"{self.local_sims} of this machine's {cpus} CPUs, where torch's idle threads would spin{back} "
            "(docs/performance.md, 'The learner beside the sims'). To keep torch's setting, pass "
            "torch_threads=None to the vector env or set OMP_NUM_THREADS.",
            TorchThreadsNotice,
            stacklevel=_user_stacklevel(),
        )

    def step_starts(self) -> None:
        """A vector step starts (see :meth:`UpdateThreads.step_starts`)."""
        if self.update is not None:
            self.update.step_starts()

    def step_returns(self) -> None:
        """A vector step returns to the caller (see :meth:`UpdateThreads.step_returns`)."""
        if self.update is not None:
            self.update.step_returns()

    def interrupted(self) -> None:
        """A reset or close (see :meth:`UpdateThreads.interrupted`)."""
        if self.update is not None:
            self.update.interrupted()


#: Packages whose frames stand between the user's call and :meth:`TorchThreads.apply`
#: (``gym.make_vec`` / ``gym.make``, the vector env's constructor or ``reset``).
_LIBRARY_DIRS = tuple(
    os.path.dirname(os.path.abspath(module.__file__)) + os.sep
    for module in (sys.modules["remoteenv"], sys.modules.get("gymnasium"))
    if module is not None and module.__file__
)


def _user_stacklevel() -> int:
    """The ``stacklevel`` that names the user's line (the first frame outside
    remoteenv and Gymnasium) for a warning raised in the caller of this."""
    frame: types.FrameType | None = sys._getframe(2)  # the caller's caller
    level = 2
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_LIBRARY_DIRS):
        frame = frame.f_back
        level += 1
    return level


__all__ = ["AUTO", "TorchThreads", "TorchThreadsNotice", "check_torch_threads"]
