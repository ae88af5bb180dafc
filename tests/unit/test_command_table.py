"""The sim's command table: every failure of a handler becomes a typed error
reply for its request, whether the request came as a frame (``handle``) or
was found posted in the pipe's region (``handle_region``)."""

from __future__ import annotations

from typing import Any

import pytest

from remoteenv.sim.serving.command_table import CommandTable
from remoteenv.sim.transport.checks import RequestError
from remoteenv.wire.protocol import region_request
from remoteenv.wire.wire_errors import INVALID_ACTION, PROTOCOL, SCENE, STATE, InvalidAction


def _raising(exc: BaseException | None):
    def handler(msg: dict[str, Any], channel: Any, *reply_to: Any) -> dict[str, Any] | None:
        if exc is not None:
            raise exc
        return {"shared": True}

    return handler


@pytest.mark.parametrize(
    "exc, kind",
    [
        (RequestError(STATE, "no region"), STATE),
        (InvalidAction("action 3 is out of bounds"), INVALID_ACTION),
        (ValueError("the scene's hook broke"), SCENE),
    ],
)
def test_a_failing_handler_gives_the_same_typed_error_either_way(exc, kind):
    table = CommandTable({"step_batch": _raising(exc)}, region=_raising(exc))
    by_frame = table.handle({"seq": 7, "cmd": "step_batch", "region": True}, None, None)
    by_region = table.handle_region(region_request(7), None)  # type: ignore[arg-type]
    for reply in (by_frame, by_region):
        assert reply is not None and reply["seq"] == 7 and reply["ok"] is False
        assert reply["error"]["kind"] == kind
    assert by_frame["error"]["message"] == by_region["error"]["message"]


def test_a_region_request_is_answered_by_the_region_handler_with_its_seq():
    calls: list[Any] = []

    def region(msg: dict[str, Any], pipe: Any) -> dict[str, Any]:
        calls.append((msg["seq"], pipe))
        return {"shared": True}

    table = CommandTable({}, region=region)
    assert table.handle_region(region_request(3), "pipe") == {"shared": True, "seq": 3, "ok": True}  # type: ignore[arg-type]
    assert calls == [(3, "pipe")]


def test_without_a_region_handler_a_region_request_is_an_unknown_command():
    reply = CommandTable({}).handle_region(region_request(4), None)  # type: ignore[arg-type]
    assert reply is not None and reply["ok"] is False and reply["error"]["kind"] == PROTOCOL
