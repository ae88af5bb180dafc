"""Stream rendered frames from sim processes into a torch ``DataLoader``.

Runs in the agent process (and in the DataLoader's worker processes). The sim
side is :mod:`remoteenv.sim.publisher`: each publisher instance drives and
renders its own world and sends ``{"instance", "index", "episode", "step",
"frame", "labels"}`` items (msgpack, see that module), one for each item its
reader asks for.

How items are split between workers: DataLoader worker ``w`` of ``W`` reads
the publishers ``i`` with ``i % W == w``, each over its own socket, so every
publisher has exactly one reader and no item is read twice. Workers that got
no publisher (``num_workers`` > publishers) yield nothing.

Passes (epochs): with ``items_per_publisher`` set, a pass over the dataset
reads exactly that many items from each publisher, and the dataset can be
iterated any number of times. **A new pass continues the stream**: it reads
each publisher's next items (fresh frames of the world as it goes on), it
does not replay earlier ones. Readers ask for items as they read them
(credit, at most :data:`~remoteenv.wire.messages.stream_credit.WINDOW` ahead) and a pass
asks for no more than it reads, so a pass that runs to its end leaves
nothing in flight: the next pass starts at the index where it stopped. A
pass left early (``break``, an exception) drops what it had asked for and not
read (at most ``WINDOW`` items per publisher): the next pass then starts at a
later index. Within a pass each publisher's ``index`` must follow the
previous one; a gap raises (nothing is lost silently). Without
``items_per_publisher`` a pass is endless.

Usage::

    from torch.utils.data import DataLoader
    from remoteenv.integrations.frame_dataset import RemoteIterableDataset, launch_publishers

    with launch_publishers("cartpole", num_instances=2, items_per_instance=64,
                           width=160, height=120, seed=0) as pubs:
        loader = DataLoader(RemoteIterableDataset.from_publishers(pubs),
                            batch_size=16, num_workers=2)
        for epoch in range(3):          # each epoch: the next 64 frames of each publisher
            for batch in loader:
                batch["frame"]   # uint8 tensor B x H x W x 3
                batch["labels"]  # the scene's labels, collated
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import torch
import torch.utils.data
import zmq

from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout
from remoteenv.agent.launch.launcher import Launcher
from remoteenv.agent.launch.processes import pid_alive
from remoteenv.wire import protocol
from remoteenv.wire.messages.stream_credit import WINDOW, credit_message, is_superseded
from remoteenv.wire.wire_errors import short_repr

_POLL_MS = 100


class Publishers:
    """Frame-publisher sim processes started by :func:`launch_publishers`.

    Stop them with :meth:`close` (or use as a context manager); they are also
    stopped when this object is garbage collected or the interpreter exits.
    """

    def __init__(self, launcher: Launcher, items_per_instance: int | None) -> None:
        #: Items each publisher contributes to one pass of :meth:`RemoteIterableDataset.from_publishers`.
        self.launcher = launcher
        self.items_per_instance = items_per_instance

    @property
    def endpoints(self) -> list[str]:
        return self.launcher.endpoints

    @property
    def pids(self) -> list[int]:
        return self.launcher.pids

    def close(self) -> None:
        self.launcher.close()

    def __enter__(self) -> Publishers:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def launch_publishers(
    scene: str | os.PathLike[str],
    num_instances: int = 1,
    *,
    items_per_instance: int | None = None,
    seed: int | None = None,
    episode_steps: int = 100,
    quality: bool = False,
    startup_timeout: float = 60.0,
    **env_kwargs: Any,
) -> Publishers:
    """Start ``num_instances`` frame publishers of ``scene``.

    Args:
        scene: a shipped scene name (``"cartpole"``) or the path of a scene script.
        items_per_instance: frames each publisher contributes to one pass over
            :meth:`RemoteIterableDataset.from_publishers` (None: endless passes);
            publishers themselves stream for as long as they are read.
        seed: publisher ``i`` uses ``seed + i`` for resets and random actions.
        episode_steps: control ticks per episode before the publisher resets.
        quality: render frames at the MJCF's quality (4x multisampling and a
            shadow map by MuJoCo's default: ~50x the time of a frame under
            software OpenGL); False (the default): without them, as camera
            observations are rendered.
        env_kwargs: keyword arguments of the scene's env class, e.g. ``width``, ``height``.
    """
    from remoteenv import scene_path
    from remoteenv.sim import publisher

    script = os.fspath(scene)
    if os.sep not in script and not script.endswith(".py"):
        script = scene_path(script)
    extra = ["--scene", os.path.abspath(script), "--episode-steps", str(int(episode_steps))]
    if quality:
        extra.append("--quality")
    if items_per_instance is not None and items_per_instance < 1:
        raise ValueError(f"items_per_instance must be >= 1 or None, got {items_per_instance}")
    launcher = Launcher(
        publisher.__file__,
        num_instances,
        seed=seed,
        env_kwargs=env_kwargs,
        startup_timeout=startup_timeout,
        extra_args=extra,
    )
    return Publishers(launcher, items_per_instance)


class RemoteIterableDataset(torch.utils.data.IterableDataset):
    """Items sent by frame publishers, read without duplicates or loss.

    Args:
        endpoints: the publishers' bound endpoints.
        items_per_publisher: items one pass reads from each publisher (None:
            endless); each pass reads the next ones (see the module docstring).
        pids: the publishers' process ids, when they run on this machine; a
            publisher whose process is gone raises :class:`RemoteEnvError`
            within ~0.1 s instead of waiting for ``timeout``.
        timeout: seconds without an item from any of a worker's publishers
            before :class:`RemoteEnvTimeout`.
        transform: applied to each item (a dict) before it is yielded.

    Each yielded item is a dict: ``frame`` (uint8 numpy array H x W x 3; the
    default collate turns a batch into a B x H x W x 3 tensor), ``labels``,
    ``instance``, ``index``, ``episode``, ``step``.
    """

    def __init__(
        self,
        endpoints: Sequence[str],
        *,
        items_per_publisher: int | None = None,
        pids: Sequence[int] | None = None,
        timeout: float = 60.0,
        transform: Callable[[dict[str, Any]], Any] | None = None,
    ) -> None:
        super().__init__()
        if not endpoints:
            raise ValueError("RemoteIterableDataset needs at least one publisher endpoint")
        if pids is not None and len(pids) != len(endpoints):
            raise ValueError(f"got {len(pids)} pids for {len(endpoints)} endpoints")
        self.endpoints = list(endpoints)
        self.items_per_publisher = items_per_publisher
        self.pids = list(pids) if pids is not None else None
        self.timeout = timeout
        self.transform = transform

    @classmethod
    def from_publishers(cls, publishers: Publishers, **kwargs: Any) -> RemoteIterableDataset:
        """The dataset reading the publishers :func:`launch_publishers` started."""
        kwargs.setdefault("items_per_publisher", publishers.items_per_instance)
        return cls(publishers.endpoints, pids=publishers.pids, **kwargs)

    def __len__(self) -> int:
        if self.items_per_publisher is None:
            raise TypeError("an endless RemoteIterableDataset has no length")
        return self.items_per_publisher * len(self.endpoints)

    def assigned_publishers(self) -> list[int]:
        """Indices of the publishers the calling DataLoader worker reads."""
        info = torch.utils.data.get_worker_info()
        if info is None:
            return list(range(len(self.endpoints)))
        return list(range(info.id, len(self.endpoints), info.num_workers))

    def __iter__(self) -> Iterator[Any]:
        mine = self.assigned_publishers()
        if not mine:
            return
        # A fresh context: one inherited through fork must not be used.
        ctx = zmq.Context()
        sockets: dict[zmq.Socket, int] = {}
        try:
            poller = zmq.Poller()
            for i in mine:
                sock = ctx.socket(zmq.DEALER)
                sock.setsockopt(zmq.RCVHWM, 2 * WINDOW)
                sock.setsockopt(zmq.LINGER, 0)
                sock.setsockopt(zmq.MAXMSGSIZE, protocol.MAX_MESSAGE_BYTES)
                sock.connect(self.endpoints[i])
                poller.register(sock, zmq.POLLIN)
                sockets[sock] = i
            streams = {i: _Stream(self.items_per_publisher) for i in mine}
            for sock, i in sockets.items():
                streams[i].grant(sock)
            last_item = last_check = time.monotonic()
            while any(not stream.done for stream in streams.values()):
                ready = dict(poller.poll(_POLL_MS))
                now = time.monotonic()
                if now - last_check >= _POLL_MS / 1000:
                    self._check_alive(streams, skip={sockets[s] for s in ready})
                    last_check = now
                if not ready:
                    if now - last_item > self.timeout:
                        received = {i: stream.received for i, stream in streams.items()}
                        raise RemoteEnvTimeout(
                            f"no frame from publishers {sorted(received)} for {self.timeout:g} s "
                            f"(received in this pass: {received}); they are alive but silent. Raise "
                            "timeout= if rendering is slow on this machine.",
                            kind="timeout",
                        )
                    continue
                for sock in ready:
                    i = sockets[sock]
                    stream = streams[i]
                    item = self._decode(sock.recv(copy=True), i, stream.next_index)
                    stream.took(item["index"])
                    if stream.done:
                        poller.unregister(sock)
                    else:
                        stream.grant(sock)
                    last_item = time.monotonic()
                    yield self.transform(item) if self.transform is not None else item
        finally:
            for sock in sockets:
                sock.close(linger=0)
            ctx.term()

    def _decode(self, frame: bytes, i: int, expected: int | None) -> dict[str, Any]:
        """Publisher ``i``'s item; ``expected``: the index it must have (None: any, the pass's first)."""
        try:
            item = protocol.unpack(frame)
        except protocol.ProtocolError as exc:
            raise RemoteEnvError(
                f"publisher {i} ({self.endpoints[i]}) sent an undecodable item: {exc}", kind="protocol", instance=i
            ) from None
        if is_superseded(item):
            raise RemoteEnvError(
                f"publisher {i} ({self.endpoints[i]}): another reader is reading it too and took it over "
                "(the newest reader is served); read each publisher from exactly one RemoteIterableDataset "
                "at a time",
                kind="protocol",
                instance=i,
            )
        if not isinstance(item, dict) or "frame" not in item or "index" not in item:
            raise RemoteEnvError(
                f"publisher {i} ({self.endpoints[i]}) sent an item that is not a frame map", kind="protocol", instance=i
            )
        index = item["index"]
        if type(index) is not int or index < 0 or (expected is not None and index != expected):
            raise RemoteEnvError(
                f"publisher {i} ({self.endpoints[i]}) sent item {short_repr(index)} where "
                f"{'a first index' if expected is None else expected} was due: items were lost or "
                "another reader is reading it too (read each publisher from exactly one "
                "RemoteIterableDataset at a time)",
                kind="protocol",
                instance=i,
            )
        return item

    def _check_alive(self, streams: dict[int, _Stream], skip: set[int]) -> None:
        """Raise if a publisher that still owes items (and has none queued) is gone."""
        if self.pids is None:
            return
        for i, stream in streams.items():
            if i in skip or stream.done or pid_alive(self.pids[i]):
                continue
            due = "" if self.items_per_publisher is None else f" of {self.items_per_publisher}"
            raise RemoteEnvError(
                f"frame publisher {i} (pid {self.pids[i]}, {self.endpoints[i]}) vanished after "
                f"{stream.received}{due} items of this pass; its process is gone. Relaunch the publishers "
                "(see the launcher's log for why it exited).",
                kind="died",
                instance=i,
            )


class _Stream:
    """One publisher's part of a pass: what was read, what was asked for."""

    def __init__(self, quota: int | None) -> None:
        self.quota = quota
        self.received = 0
        self.asked = 0
        #: The index the next item must have (None until the pass's first item).
        self.next_index: int | None = None

    @property
    def done(self) -> bool:
        return self.quota is not None and self.received >= self.quota

    def took(self, index: int) -> None:
        self.received += 1
        self.next_index = index + 1

    def grant(self, sock: zmq.Socket) -> None:
        """Ask for more items once half the window is read, never beyond the quota."""
        in_flight = self.asked - self.received
        if in_flight > WINDOW // 2:
            return
        want = WINDOW - in_flight
        if self.quota is not None:
            want = min(want, self.quota - self.asked)
        if want > 0:
            sock.send(credit_message(want), zmq.NOBLOCK)
            self.asked += want


__all__ = ["Publishers", "RemoteIterableDataset", "launch_publishers"]
