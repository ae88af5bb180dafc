"""Checks of ``get_attr``, ``set_attr`` and ``call`` (a server's reach into its scene).

Run only against a server whose handshake offers all three. A server cannot
be asked for its scene's attribute names, so the checks probe the refusals
the spec requires of any scene: private names, names no scene has, and the
methods that drive the world, each an ``attribute`` error after which the
server keeps serving.

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

from remoteenv.compliance.check_results import Check
from remoteenv.compliance.failures import CheckSkipped
from remoteenv.compliance.probe import Probe
from remoteenv.wire.wire_errors import ATTRIBUTE, PROTOCOL

#: The commands these checks need.
ATTRIBUTE_COMMANDS = ("get_attr", "set_attr", "call")
#: A name no scene has.
NO_SUCH_NAME = "no_such_attribute_of_any_scene"


def scene_attribute_refusals(p: Probe) -> None:
    why = p.handshake.lacks(*ATTRIBUTE_COMMANDS)
    if why:
        raise CheckSkipped(why)
    p.error("get_attr", [ATTRIBUTE], "a private name", world=0, name="_private")
    p.error("get_attr", [ATTRIBUTE], "a name no scene has", world=0, name=NO_SUCH_NAME)
    p.error("set_attr", [ATTRIBUTE], "setting a name no scene has", world=0, name=NO_SUCH_NAME, value=1)
    p.error("call", [ATTRIBUTE], "calling 'step' (it drives the world)", world=0, name="step", args=[], kwargs={})
    p.error("get_attr", [PROTOCOL, ATTRIBUTE], "a name that is not a str", world=0, name=7)
    p.still_serving("refused attribute requests")


CHECKS = (
    Check(
        "scene_attributes",
        "get_attr/set_attr/call refuse private, missing and world-driving names with 'attribute' errors",
        scene_attribute_refusals,
    ),
)
