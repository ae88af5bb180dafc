"""The remoteenv wire format. Both processes import this module; it is the spec.

Transport
---------
ZeroMQ. The sim process binds one ROUTER socket; an agent connects one DEALER
socket. Each message is a single ZeroMQ frame holding one msgpack document
(the ROUTER additionally sees the peer's routing id as a first frame, which it
echoes back unchanged). Nothing on the wire is ever unpickled or evaluated.

Default addresses are ``ipc://<private temp dir>/sim-<instance>.sock`` or
``tcp://127.0.0.1:<port chosen by the OS>``. Binding any other interface is an
explicit choice of the user.

The local pipe. A sim process started by an agent's launcher also gets one end
of a Unix stream socketpair as an inherited file descriptor (``--pipe-fd``);
the launching agent keeps the other end and sends its own requests there,
which skips ZeroMQ's I/O threads (the fastest path on one machine). On the
pipe each message is a 4-byte little-endian unsigned length followed by that
many bytes: the same msgpack frame as on ZeroMQ. It has exactly one peer, so
there is no routing id. End of file on the pipe means the agent is gone; the
sim then stops. A frame whose length is above :data:`MAX_MESSAGE_BYTES` is
skipped (its bytes are read and dropped, so the stream stays in step) and
answered like an undecodable frame.

The layout gate. Before a sim serves, its launcher may hold it at a gate
(the command-line option ``--layout-gate FILE``): the sim makes one scratch
world as it makes a served one (no viewer window; never served), times its
whole control tick as a ``world_cost`` handshake would, writes ``FILE``
(JSON, replaced atomically: a reader sees no file or all of it, at most
4 KiB) ``{"world_cost_s": float >= 0 or null, "stacked_hooks": bool,
"worlds_that_fit": int >= 0, "pid": int}`` (the seconds one world's tick cost
on one thread, whether the worlds step as one batch through the scene's
stacked hooks, how many worlds' observations one batch reply carries, and
the sim's process id), and waits, before it builds a served world. SIGUSR1
from the launcher says go: it builds its worlds and serves as any sim. The
launcher that finds the facts calling for another layout ends it instead
(SIGTERM); an agent that dies ends it too (the sim watches its parent). The
launcher reads the file as it reads a reply: bounded, every field checked,
the pid its own sim's. Only a first launch is gated, never a restart.

Limits
------
No frame, in either direction and on either transport, is longer than
:data:`MAX_MESSAGE_BYTES` (32 MiB: a 4K RGB frame fits). A sender checks
before sending: the agent refuses an oversize request with an error naming
the limit and sends nothing; the sim answers a request whose reply would be
oversize with an error reply instead. A receiver drops an oversize frame
(ZeroMQ does so itself through ``ZMQ_MAXMSGSIZE``, which closes that peer's
connection). In a request, no msgpack array or map holds more than
:data:`MAX_REQUEST_ITEMS` entries (lists of numbers travel as arrays).
A server bounds what it holds for its peers in total: it may refuse a
connection's handshake when it serves enough connections already (the
reference sims admit 8 at once; libzmq ends a refused connection and drops
what was queued on it, so a client that wants in connects again after a
pause and sends those requests again: none of them reached the server), and it may drop a request unread when too
many requests from connections that drive no world (see Drivers) are
waiting, answering it with a ``state`` error whose ``seq`` is read from the
frame's first bytes (-1 if it is not there: :func:`peek_seq`).
Integers are within msgpack's range ``[-2**63, 2**64)``. Error messages echo
at most a bounded repr of the request's content
(:data:`remoteenv.wire.wire_errors.MAX_ECHO_CHARS` characters per value) and are
at most :data:`MAX_ERROR_CHARS` characters long.

A reply holds at most :data:`MAX_REPLY_VALUES` msgpack values (every map,
array and scalar counts one; a client counts them before decoding and refuses
a larger reply). A handshake's counts are bounded too, and a client refuses a
handshake beyond them before it builds anything from it: ``num_worlds`` is
an int in ``1 .. MAX_WORLDS`` (:data:`MAX_WORLDS` = 65,536), and one
observation of every world fits in a frame together (``num_worlds`` times the
bytes of one observation, a Discrete value counting 8, at most
:data:`MAX_MESSAGE_BYTES`: a batch reply carries them all); each space map
holds at most :data:`MAX_SPACE_NODES` spaces (1,024, every Dict and Tuple
member counted), nested at most :data:`MAX_SPACE_DEPTH` (16) deep, with
dtypes from :data:`ARRAY_DTYPES`, Discrete ``n`` and ``start`` within int64,
and one value of the space within :data:`MAX_MESSAGE_BYTES`.

Clients
-------
Both ends distrust each other; a client owes the server what the server owes
a client. A client's wait for a reply ends at its deadline whatever arrives:
it checks the deadline after every frame, so stale or foreign frames cannot
extend it, and drops them (a bounded number per look). It bounds what it
queues (the reference agent: a receive high-water mark of 4 frames, each at
most :data:`MAX_MESSAGE_BYTES`), caps a received error text at
:data:`MAX_ERROR_CHARS`, and checks every ``ok`` reply against the handshake
before it uses it: observations of the observation space's dtype and shape,
numeric rewards, bool flags, info maps with str keys, batch fields of exactly
the worlds asked for, ``final`` positions distinct and in ``0 .. n-1``,
render frames uint8 ``H x W x 3`` or nil. A reply that breaks any of this is a
protocol error of that call, naming the command, the field and the server;
none of it is used. It maps a ``shared_batch`` region only if it is sealed
against shrinking. ``tests/integration/servers/hostile_server.py`` is a
server that breaks each of these rules on request, for testing a client.

Messages
--------
A request is a msgpack map::

    {"seq": int, "cmd": str, ...command arguments}

``seq`` is chosen by the client and strictly increases per connection. Every
reply echoes it::

    {"seq": int, "ok": true,  ...results}
    {"seq": int, "ok": false, "error": {"kind": str, "message": str,
                                         "traceback": str}}

A client drops any reply whose ``seq`` is not the one it is waiting for (a
stale reply from a request that timed out is never taken for the current one).
A frame that cannot be decoded as a request gets an error reply with
``seq = -1``; a client takes such a reply as the answer to its request only
when it has no earlier request outstanding on that connection (otherwise the
undecodable frame may have been an earlier one) and never waits past it
for nothing: see :class:`remoteenv.agent.connection.sim_connection.SimConnection`. Error kinds: ``"protocol"`` (malformed request, unknown command,
version mismatch), ``"invalid_action"``, ``"scene"`` (the env code raised),
``"state"`` (e.g. step before reset), ``"attribute"`` and ``"unsendable"``
(see ``get_attr`` below).

Commands (version 1)
--------------------
``handshake`` ``{"protocol": int, "world_cost": bool (optional), "probe": bool (optional)}`` -> ``{"protocol",
"env_id", "instance", "pid", "num_worlds", "observation_space", "action_space",
"metadata", "stepping", "commands"}``. The server refuses a protocol version it does not speak,
naming both versions. ``commands`` (optional; a list of str) names every
command the server answers; a client that finds no such field assumes
``reset_batch``/``step_batch`` exist exactly when ``stepping.mode`` is
``"lock_step"`` and ``timing`` exactly when it is ``"real_time"``. ``metadata`` holds ``render_modes``, ``render_fps``,
``dt`` (seconds of simulated time per env step), ``timestep`` (seconds per
physics substep), ``frame_skip``, optionally (lock-step) ``physics_threads``
(the threads, 1 or more, the server steps its worlds' physics on) and
``stacked_hooks`` (true when it steps its worlds as one batch through the
scene's stacked hooks: its Python runs once per tick, not once per world;
a vector env's default layout reads both), and, optionally, ``world_cost_s`` (wall
seconds one world's whole control tick costs the server on one thread: the
physics and every hook of the scene, images included, measured on a scratch
world; a hint for how many worlds a process should host). A server measures
it only when the request carries ``"world_cost": true`` (it takes a few ticks'
time) and may answer without it (then the client keeps its layout). With
``"probe": true`` beside it the client will close the server after the
handshake (it asked only to learn the scene): the server may measure on its
own world 0 instead of a scratch world, leaving that world reset and stepped; ``stepping`` holds ``mode``
(``"lock_step"`` or ``"real_time"``) and that mode's parameters: in lock-step
``action_delay`` (ticks; the largest of a random model) and, with delays
beyond a constant action delay, ``obs_delay`` (the largest, ticks),
``action_delay_spec`` and ``obs_delay_spec`` (the models' wire forms, see
:mod:`remoteenv.wire.delays.delay_specs`) and, with a delay and delivery rules or
delayed rewards other than the default, ``channel`` (see
:mod:`remoteenv.wire.delays.channel_rules`); in real time ``real_time_factor`` and, with an
emulated link, ``link_delay_spec``, and ``real_time_mode`` (``"elastic"``
or ``"fixed_step"``, see :mod:`remoteenv.wire.run_options.real_time_modes`; a server
that does not say runs ``"elastic"``).

``reset`` ``{"world": int, "seed": int | nil, "options": map | nil}`` ->
``{"obs", "info"}``. In real time, options holding the key
``"remoteenv_replay"`` (a map ``{"mode": str, "action_substeps": [int,
...]}``, at most 100,000 non-decreasing ints) make the world replay a
recorded episode without its clock: the key is removed before the scene
sees the options, and each ``step`` of the episode is answered at once, its
action taking effect at the next listed substep (counted from the reset),
as it would have on the clock (:mod:`remoteenv.wire.run_options.real_time_modes`,
:mod:`remoteenv.sim.stepping.real_time_replay`). A schedule of another
regime, a malformed one, or a step beyond it is a ``protocol`` error.

``step`` ``{"world": int, "action"}`` -> ``{"obs", "reward": float,
"terminated": bool, "truncated": bool, "info": map}`` (and ``"types"``, see
Values).

``render`` ``{"world": int}`` -> ``{"frame": uint8 array H x W x 3 | nil}``.

``close`` ``{}`` -> ``{}``; the server then exits. Only a connection that
drives the worlds may close a sim (see Drivers).

``timing`` ``{"clear": bool}`` -> ``{"worlds": [map, ...]}`` (real-time sims
only): per world, ``pacing_error_s`` and ``apply_delay_s`` summaries
(``count``, ``mean``, ``p50``, ``p99``, ``max``, wall seconds), ``overruns``,
``substeps``, ``period_s``, ``clock_slips`` and ``slipped_s`` (times the
world's clock slipped because it fell more than a second behind, and the
wall seconds it dropped; see :mod:`remoteenv.sim.stepping.real_time`; the
reference server sends them) and ``link_delay_s`` (the emulated link delays
drawn, when the reference server emulates one); ``clear`` resets them after
replying. In real time a ``step`` reply is sent when its action has been in
force for one control tick (see :mod:`remoteenv.sim.stepping.real_time`).

``pause`` ``{}`` -> ``{"sim_time": [float, ...]}`` and ``resume`` ``{}`` ->
``{"sim_time": [float, ...], "paused_s": float}`` (real-time sims that list
them in ``commands``): ``pause`` stops every world's clock (no physics runs,
the held action stays) and replies with each world's sim time; ``resume``
restarts the clocks with every deadline shifted by the paused wall seconds
``paused_s`` (0.0 if not paused), so the pause counts in no timing figure.
Pausing twice or resuming unpaused changes nothing. A ``step`` sent while
paused is answered after the resume.

``reset_batch`` ``{"worlds": [int, ...], "seeds": [int | nil, ...] | nil,
"options": map | nil}`` -> ``{"obs", "info": infos}`` (lock-step sims only):
resets the listed worlds in order, world ``worlds[j]`` with ``seeds[j]``.

``step_batch`` ``{"ops": [int, ...], "actions", "worlds": [int, ...] | nil}``
-> ``{"obs", "reward": [float, ...], "terminated": [bool, ...], "truncated":
[bool, ...], "info": infos, "final": [[position, obs, info], ...]}``
(lock-step sims only): one request for ``n = len(ops)`` worlds, ``0 .. n-1``
or, when ``worlds`` is given, the ``n`` distinct worlds it lists (position
``j`` of ops, actions and every reply field is world ``worlds[j]``); ``actions`` holds their
``n`` actions, stacked in one array (Box: shape ``(n, *shape)``; Discrete:
ints of shape ``(n,)``) or as a list. ``ops[j]`` says what its world does:
0 step; 1 reset (action ignored; reward 0, not terminated, not truncated,
info = the reset's info); 2 step, then reset if the step terminated or
truncated; 3 step, then reset (the agent's time limit ends the episode). A
world reset after a step is listed in ``final`` with the step's obs and info,
and its ``obs``/``info`` entries are the reset's. An optional
``"final_types"`` list (one entry per ``final`` entry: nil or an info
``{key: dtype}`` map) types their info values as ``"types"`` does (see Values).

``shared_batch`` ``{}`` -> ``{"pid": int, "fd": int, "layout": {"worlds":
int, "actions": [dtype, shape], "obs": [dtype, shape]}}`` (optional; a
lock-step sim whose worlds step together and whose spaces fit offers it, to
the agent that launched it, over the local pipe only; anyone else gets a
``state`` error): the sim's shared-memory region for batched steps, an
anonymous file the agent maps as ``/proc/<pid>/fd/<fd>``, sealed against
shrinking and growing (``F_SEAL_SHRINK | F_SEAL_GROW | F_SEAL_SEAL``) before
it is offered, laid out as
:mod:`remoteenv.wire.shared_memory.shared_batch` says. Afterwards a ``step_batch`` on the
pipe may carry ``"shared": true`` and no ``actions`` (nor ``worlds``): the
actions of positions ``0 .. n-1`` are rows ``0 .. n-1`` of the region's
actions block, checked as sent ones are. If every world steps and none
resets, the reply then is ``{"shared": true, "info": infos, "final": []}``
with ``obs``, ``reward``, ``terminated`` and ``truncated`` in rows ``0 .. n-1``
of the region; any other outcome is answered in the usual form.

The fast lane. A region whose layout has ``"info_columns": M`` (``M > 0``)
also holds a header of 16 ``<i8`` doorbell words, the request's ``ops`` and
``worlds`` and ``M`` typed info columns (:mod:`remoteenv.wire.shared_memory.shared_batch`).
The agent may then post a whole ``step_batch`` there: it writes ops, worlds
(when it names them) and actions, then the words ``REQ_N`` (``n``),
``REQ_NAMED`` (1: the worlds block names the worlds), ``AGENT_THINK_US``
(its think time before this request in microseconds, when it tells it; 0
otherwise: a hint the sim may use to sleep rather than wait hot for the
next request, never checked) and last ``REQ_SEQ`` (the request's
``seq``), and sends ``{"seq": s, "cmd": "step_batch", "region": true}`` on
the pipe unless the sim's ``SIM_WATCHING`` word says it will look at
``REQ_SEQ`` before it blocks. The sim serves such a request
like a sent one (``n``, ops, worlds and actions checked as sent ones are;
its frame, if it comes after the request was served, is dropped). If every
world steps, none resets and every info value is a column the region can
hold (at most ``M`` keys, bool, int or float values of at most 8 bytes),
the sim answers in the region: rows ``0 .. n-1`` of ``obs``, ``reward``,
``terminated``, ``truncated`` and the info columns, then the words
``REP_INFO`` (the info layout's version) and last ``REP_SEQ`` (``s``), and
sends ``{"seq": s, "ok": true, "region": true}`` unless ``AGENT_WATCHING``
says the agent will look at ``REP_SEQ`` before it blocks. The info columns
are announced before their first use, in a pipe reply to a region request
(``{"shared": true, ..., "info_layout": {"version": int, "columns": [[key,
dtype, python], ...]}}``, the version above every earlier one; ``python``:
the values are python scalars, carried as ``|b1``, ``<i8`` or ``<f8``); a
region reply uses the last announced layout. Any other outcome (a reset, an
error, other infos) is answered on the pipe as usual. Replies keep request
order. Before a side blocks it clears its ``*_WATCHING`` word, then a full
fence, then it looks at the peer's sequence word once more (and does not
block if it moved). A heads-up: an agent about to block on one sim's pipe may
also set ``AGENT_HEADS_UP`` (1) as it clears ``AGENT_WATCHING``; a sim that
finds both so once the physics of a region request is done may send
``{"seq": s, "soon": true}`` before it runs the rest of the tick (hooks,
checks, answer), so that the agent's wake-up overlaps that work. The agent,
woken by it, watches again (``AGENT_WATCHING`` 1, ``AGENT_HEADS_UP`` 0) and
waits for the reply (in the region or as a frame) hot for a bounded time,
then blocks as before. A heads-up is a hint: it answers nothing (a reader
drops one it does not await, and one that comes late, read after the wait
it was for ended, leaves the agent watching the region for the reply), the
reply and its wake-up frame follow the rules above unchanged, and a sim may
send none (it sends none where its ticks take long after the physics).
Between requests the agent may set ``AGENT_AWAY`` (1) when its caller begins
a long think (its learner's update), and clears it with its next request;
a sim waiting hot for that request stops and blocks (a hint, like
``AGENT_THINK_US``; either side refuses a header whose ``AGENT_AWAY`` is
neither 0 nor 1, and the agent one that holds other than it wrote last).
Without total store order (off x86-64) a side sets no
``*_WATCHING`` word and reads no sequence word without its frame, so every
request and reply then goes as its frame. The agent takes a region reply
only for the request it awaits, in the announced layout, and refuses
(``protocol``) a region reply to a request that was not posted there, an
``info_layout`` off these rules, and a ``REP_SEQ`` or ``REP_INFO`` that does
not match. The words: :mod:`remoteenv.wire.shared_memory.doorbell`.

In both, ``obs`` is one array of shape ``(n, *obs_shape)`` when every world's
obs is an array of one shape and dtype, else a list of ``n`` obs. ``infos`` is
``{"columns": {key: [values, present]}}`` when every info value is a bool,
int or float with one type per key (``values``: list of ``n`` such values, 0
where absent, or an array of the dtype of the first world's value when that
is a numpy number; ``present``: list of ``n`` bools), else
``{"maps": [map, ...]}``, one info map per world.

``get_attr`` ``{"world": int, "name": str}`` -> ``{"value", "callable":
bool}``: a public attribute of the world's scene env; for a method,
``callable`` is true and ``value`` nil (call it with ``call``).

``set_attr`` ``{"world": int, "name": str, "value"}`` -> ``{}``: sets an
attribute the scene env has (it never creates one).

``call`` ``{"world": int, "name": str, "args": list | nil, "kwargs": map |
nil}`` -> ``{"result"}``: calls the scene env's method ``name`` with the
arguments and returns what it returned; for an attribute that is not
callable (and no arguments) returns its value, as Gymnasium's vector
``call`` does.

These three refuse private names (leading ``_``), names the scene env lacks
and the methods that drive the world (``reset``, ``step``, ``render``,
``close``, ...) with error kind ``"attribute"``, and a value that cannot be
encoded with kind ``"unsendable"``. A server without them leaves them out of
its handshake's ``commands``.

``world`` defaults to 0 and addresses one of the ``num_worlds`` MuJoCo worlds
a sim process hosts.

Drivers
-------
One connection drives each world (a connection is the local pipe, or one
ZeroMQ peer, known by its routing id: a client keeps its routing id when it
reconnects). A sim with a local pipe is driven by the pipe, every world and
for good. Otherwise nobody drives a world until a connection resets or
steps it; that connection then drives it until its connection ends (the
sim's socket monitor reports the disconnect). That report comes a moment
after the close, on its own path: a client that resets a world right after
the previous driver's connection closed may be refused for that moment, so
a client taking over a world retries a refusal that names another driver
for up to :data:`DRIVER_RELEASE_GRACE_S` before it gives up (the checker
and the reference agent do). A ``state`` error answers
``reset``, ``reset_batch``, ``step`` or ``step_batch`` on a world another
connection drives; and ``close``, ``pause`` or ``resume`` from a connection
that does not drive every world somebody drives (the sim's owner: its pipe,
else the connection driving its worlds). Every other command is open to
every connection. A client that wants to drive a world resets it first.
This keeps a second client from displacing a driver's steps, taking its
worlds over or stopping its sim; it does not tell users apart: who may
connect at all is up to the transport
(an ipc socket in a private dir, CURVE keys).

Values
------
Plain msgpack types (nil, bool, int, float, str, bin, array, map with str
keys). numpy arrays travel as msgpack extension type 1 whose payload is::

    uint8 L | dtype: L ASCII bytes | uint8 ndim | shape: ndim x uint64 LE | data

with ``dtype`` an explicit little-endian numpy type string from
:data:`ARRAY_DTYPES` (``"<f4"``, ``"|u1"``, ...), ``ndim`` at most 32 and
``data`` the C-ordered raw bytes. Decoders check that ``len(data) ==
prod(shape) * itemsize`` and return a fresh, writable array that shares
memory with nothing. numpy scalars are sent as plain ints, floats and
bools; a ``reset`` or ``step`` reply whose reward or info values were numpy
scalars says which in an optional ``"types"`` map, ``{"reward": dtype,
"info": {key: dtype}}`` (dtype strings from :data:`ARRAY_DTYPES`), so a
client can give them back their type (see :mod:`remoteenv.wire.codec.scalar_types`;
a client may ignore it).

An integer outside msgpack's range ``[-2**63, 2**64)`` travels in a reply
(never in a request) as msgpack extension type 2: its two's-complement
big-endian bytes, 1 to :data:`~remoteenv.wire.codec.arrays.MAX_BIG_INT_BYTES` of them
(Gymnasium's ``np_random_seed`` is a 128-bit integer). Requests keep the
range: a client refuses to send a larger integer and a sim refuses type 2.

Spaces (Box, Discrete, MultiDiscrete, MultiBinary, Dict, Tuple) travel as maps,
see :mod:`remoteenv.wire.codec.spaces`.
"""

from __future__ import annotations

import select
import socket
import struct
from typing import Any

import msgpack

from remoteenv.wire.codec.arrays import ARRAY_DTYPES, _default, _default_big, _ext_hook, _ext_hook_big, wire_dtype
from remoteenv.wire.codec.frame_limits import (
    MAX_ERROR_CHARS,
    MAX_MESSAGE_BYTES,
    MAX_REPLY_VALUES,
    MAX_REQUEST_ITEMS,
    MAX_SPACE_DEPTH,
    MAX_SPACE_NODES,
    MAX_WORLDS,
    FrameTooLarge,
)
from remoteenv.wire.codec.value_count import values_within
from remoteenv.wire.wire_errors import ProtocolError, short_repr

PROTOCOL_VERSION = 1

#: Seconds a client taking over a world keeps retrying a reset refused because
#: another connection drives it (see "Drivers" above): the sim frees a world
#: when its socket monitor reports the driver's disconnect, a moment after it.
DRIVER_RELEASE_GRACE_S = 2.0


#: ``step_batch`` operations, one per world (see the spec above).
#: Step the world with its action.
OP_STEP = 0
#: Reset the world (no seed, no options); its action is ignored; reward 0, not done.
OP_RESET = 1
#: Step; if the step terminated or truncated, reset and report the final obs/info.
OP_STEP_AUTORESET = 2
#: Step, then reset regardless (the agent's time limit truncates this step).
OP_STEP_RESET = 3
OPS = (OP_STEP, OP_RESET, OP_STEP_AUTORESET, OP_STEP_RESET)


def pack(obj: Any, big_ints: bool = False) -> bytes:
    """Encode one message (a map) as msgpack bytes.

    Raises :class:`FrameTooLarge` for a frame above :data:`MAX_MESSAGE_BYTES`
    (an oversize array is refused before it is copied), ``ValueError`` for an
    integer outside msgpack's range (with ``big_ints``, a reply's, outside
    extension type 2's) and ``TypeError`` for a value the wire cannot carry.
    """
    try:
        frame: bytes = msgpack.packb(obj, default=_default_big if big_ints else _default, use_bin_type=True)
    except OverflowError:
        raise ValueError("an integer is outside the wire's range [-2**63, 2**64)") from None
    if len(frame) > MAX_MESSAGE_BYTES:
        raise FrameTooLarge(len(frame))
    return frame


def unpack(frame: bytes, max_items: int | None = None, max_values: int | None = None, big_ints: bool = False) -> Any:
    """Decode one frame. Raises :class:`ProtocolError` for anything off-spec.

    ``max_items`` caps the entries of every array and map, ``max_values`` the
    values of the whole frame (both checked before any value is built);
    ``big_ints`` (a reply) takes extension type 2's integers.
    """
    if len(frame) > MAX_MESSAGE_BYTES:
        raise FrameTooLarge(len(frame))
    if max_values is not None and not values_within(frame, max_values):
        raise ProtocolError(f"a frame of {len(frame)} bytes holds more than {max_values} msgpack values")
    limits = {} if max_items is None else {"max_array_len": max_items, "max_map_len": max_items}
    try:
        hook = _ext_hook_big if big_ints else _ext_hook
        return msgpack.unpackb(frame, raw=False, ext_hook=hook, strict_map_key=True, use_list=True, **limits)
    except ProtocolError:
        raise
    except Exception as exc:  # msgpack raises several types for bad input
        raise ProtocolError(f"undecodable frame ({type(exc).__name__}: {short_repr(str(exc))})") from None


def peek_seq(frame: Any, prefix: int = 64) -> int:
    """The ``seq`` of a request frame read from its first ``prefix`` bytes only,
    or -1 when it is not among them (a receiver that drops a frame unread
    answers it with this ``seq``). Never raises."""
    unpacker = msgpack.Unpacker(raw=False, strict_map_key=True, max_buffer_size=prefix)
    try:
        unpacker.feed(bytes(memoryview(frame)[:prefix]))
        for _ in range(min(unpacker.read_map_header(), 4)):
            key, value = unpacker.unpack(), unpacker.unpack()
            if key == "seq":
                return value if type(value) is int and -1 <= value < 2**64 else -1
    except Exception:
        pass
    return -1


def region_request(seq: int) -> dict[str, Any]:
    """Request ``seq`` posted in the shared region, as a map:
    ``{"seq": seq, "cmd": "step_batch", "region": true}``. The frame that
    rings a sleeping sim for it carries this map (:func:`region_ring`); a sim
    that finds the request in the region while watching serves the same map
    without a frame (see "The fast lane" above)."""
    return {"seq": seq, "cmd": "step_batch", "region": True}


def region_ring(seq: int) -> bytes:
    """The frame that rings a sim for request ``seq`` posted in its shared
    region: :func:`region_request`'s map, packed."""
    return pack(region_request(seq))


def region_reply(seq: int) -> dict[str, Any]:
    """The reply to request ``seq`` when it is in the shared region:
    ``{"seq": seq, "ok": true, "region": true}``, the map the sim's wake-up
    frame for it carries (see "The fast lane" above)."""
    return {"seq": seq, "ok": True, "region": True}


def reply_soon(seq: int) -> bytes:
    """The heads-up a sim may send once the physics of region request ``seq``
    is done and the agent sleeps waiting for it: ``{"seq": seq, "soon": true}``
    (see "The fast lane" above). It answers nothing."""
    return pack({"seq": seq, "soon": True})


def is_reply_soon(reply: dict[str, Any]) -> bool:
    """Whether a decoded frame is a heads-up (:func:`reply_soon`), which answers nothing."""
    return reply.get("soon") is True


def decode_request(frame: bytes) -> dict[str, Any]:
    """Decode and shape-check a request frame (arrays and maps of at most
    :data:`MAX_REQUEST_ITEMS` entries; an int ``seq``, a str ``cmd``)."""
    msg = unpack(frame, MAX_REQUEST_ITEMS)
    if not isinstance(msg, dict):
        raise ProtocolError(f"a request must be a map, got {type(msg).__name__}")
    seq = msg.get("seq")
    if not isinstance(seq, int) or isinstance(seq, bool):
        raise ProtocolError("a request needs an integer 'seq'")
    if not isinstance(msg.get("cmd"), str):
        raise ProtocolError("a request needs a string 'cmd'")
    return msg


_LENGTH = struct.Struct("<I")
#: Bytes one read from a local pipe takes at most (a frame may span several reads).
STREAM_READ_BYTES = 1 << 18


def stream_frame(payload: bytes) -> bytes:
    """``payload`` with its length prefix, for the local pipe."""
    return _LENGTH.pack(len(payload)) + payload


class StreamDecoder:
    """Splits the byte stream of a local pipe into frames.

    A frame that declares a length above :data:`MAX_MESSAGE_BYTES` is skipped:
    its bytes are dropped as they arrive (never buffered), so the frames after
    it decode normally. The decoder is never left out of step.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._skip = 0
        self._held: list[bytes | FrameTooLarge] = []
        self._read_buf = bytearray(STREAM_READ_BYTES)
        self._read_view = memoryview(self._read_buf)
        #: A poll of the socket last read without waiting, and its descriptor.
        self._poll: Any = None
        self._polled_fd = -1

    def recv_from(self, sock: socket.socket, wait: bool = False) -> memoryview | None:
        """Read what has arrived on ``sock`` into a buffer this decoder reuses
        (valid until the next call; pass it to :meth:`items`). Without
        ``wait`` the read never blocks; with it, it blocks as the socket does
        (a blocking socket with ``SO_RCVTIMEO`` set waits at most that long).

        Returns None when nothing has arrived, an empty view at end of file (or
        when the socket failed). Reusing one buffer matters: ``socket.recv(n)``
        allocates ``n`` bytes on every call, even when nothing is there. A read
        without ``wait`` polls first: finding nothing costs a third of a read
        that fails (no exception raised and caught), and hot waits look often.
        """
        if not wait and not self._readable(sock):
            return None
        try:
            n = sock.recv_into(self._read_buf, STREAM_READ_BYTES, 0 if wait else socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError:
            n = 0
        return self._read_view[:n]

    def _readable(self, sock: socket.socket) -> bool:
        """Whether a read of ``sock`` would not block now (bytes, its end, or an error are there)."""
        fd = sock.fileno()
        if fd < 0:
            return True  # closed here: the read reports it
        if fd != self._polled_fd:
            self._poll = select.poll()
            self._poll.register(fd, select.POLLIN)
            self._polled_fd = fd
        return bool(self._poll.poll(0))

    def items(self, data: bytes | memoryview) -> list[bytes | FrameTooLarge]:
        """Add received bytes; return the frames now complete, in order, an
        oversize frame as a :class:`FrameTooLarge` at the place it started."""
        frames, self._held = self._held, []
        if self._skip:
            dropped = min(self._skip, len(data))
            self._skip -= dropped
            data = data[dropped:]
        buf = self._buf
        buf += data
        start = 0
        while len(buf) - start >= 4:
            (length,) = _LENGTH.unpack_from(buf, start)
            if length > MAX_MESSAGE_BYTES:
                frames.append(FrameTooLarge(length, "a pipe frame"))
                available = len(buf) - start - 4
                if available < length:
                    self._skip = length - available
                    start = len(buf)
                    break
                start += 4 + length
                continue
            end = start + 4 + length
            if len(buf) < end:
                break
            frames.append(bytes(buf[start + 4 : end]))
            start = end
        if start:
            del buf[:start]
        return frames

    def feed(self, data: bytes | memoryview) -> list[bytes]:
        """Like :meth:`items`, but raise :class:`FrameTooLarge` for an oversize
        frame once the frames before it are returned; the frames after it come
        with the next call (``feed(b"")`` if nothing more arrives)."""
        frames = self.items(data)
        for i, frame in enumerate(frames):
            if isinstance(frame, FrameTooLarge):
                self._held = frames[i + 1 :]
                if i == 0:
                    raise frame
                self._held.insert(0, frame)
                return frames[:i]  # type: ignore[return-value]
        return frames  # type: ignore[return-value]


def _capped(text: str) -> str:
    if len(text) <= MAX_ERROR_CHARS:
        return text
    return f"{text[: MAX_ERROR_CHARS - 40]}... ({len(text) - MAX_ERROR_CHARS + 40} more characters)"


def error_reply(seq: int, kind: str, message: str, traceback: str = "") -> dict[str, Any]:
    """An error reply; ``message`` and ``traceback`` are capped at :data:`MAX_ERROR_CHARS`
    (messages built from request content must bound each echoed value themselves,
    with :func:`~remoteenv.wire.wire_errors.short_repr`)."""
    return {
        "seq": seq,
        "ok": False,
        "error": {"kind": kind, "message": _capped(message), "traceback": _capped(traceback)},
    }


__all__ = [
    "ARRAY_DTYPES",
    "DRIVER_RELEASE_GRACE_S",
    "MAX_ERROR_CHARS",
    "MAX_MESSAGE_BYTES",
    "MAX_REPLY_VALUES",
    "MAX_REQUEST_ITEMS",
    "MAX_SPACE_DEPTH",
    "MAX_SPACE_NODES",
    "MAX_WORLDS",
    "OPS",
    "OP_RESET",
    "OP_STEP",
    "OP_STEP_AUTORESET",
    "OP_STEP_RESET",
    "PROTOCOL_VERSION",
    "FrameTooLarge",
    "ProtocolError",
    "StreamDecoder",
    "decode_request",
    "error_reply",
    "is_reply_soon",
    "pack",
    "peek_seq",
    "region_reply",
    "region_request",
    "region_ring",
    "reply_soon",
    "stream_frame",
    "unpack",
    "wire_dtype",
]
