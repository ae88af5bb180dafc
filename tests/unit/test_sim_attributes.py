"""The sim's get_attr / set_attr / call commands, on plain objects (no processes)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from remoteenv.sim.serving.attributes import AttributeCommands
from remoteenv.sim.transport.checks import RequestError


class Scene:
    def __init__(self) -> None:
        self.mass = 1.0
        self._secret = 3
        self.model = object()

    def scaled(self, k: float, *, offset: float = 0.0) -> float:
        return self.mass * k + offset

    def step(self, action: Any) -> None:
        raise AssertionError("the stepping drives the world, not call")


@pytest.fixture
def commands() -> AttributeCommands:
    return AttributeCommands([Scene(), Scene()], instance=4)  # type: ignore[list-item]


def ask(commands: AttributeCommands, cmd: str, **msg: Any) -> dict[str, Any]:
    return commands.handlers()[cmd](msg, None, None)


def test_get_set_call_address_one_world(commands: AttributeCommands) -> None:
    assert ask(commands, "get_attr", world=1, name="mass") == {"value": 1.0, "callable": False}
    assert ask(commands, "get_attr", world=1, name="scaled") == {"value": None, "callable": True}
    ask(commands, "set_attr", world=1, name="mass", value=2.5)
    assert ask(commands, "call", world=1, name="mass") == {"result": 2.5}
    assert ask(commands, "call", world=0, name="mass") == {"result": 1.0}
    assert ask(commands, "call", world=1, name="scaled", args=[2.0], kwargs={"offset": 1.0}) == {"result": 6.0}
    value = np.arange(3.0)
    ask(commands, "set_attr", world=0, name="mass", value=value)
    assert ask(commands, "get_attr", world=0, name="mass")["value"] is value


@pytest.mark.parametrize(
    ("cmd", "name", "kind", "says"),
    [
        ("get_attr", "_secret", "attribute", "private"),
        ("set_attr", "missing", "attribute", "Scene (world 0 of sim instance 4) has no attribute 'missing'"),
        ("call", "step", "attribute", "drives the world"),
        ("get_attr", "model", "unsendable", "cannot cross the wire"),
        ("get_attr", "not a name", "protocol", "must be an attribute name"),
        ("call", "mass", "protocol", "'args' as a list"),
    ],
)
def test_refusals(commands: AttributeCommands, cmd: str, name: str, kind: str, says: str) -> None:
    extra = {"args": "x"} if says == "'args' as a list" else {}
    with pytest.raises(RequestError) as err:
        ask(commands, cmd, world=0, name=name, value=1, **extra)
    assert err.value.kind == kind
    assert says in str(err.value)


def test_a_plain_attribute_takes_no_arguments(commands: AttributeCommands) -> None:
    with pytest.raises(RequestError, match="not callable"):
        ask(commands, "call", world=0, name="mass", args=[1])


def test_world_out_of_range(commands: AttributeCommands) -> None:
    with pytest.raises(RequestError, match="out of range"):
        ask(commands, "get_attr", world=2, name="mass")
