"""The sim's socket, gate and context close in bounded time: a step libzmq
never finishes (a context that cannot terminate after refused handshakes,
zeromq/libzmq#2733) holds the server's shutdown at most CLOSE_WAIT_S, with a
warning that names the sim and the step."""

from __future__ import annotations

import logging
import threading
from typing import Any

import pytest

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim.serving.sim_server import RemoteControlledAgent
from remoteenv.sim.transport import router_close
from remoteenv.sim.transport.router_close import close_router

#: Generous: the closer thread must end once released (threads are not timed here).
JOIN_S = 30.0


class Recorder:
    """A stand-in gate, socket and context that log their calls; ``hold`` names
    the call that waits until ``release`` is set."""

    def __init__(self, hold: str | None = None) -> None:
        self.calls: list[Any] = []
        self.hold = hold
        self.release = threading.Event()

    def _call(self, name: str, *args: Any) -> None:
        self.calls.append((name, *args))
        if name == self.hold:
            self.release.wait()

    def stop(self) -> None:
        self._call("gate.stop")

    def close(self, linger: int | None = None) -> None:
        self._call("socket.close", linger)

    def term(self) -> None:
        self._call("context.term")


def _closer_threads(instance: int) -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == f"remoteenv-router-close-{instance}"]


def _release_and_join(release: threading.Event, instance: int) -> None:
    release.set()
    for thread in _closer_threads(instance):
        thread.join(JOIN_S)
    assert not _closer_threads(instance), "the closer thread did not end once released"


def test_the_gate_stops_then_the_socket_closes_then_the_context_ends() -> None:
    r = Recorder()
    assert close_router(r, r, r, instance=3) is True  # type: ignore[arg-type]
    assert r.calls == [("gate.stop",), ("socket.close", 0), ("context.term",)]
    assert not _closer_threads(3)


@pytest.mark.parametrize(
    "hold, step",
    [
        ("gate.stop", "stopping the gate"),
        ("socket.close", "closing the socket"),
        ("context.term", "terminating the context"),
    ],
)
def test_a_step_that_never_returns_is_left_behind_with_a_warning(caplog, hold: str, step: str) -> None:
    r = Recorder(hold=hold)
    try:
        with caplog.at_level(logging.WARNING, logger=router_close.__name__):
            assert close_router(r, r, r, instance=7, wait_s=0.05) is False  # type: ignore[arg-type]
        [record] = caplog.records
        assert record.levelno == logging.WARNING
        assert f"sim instance 7: {step} did not finish" in record.getMessage()
        assert "libzmq" in record.getMessage()
    finally:
        _release_and_join(r.release, 7)
    assert r.calls[-1] == ("context.term",)  # released, it finishes the rest in order


class StuckContext:
    """The server's context, whose ``term`` waits until ``release`` is set."""

    def __init__(self, ctx: Any) -> None:
        self.ctx = ctx
        self.release = threading.Event()

    def term(self) -> None:
        self.release.wait()
        self.ctx.term()


def test_a_server_whose_context_never_ends_still_shuts_down(tmp_path, monkeypatch, caplog) -> None:
    srv = RemoteControlledAgent(
        [CartPoleEnv(render_mode="rgb_array", width=32, height=24)], f"ipc://{tmp_path}/sim.sock"
    )
    stuck = StuckContext(srv._ctx)
    srv._ctx = stuck  # type: ignore[assignment]
    monkeypatch.setattr(router_close, "CLOSE_WAIT_S", 0.05)
    socket_file = tmp_path / "sim.sock"
    assert socket_file.exists()
    try:
        with caplog.at_level(logging.WARNING, logger=router_close.__name__):
            srv.shutdown()  # returns although the context has not ended
        assert [r.getMessage() for r in caplog.records if "terminating the context" in r.getMessage()]
        assert not socket_file.exists()  # the socket file is gone all the same
    finally:
        _release_and_join(stuck.release, srv.instance)
    assert stuck.ctx.closed  # released, the real context ended
