"""A client taking a world over retries a refusal that names another driver, for a bounded grace.

The sim frees a driven world when its socket monitor reports the driver's
disconnect, a moment after the close; the agent (``retry_taking_over``) and
the checker (``Probe.call``) resend a reset refused in that moment.
"""

from __future__ import annotations

import threading
from typing import Any

import msgpack
import pytest
import zmq

from remoteenv.agent.connection import take_over
from remoteenv.agent.errors import RemoteEnvError, StateError
from remoteenv.compliance import probe as probe_module
from remoteenv.compliance.probe import Probe, Target
from remoteenv.wire import protocol
from remoteenv.wire.wire_errors import ANOTHER_DRIVER, refused_for_another_driver

_REFUSAL = f"'reset' refused: world 0 of sim instance 0 {ANOTHER_DRIVER} (until its connection ends)"


class _Conn:
    """A connection whose first ``refusals`` resets are refused as driven by another connection."""

    def __init__(self, refusals: int, message: str = _REFUSAL) -> None:
        self.refusals = refusals
        self.message = message
        self.sent: list[tuple[str, dict[str, Any]]] = []

    def request(self, cmd: str, timeout: float | None = None, **args: Any) -> dict[str, Any]:
        self.sent.append((cmd, args))
        if len(self.sent) <= self.refusals:
            raise RemoteEnvError(f"sim instance 0 failed '{cmd}' (state): {self.message}", kind="state", instance=0)
        return {"seq": len(self.sent), "ok": True}


def test_a_reset_refused_while_the_previous_driver_is_released_is_resent_until_it_passes(monkeypatch):
    monkeypatch.setattr(take_over, "RETRY_S", 0.001)
    conn = _Conn(refusals=3)
    reply = take_over.retry_taking_over(lambda: conn.request("reset", 5.0, seed=7, options=None))
    assert reply["ok"] is True
    assert conn.sent == [("reset", {"seed": 7, "options": None})] * 4


def test_a_world_still_driven_after_the_grace_raises_the_refusal(monkeypatch):
    monkeypatch.setattr(take_over, "RETRY_S", 0.001)
    monkeypatch.setattr(protocol, "DRIVER_RELEASE_GRACE_S", 0.05)
    conn = _Conn(refusals=10**9)
    with pytest.raises(StateError, match=ANOTHER_DRIVER):
        take_over.retry_taking_over(lambda: conn.request("reset", 5.0, seed=None, options=None))
    assert len(conn.sent) > 1


def test_other_state_errors_are_raised_at_once(monkeypatch):
    conn = _Conn(refusals=1, message="step before reset on world 0 of instance 0")
    with pytest.raises(StateError, match="step before reset"):
        take_over.retry_taking_over(lambda: conn.request("reset", 5.0, seed=None, options=None))
    assert len(conn.sent) == 1


def test_the_refusal_is_told_by_kind_and_words():
    refused = {"seq": 1, "ok": False, "error": {"kind": "state", "message": _REFUSAL}}
    assert refused_for_another_driver(refused)
    assert not refused_for_another_driver({**refused, "error": {"kind": "protocol", "message": _REFUSAL}})
    assert not refused_for_another_driver({**refused, "error": {"kind": "state", "message": "step before reset"}})
    assert not refused_for_another_driver({"seq": 1, "ok": True})
    assert not refused_for_another_driver({"seq": 1, "ok": False, "error": "not a map"})


def _server(sock: zmq.Socket, refusals: int, seen: list[str], stop: threading.Event) -> None:
    """Answer resets: the first ``refusals`` refused as driven by another connection, then ok."""
    while not stop.is_set():
        if not sock.poll(20):
            continue
        routing_id, frame = sock.recv_multipart()
        request = msgpack.unpackb(frame)
        seen.append(request["cmd"])
        if request["cmd"] == "reset" and seen.count("reset") <= refusals:
            error = {"kind": "state", "message": _REFUSAL, "traceback": ""}
            reply = {"seq": request["seq"], "ok": False, "error": error}
        else:
            reply = {"seq": request["seq"], "ok": True}
        sock.send_multipart([routing_id, msgpack.packb(reply)])


@pytest.mark.parametrize("cmd, refusals, resets", [("reset", 2, 3), ("render", 2, 0)])
def test_the_checker_resends_only_a_reset_refused_for_another_driver(monkeypatch, cmd, refusals, resets):
    monkeypatch.setattr(probe_module, "RELEASE_RETRY_S", 0.001)
    ctx = zmq.Context.instance()
    server = ctx.socket(zmq.ROUTER)
    server.setsockopt(zmq.LINGER, 0)
    port = server.bind_to_random_port("tcp://127.0.0.1")
    seen: list[str] = []
    stop = threading.Event()
    thread = threading.Thread(target=_server, args=(server, refusals, seen, stop))
    thread.start()
    try:
        with Probe(Target(endpoint=f"tcp://127.0.0.1:{port}", timeout=5.0)) as probe:
            reply = probe.call(cmd, world=0, seed=0, options=None)
    finally:
        stop.set()
        thread.join()
        server.close(linger=0)
    assert reply["ok"] is True
    assert seen.count("reset") == resets and len(seen) == max(resets, 1)
