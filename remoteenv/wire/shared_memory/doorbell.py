"""The fast lane's doorbell: requests and replies through a shared region,
with no system call while the other side is awake (both processes use it).

Part of the spec (:mod:`remoteenv.wire.protocol`, ``shared_batch``). A region
laid out with info columns (:mod:`remoteenv.wire.shared_memory.shared_batch`) starts its
lane blocks with 16 ``<i8`` header words, in two 64-byte lines so that each
side writes only its own:

====  ==================  ======  =============================================
word  name                writer  meaning
====  ==================  ======  =============================================
0     ``REQ_SEQ``         agent   ``seq`` of the last request posted (0: none)
1     ``REQ_N``           agent   positions of that request (``1 .. K``)
2     ``REQ_NAMED``       agent   1: the ``worlds`` block names its worlds
3     ``AGENT_WATCHING``  agent   1: the agent will look at ``REP_SEQ`` before
                                  it blocks (no wake-up frame needed)
4     ``AGENT_THINK_US``  agent   microseconds from the agent's previous
                                  vector step returning to its caller to this
                                  request (its think time), told when its
                                  sims take every CPU it may use (0: not
                                  told); a hint for the sim's waits, never
                                  checked
5     ``AGENT_HEADS_UP``  agent   1 (only while ``AGENT_WATCHING`` is 0): wake
                                  the agent with ``{"seq": s, "soon": true}``
                                  once the request's physics is done
6     ``AGENT_AWAY``      agent   1: the agent's caller has begun a long
                                  think (its learner's update) after the
                                  last reply; cleared with the next request.
                                  A hint: a sim waiting hot for that request
                                  stops and blocks
8     ``REP_SEQ``         sim     ``seq`` of the last request answered in the
                                  region
9     ``REP_INFO``        sim     the info layout version of that answer
10    ``SIM_WATCHING``    sim     1: the sim will look at ``REQ_SEQ`` before
                                  it blocks (no request frame needed)
====  ==================  ======  =============================================

A request: the agent writes ops, worlds and actions, then ``REQ_N``,
``REQ_NAMED`` and ``AGENT_THINK_US``, then ``REQ_SEQ``; if ``SIM_WATCHING``
is 0 it also sends ``{"seq": s, "cmd": "step_batch", "region": true}`` on
the pipe. A reply in the region: the sim
writes the arrays and info columns, then ``REP_INFO``, then ``REP_SEQ``; if
``AGENT_WATCHING`` is 0 it also sends ``{"seq": s, "ok": true, "region":
true}``. Any other reply (an error, a reset, infos that are not the announced
columns) goes on the pipe as usual and leaves ``REP_SEQ`` alone. Before a
side blocks it clears its ``*_WATCHING`` word and looks once more: the
store, a full fence, then the load, on both sides (Dekker's pattern), so at
least one of "the peer sees the flag cleared" and "we see its sequence word"
holds and no request or reply is left unseen. A request's frame for a request
already served is dropped, and so is a wake-up frame for a reply already read.

Heads-up. An agent about to block on one sim's pipe for a region reply (not
in a poll over several pipes) sets ``AGENT_HEADS_UP`` as it clears ``AGENT_WATCHING``; the sim,
when the request's physics is done and it finds both so, sends
``{"seq": s, "soon": true}`` and goes on with the tick. The agent's wake-up
(tens of microseconds on a virtual machine, more after an idle CPU) then
overlaps the tick's hooks, checks and answer instead of following them; the
woken agent watches again and waits hot, for a bounded time, for the reply.
The reply and its frame follow the rules above unchanged: a heads-up answers
nothing. It may come late (sent just as the agent's blocked read timed out,
read by a later look): the agent drops it wherever it reads it and keeps
watching ``REP_SEQ``, since the sim, finding the agent awake, answers with
no frame.

Ordering. The data are written before the sequence word and read after it,
with a fence between (:func:`fence`: a lock taken and released, an atomic
read-modify-write). Reading the sequence words without the pipe's help
relies on the processor keeping stores in order and loads in order (total
store order: x86-64). Elsewhere :data:`SILENT` is False: every request and
reply then also goes as its frame, and the reader waits for the frame (the
kernel's socket locks order the region's accesses, as for the plain region).
A loud side never sets its ``*_WATCHING`` word, so a silent peer always
sends it frames too: the two ends need not agree on :data:`SILENT`.

Tampering. Each side checks the header against what both sides can have
written (:meth:`Doorbell.agent_tampered`, :meth:`Doorbell.sim_tampered`):
its own words hold what it last wrote, the peer's hold values the protocol
allows (flags 0 or 1, a reply only to a request that was posted, a request
``seq`` no further than :data:`MAX_SEQ_GAP` past the last one served). A
side that finds the header otherwise stops using the region (the sim writes
:data:`POISONED` into ``REP_SEQ`` so that the agent sees it too) and both
go back to plain frames on the pipe.
"""

from __future__ import annotations

import os
import platform
import threading

import numpy as np

REQ_SEQ, REQ_N, REQ_NAMED, AGENT_WATCHING, AGENT_THINK_US, AGENT_HEADS_UP, AGENT_AWAY = 0, 1, 2, 3, 4, 5, 6
REP_SEQ, REP_INFO, SIM_WATCHING = 8, 9, 10
#: ``REP_SEQ`` of a region the sim stopped using: it found the header tampered with.
POISONED = -1
#: Furthest a posted request's ``seq`` may lie past the last one the sim served
#: (the agent's other requests in between also take sequence numbers).
MAX_SEQ_GAP = 1 << 20

#: Largest ``AGENT_THINK_US`` either side writes or believes (an hour).
MAX_THINK_US = 3_600_000_000

#: Whether this processor keeps stores and loads in order (total store order),
#: so that a sequence word read from shared memory can vouch for the data
#: written before it; elsewhere, or with ``REMOTEENV_LOUD_DOORBELL`` set, every
#: message also goes as a frame on the pipe.
SILENT = platform.machine().lower() in ("x86_64", "amd64", "i386", "i686") and not os.environ.get(
    "REMOTEENV_LOUD_DOORBELL"
)

_fence_lock = threading.Lock()


def fence() -> None:
    """A full memory fence: a lock taken and released (an atomic read-modify-write each)."""
    _fence_lock.acquire()
    _fence_lock.release()


class Doorbell:
    """One side's view of a region's header words (``header``: 16 ``<i8``).

    ``silent`` (default :data:`SILENT`, read when the doorbell is made): whether
    the sequence words may be read without waiting for frames."""

    def __init__(self, header: np.ndarray, silent: bool | None = None) -> None:
        self._words = memoryview(header).cast("B").cast("q")  # type: ignore[arg-type]
        #: Whether the sequence words may be read without waiting for frames.
        self.silent = SILENT if silent is None else bool(silent)
        #: The value this side's ``*_WATCHING`` word takes while it is awake (0 when loud).
        self._watching = 1 if self.silent else 0
        # What each side last wrote into its sequence words (as found when this view was made).
        self._posted = int(self._words[REQ_SEQ])
        self._replied = (int(self._words[REP_SEQ]), int(self._words[REP_INFO]))
        self._away = int(self._words[AGENT_AWAY])

    def word(self, index: int) -> int:
        return int(self._words[index])

    # ------------------------------------------------------------ agent side

    def post(self, seq: int, n: int, named: bool, think_s: float = 0.0) -> bool:
        """Publish request ``seq`` (its blocks written); True if the sim must be
        rung (it sleeps, or the doorbell is not silent). ``think_s``: seconds
        from the agent's previous vector step returning to its caller to this
        request (0: not told), written as ``AGENT_THINK_US``."""
        words = self._words
        words[REQ_N] = n
        words[REQ_NAMED] = 1 if named else 0
        words[AGENT_THINK_US] = min(max(int(think_s * 1e6), 0), MAX_THINK_US)
        words[AGENT_WATCHING] = self._watching
        words[AGENT_AWAY] = self._away = 0
        fence()
        words[REQ_SEQ] = seq
        self._posted = seq
        if not self.silent:
            return True
        fence()
        return not words[SIM_WATCHING]

    def agent_tampered(self) -> str | None:
        """Agent side, between requests: why the header is not what the two
        sides can have written (None if it is)."""
        words = self._words
        if words[REP_SEQ] == POISONED:
            return "the sim found it tampered with"
        if words[REQ_SEQ] != self._posted:
            return f"its request sequence word holds {int(words[REQ_SEQ])}, not the {self._posted} posted last"
        if not 0 <= words[REP_SEQ] <= self._posted:
            return f"its reply sequence word holds {int(words[REP_SEQ])}, beyond the last request posted"
        if words[AGENT_WATCHING] not in (0, 1) or words[SIM_WATCHING] not in (0, 1):
            return "its watching flags hold values other than 0 and 1"
        if words[AGENT_HEADS_UP] != 0:
            return f"its heads-up word holds {int(words[AGENT_HEADS_UP])} between requests, not the 0 written last"
        if words[AGENT_AWAY] != self._away:
            return f"its away word holds {int(words[AGENT_AWAY])}, not the {self._away} written last"
        if words[REP_INFO] < 0:
            return f"its info layout word holds {int(words[REP_INFO])}"
        return None

    def answered(self, seq: int) -> bool:
        """Whether the region holds the reply to ``seq`` (then its blocks may be read)."""
        if self.silent and self._words[REP_SEQ] == seq:
            fence()
            return True
        return False

    def agent_sleeps(self, seq: int, heads_up: bool = False) -> bool:
        """The agent is about to block waiting for ``seq``: False (and still
        watching) if the reply is there after all. ``heads_up``: ask the sim
        for ``{"seq": seq, "soon": true}`` once the request's physics is done
        (silent doorbells only)."""
        words = self._words
        if heads_up and self.silent:
            words[AGENT_HEADS_UP] = 1
        words[AGENT_WATCHING] = 0
        fence()
        if self.answered(seq):
            self.agent_wakes()
            return False
        return True

    def away(self) -> None:
        """Agent side, between requests: its caller has begun a long think (``AGENT_AWAY``)."""
        self._words[AGENT_AWAY] = self._away = 1

    def agent_wakes(self) -> None:
        words = self._words
        words[AGENT_WATCHING] = self._watching
        words[AGENT_HEADS_UP] = 0

    # ------------------------------------------------------------ sim side

    def posted(self, served: int) -> int:
        """``seq`` of a request posted since ``served`` (0: none), its blocks
        readable. A ``seq`` further than :data:`MAX_SEQ_GAP` past ``served`` is no
        request the agent can have posted: see :meth:`sim_tampered`."""
        if not self.silent:
            return 0
        seq = self._words[REQ_SEQ]
        if served < seq <= served + MAX_SEQ_GAP:  # seq numbers increase: an older one is not a request
            fence()
            return int(seq)
        return 0

    def sim_tampered(self, served: int) -> str | None:
        """Sim side: why the header is not what the two sides can have written
        (None if it is); ``served`` is the last request taken from the region."""
        words = self._words
        if (words[REP_SEQ], words[REP_INFO]) != self._replied:
            return f"its reply words hold {int(words[REP_SEQ])}, {int(words[REP_INFO])}, not what this sim wrote"
        seq = words[REQ_SEQ]
        if seq < 0 or seq > served + MAX_SEQ_GAP:
            return f"its request sequence word holds {int(seq)}, no request the agent can have posted"
        if (
            words[AGENT_WATCHING] not in (0, 1)
            or words[SIM_WATCHING] not in (0, 1)
            or words[AGENT_HEADS_UP] not in (0, 1)
            or words[AGENT_AWAY] not in (0, 1)
        ):
            return "its watching flags hold values other than 0 and 1"
        if not 0 <= words[REQ_N] <= 1 << 16 or words[REQ_NAMED] not in (0, 1):
            return "its request size words hold values no request has"
        return None

    def poison(self) -> None:
        """Sim side: stop using the region; the agent sees :data:`POISONED` and stops too."""
        words = self._words
        words[SIM_WATCHING] = 0
        words[REP_SEQ] = POISONED

    def agent_think_s(self) -> float:
        """Sim side: ``AGENT_THINK_US`` of the request just taken, in seconds
        (0: not told; a hint, read as found: clamped to ``0 .. MAX_THINK_US``)."""
        return min(max(int(self._words[AGENT_THINK_US]), 0), MAX_THINK_US) * 1e-6

    def agent_away(self) -> bool:
        """Sim side: whether the agent said its caller began a long think after
        the last reply (``AGENT_AWAY``; a hint, read as found)."""
        return self._words[AGENT_AWAY] == 1

    def request(self) -> tuple[int, int, int]:
        """``(REQ_SEQ, REQ_N, REQ_NAMED)`` as they are now (after the request's frame)."""
        words = self._words
        seq = int(words[REQ_SEQ])
        fence()
        return seq, int(words[REQ_N]), int(words[REQ_NAMED])

    def sim_sleeps(self, served: int) -> int:
        """The sim is about to block: clear ``SIM_WATCHING``, then look once
        more; returns a request's ``seq`` that came meanwhile (and watches again), or 0."""
        words = self._words
        words[SIM_WATCHING] = 0
        fence()
        seq = self.posted(served)
        if seq:
            words[SIM_WATCHING] = self._watching
        return seq

    def agent_wants_heads_up(self) -> bool:
        """Sim side: whether the agent sleeps and asked to be woken once the
        physics of the request it waits for is done (``AGENT_HEADS_UP``)."""
        words = self._words
        return self.silent and words[AGENT_WATCHING] == 0 and words[AGENT_HEADS_UP] == 1

    def sim_watches(self) -> None:
        """The sim is awake and will look before it blocks."""
        self._words[SIM_WATCHING] = self._watching

    def reply(self, seq: int, info_version: int) -> bool:
        """Publish the region's reply to ``seq`` (its blocks written); True if the
        agent must be woken (it sleeps, or the doorbell is not silent)."""
        words = self._words
        words[SIM_WATCHING] = self._watching
        words[REP_INFO] = info_version
        fence()
        words[REP_SEQ] = seq
        self._replied = (seq, info_version)
        if not self.silent:
            return True
        fence()
        return not words[AGENT_WATCHING]


__all__ = [
    "AGENT_AWAY",
    "AGENT_HEADS_UP",
    "AGENT_THINK_US",
    "AGENT_WATCHING",
    "MAX_SEQ_GAP",
    "MAX_THINK_US",
    "POISONED",
    "REP_INFO",
    "REP_SEQ",
    "REQ_N",
    "REQ_NAMED",
    "REQ_SEQ",
    "SILENT",
    "SIM_WATCHING",
    "Doorbell",
    "fence",
]
