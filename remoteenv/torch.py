"""Stream rendered frames from sim processes into a torch ``DataLoader``.

Runs in the agent process (and in the DataLoader's worker processes). The sim
side is :mod:`remoteenv.sim.publisher`: each publisher instance renders its
world offscreen and PUSHes ``{"instance", "index", "episode", "step", "frame",
"labels"}`` items (msgpack, see that module).

How items are split between workers: DataLoader worker ``w`` of ``W`` reads
the publishers ``i`` with ``i % W == w``, each over its own PULL socket, so
every publisher has exactly one reader and no item is read twice. Each item's
``index`` must follow the previous one from the same publisher; a gap raises
(nothing is lost silently). With ``items_per_publisher`` set, a pass over the
dataset ends after exactly that many items from each publisher; workers that
got no publisher (``num_workers`` > publishers) yield nothing. Without it the
stream is endless.

Usage::

    from torch.utils.data import DataLoader
    from remoteenv.torch import RemoteIterableDataset, launch_publishers

    with launch_publishers("cartpole", num_instances=2, items_per_instance=64,
                           width=160, height=120, seed=0) as pubs:
        loader = DataLoader(RemoteIterableDataset.from_publishers(pubs),
                            batch_size=16, num_workers=2)
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
from remoteenv.agent.launcher import Launcher
from remoteenv.agent.processes import pid_alive
from remoteenv.wire import protocol

#: Frames a reader's PULL socket buffers per publisher.
RECV_HWM = 8
_POLL_MS = 100


class Publishers:
    """Frame-publisher sim processes started by :func:`launch_publishers`.

    Stop them with :meth:`close` (or use as a context manager); they are also
    stopped when this object is garbage collected or the interpreter exits.
    """

    def __init__(self, launcher: Launcher, items_per_instance: int | None) -> None:
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
    startup_timeout: float = 60.0,
    **env_kwargs: Any,
) -> Publishers:
    """Start ``num_instances`` frame publishers of ``scene``.

    Args:
        scene: a shipped scene name (``"cartpole"``) or the path of a scene script.
        items_per_instance: frames each publisher produces (None: endless).
        seed: publisher ``i`` uses ``seed + i`` for resets and random actions.
        episode_steps: control ticks per episode before the publisher resets.
        env_kwargs: keyword arguments of the scene's env class, e.g. ``width``, ``height``.
    """
    from remoteenv import scene_path
    from remoteenv.sim import publisher

    script = os.fspath(scene)
    if os.sep not in script and not script.endswith(".py"):
        script = scene_path(script)
    extra = ["--scene", os.path.abspath(script), "--episode-steps", str(int(episode_steps))]
    if items_per_instance is not None:
        extra += ["--items", str(int(items_per_instance))]
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
    """Items pushed by frame publishers, read without duplicates or loss.

    Args:
        endpoints: the publishers' bound endpoints.
        items_per_publisher: items one pass reads from each publisher (None: endless).
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
                sock = ctx.socket(zmq.PULL)
                sock.setsockopt(zmq.RCVHWM, RECV_HWM)
                sock.setsockopt(zmq.LINGER, 0)
                sock.setsockopt(zmq.MAXMSGSIZE, protocol.MAX_MESSAGE_BYTES)
                sock.connect(self.endpoints[i])
                poller.register(sock, zmq.POLLIN)
                sockets[sock] = i
            received = {i: 0 for i in mine}
            last_item = last_check = time.monotonic()
            while self.items_per_publisher is None or any(n < self.items_per_publisher for n in received.values()):
                ready = dict(poller.poll(_POLL_MS))
                now = time.monotonic()
                if now - last_check >= _POLL_MS / 1000:
                    self._check_alive(received, skip={sockets[s] for s in ready})
                    last_check = now
                if not ready:
                    if now - last_item > self.timeout:
                        raise RemoteEnvTimeout(
                            f"no frame from publishers {sorted(received)} for {self.timeout:g} s "
                            f"(received so far: {received}); they are alive but silent. Raise "
                            "timeout= if rendering is slow on this machine.",
                            kind="timeout",
                        )
                    continue
                for sock in ready:
                    i = sockets[sock]
                    item = self._decode(sock.recv(copy=True), i, received[i])
                    received[i] += 1
                    if self.items_per_publisher is not None and received[i] >= self.items_per_publisher:
                        poller.unregister(sock)
                    last_item = time.monotonic()
                    yield self.transform(item) if self.transform is not None else item
        finally:
            for sock in sockets:
                sock.close(linger=0)
            ctx.term()

    def _decode(self, frame: bytes, i: int, expected: int) -> dict[str, Any]:
        try:
            item = protocol.unpack(frame)
        except protocol.ProtocolError as exc:
            raise RemoteEnvError(
                f"publisher {i} ({self.endpoints[i]}) sent an undecodable item: {exc}", kind="protocol", instance=i
            ) from None
        if not isinstance(item, dict) or "frame" not in item or "index" not in item:
            raise RemoteEnvError(
                f"publisher {i} ({self.endpoints[i]}) sent an item that is not a frame map", kind="protocol", instance=i
            )
        if item["index"] != expected:
            raise RemoteEnvError(
                f"publisher {i} ({self.endpoints[i]}) sent item {item['index']} where {expected} was "
                "due: items were lost or another reader is connected to it (connect exactly one "
                "RemoteIterableDataset per publisher)",
                kind="protocol",
                instance=i,
            )
        return item

    def _check_alive(self, received: dict[int, int], skip: set[int]) -> None:
        """Raise if a publisher that still owes items (and has none queued) is gone."""
        if self.pids is None:
            return
        for i, count in received.items():
            if i in skip:
                continue
            if (self.items_per_publisher is None or count < self.items_per_publisher) and not pid_alive(self.pids[i]):
                due = "" if self.items_per_publisher is None else f" of {self.items_per_publisher}"
                raise RemoteEnvError(
                    f"frame publisher {i} (pid {self.pids[i]}, {self.endpoints[i]}) vanished after "
                    f"{count}{due} items; its process is gone. Relaunch the publishers "
                    "(see the launcher's log for why it exited).",
                    kind="died",
                    instance=i,
                )
