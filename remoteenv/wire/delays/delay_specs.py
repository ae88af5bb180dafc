"""Delay specs: how late an action or an observation is, as a distribution.

Both processes use this module: the agent builds a spec (``action_delay=``,
``obs_delay=``), sends it in its wire form (:meth:`DelaySpec.to_wire`), and
the sim rebuilds it (:func:`delay_from_wire`, which treats every field as
hostile) and draws from it. The semantics of the delays themselves (when an
action takes effect, which observation is returned) live in
:mod:`remoteenv.wire.delays.delay_line` and ``docs/delays.md``.

Units. A spec is in control ticks (``unit="ticks"``, whole numbers, for
lock-step experiments) or in seconds (``unit="s"``, for an emulated link in
real time). One tick is ``env.dt`` simulated seconds.

Draws. ``spec.sample(rng, index)`` is the ``index``-th draw (counted from 0)
of a stream seeded by the caller; it is a pure function of the generator's
state and ``index``:

- :class:`Constant`: the value; the generator is not touched.
- :class:`Uniform`: ticks, ``rng.integers(low, high, endpoint=True)``
  (both ends included); seconds, ``rng.uniform(low, high)``.
- :class:`Categorical`: ``u = rng.random()``; the first value whose
  cumulative probability exceeds ``u`` (a value of probability 0 is never drawn).
- :class:`Trace`: ``values[index % len(values)]``: replayed in order and
  wrapped around at the end; the generator is not touched.
"""

from __future__ import annotations

import bisect
import io
import math
import os
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from remoteenv.wire.files.file_reads import parse_json, read_bytes, read_text
from remoteenv.wire.wire_errors import ProtocolError, short_repr

#: Delays in control ticks (whole numbers).
TICKS = "ticks"
#: Delays in seconds (real numbers).
SECONDS = "s"
UNITS = (TICKS, SECONDS)

#: Largest delay a spec may hold, per unit: bounds what a buffer keeps in flight.
MAX_DELAY_TICKS = 10_000
MAX_DELAY_S = 60.0
#: Most values a :class:`Trace` or :class:`Categorical` may hold.
MAX_VALUES = 100_000
#: Room for the header of a ``.npy`` trace file on top of its values (bytes).
_NPY_HEADER_BYTES = 1 << 16
#: How far the probabilities of a :class:`Categorical` may sum away from 1.
PROB_TOLERANCE = 1e-6

Delay = int | float


def _show(value: Any) -> str:
    """A bounded repr that prints floats (``short_repr`` names them ``<float>``)
    and the head of a long sequence of numbers."""
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, (list, tuple)) and all(isinstance(v, (int, float)) for v in value[:8]):
        head = ", ".join(_show(v) if isinstance(v, float) else short_repr(v) for v in value[:8])
        return f"[{head}]" if len(value) <= 8 else f"[{head}, ...] ({len(value)} values)"
    return short_repr(value)


def _delay_value(value: Any, unit: str, what: str) -> Delay:
    """``value`` as a valid delay of ``unit`` (a Python int or float); ValueError otherwise."""
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{what} must be a number of {unit}, got {value!r}")
    if unit == TICKS:
        if not isinstance(value, (int, np.integer)):
            raise ValueError(
                f"{what} must be a whole number of ticks, got {_show(value)}; for a delay in seconds pass unit='s'"
            )
        ticks = int(value)
        if not 0 <= ticks <= MAX_DELAY_TICKS:
            raise ValueError(f"{what} must be within 0..{MAX_DELAY_TICKS} ticks, got {ticks}")
        return ticks
    if not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{what} must be a number of seconds, got {_show(value)}")
    seconds = float(value)
    if not 0.0 <= seconds <= MAX_DELAY_S:  # also refuses NaN
        raise ValueError(f"{what} must be within 0..{MAX_DELAY_S} s, got {seconds!r}")
    return seconds


def _check_unit(unit: Any) -> str:
    if unit not in UNITS:
        raise ValueError(f"unit must be one of {UNITS}, got {short_repr(unit)}")
    return str(unit)


def _delay_values(values: Any, unit: str, what: str) -> tuple[Delay, ...]:
    if isinstance(values, (str, bytes)) or not isinstance(values, (Sequence, np.ndarray)):
        raise ValueError(f"{what} must be a sequence of delays, got {short_repr(values)}")
    if not 1 <= len(values) <= MAX_VALUES:
        raise ValueError(f"{what} must hold 1..{MAX_VALUES} delays, got {len(values)}")
    if isinstance(values, np.ndarray):
        if values.ndim != 1:
            raise ValueError(f"{what} must be one-dimensional, got shape {values.shape}")
        values = values.tolist()
    return tuple(_delay_value(v, unit, f"{what}[{i}]") for i, v in enumerate(values))


class DelaySpec:
    """A distribution of delays in one unit. Subclasses are immutable values
    (compared and hashed by content)."""

    kind: ClassVar[str]
    unit: str

    def sample(self, rng: np.random.Generator, index: int) -> Delay:
        """The ``index``-th draw (from 0) of a stream whose generator is ``rng``:
        an ``int`` for ticks, a ``float`` for seconds."""
        raise NotImplementedError

    @property
    def max(self) -> Delay:
        """The largest delay this spec can draw."""
        raise NotImplementedError

    @property
    def is_zero(self) -> bool:
        """True when every draw is 0 (no delay at all)."""
        return self.max == 0

    def _fields(self) -> dict[str, Any]:
        raise NotImplementedError

    def to_wire(self) -> dict[str, Any]:
        """A msgpack-able map: ``{"kind", "unit", ...fields}`` (see :func:`delay_from_wire`)."""
        return {"kind": self.kind, "unit": self.unit, **self._fields()}

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and self.to_wire() == other.to_wire()

    def __hash__(self) -> int:
        return hash((self.kind, self.unit, *(tuple(v) if isinstance(v, list) else v for v in self._fields().values())))

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"{type(self).__name__} is immutable")

    def _set(self, **fields: Any) -> None:
        for name, value in fields.items():
            object.__setattr__(self, name, value)


class Constant(DelaySpec):
    """Every draw is ``value``."""

    kind = "constant"
    value: Delay

    def __init__(self, value: Delay, unit: str = TICKS) -> None:
        unit = _check_unit(unit)
        self._set(unit=unit, value=_delay_value(value, unit, "Constant value"))

    def sample(self, rng: np.random.Generator, index: int) -> Delay:
        return self.value

    @property
    def max(self) -> Delay:
        return self.value

    def _fields(self) -> dict[str, Any]:
        return {"value": self.value}

    def __repr__(self) -> str:
        return f"Constant({self.value!r}, unit={self.unit!r})"


class Uniform(DelaySpec):
    """Uniform on ``[low, high]``: whole ticks with both ends included, or real seconds."""

    kind = "uniform"
    low: Delay
    high: Delay

    def __init__(self, low: Delay, high: Delay, unit: str = TICKS) -> None:
        unit = _check_unit(unit)
        lo = _delay_value(low, unit, "Uniform low")
        hi = _delay_value(high, unit, "Uniform high")
        if lo > hi:
            raise ValueError(f"Uniform needs low <= high, got low={lo!r} > high={hi!r}")
        self._set(unit=unit, low=lo, high=hi)

    def sample(self, rng: np.random.Generator, index: int) -> Delay:
        if self.unit == TICKS:
            return int(rng.integers(int(self.low), int(self.high), endpoint=True))
        return float(rng.uniform(self.low, self.high))

    @property
    def max(self) -> Delay:
        return self.high

    def _fields(self) -> dict[str, Any]:
        return {"low": self.low, "high": self.high}

    def __repr__(self) -> str:
        return f"Uniform({self.low!r}, {self.high!r}, unit={self.unit!r})"


class Categorical(DelaySpec):
    """``values[i]`` with probability ``probs[i]`` (equal probabilities when
    ``probs`` is None). The probabilities must be finite, >= 0 and sum to 1
    within :data:`PROB_TOLERANCE`; they are then divided by their sum."""

    kind = "categorical"
    values: tuple[Delay, ...]
    probs: tuple[float, ...]
    _cumulative: tuple[float, ...]

    def __init__(self, values: Sequence[Delay], probs: Sequence[float] | None = None, unit: str = TICKS) -> None:
        unit = _check_unit(unit)
        vals = _delay_values(values, unit, "Categorical values")
        if probs is None:
            weights = [1.0 / len(vals)] * len(vals)
        else:
            if isinstance(probs, (str, bytes)) or not isinstance(probs, (Sequence, np.ndarray)):
                raise ValueError(f"Categorical probs must be a sequence of numbers, got {short_repr(probs)}")
            if len(probs) != len(vals):
                raise ValueError(f"Categorical needs one probability per value: {len(vals)} values, {len(probs)} probs")
            weights = []
            for i, p in enumerate(probs):
                if isinstance(p, (bool, np.bool_)) or not isinstance(p, (int, float, np.integer, np.floating)):
                    raise ValueError(f"Categorical probs[{i}] must be a number, got {_show(p)}")
                if not 0.0 <= float(p) <= 1.0:  # also refuses NaN
                    raise ValueError(f"Categorical probs[{i}] must be within 0..1, got {float(p)!r}")
                weights.append(float(p))
        total = math.fsum(weights)
        if abs(total - 1.0) > PROB_TOLERANCE:
            raise ValueError(f"Categorical probs must sum to 1, they sum to {total!r}")
        norm = tuple(w / total for w in weights)
        cumulative = list(np.cumsum(norm).tolist())
        last = max(i for i, w in enumerate(norm) if w > 0)
        for i in range(last, len(cumulative)):  # rounding must not leave u in [cum[-1], 1)
            cumulative[i] = 1.0
        self._set(unit=unit, values=vals, probs=norm, _cumulative=tuple(cumulative))

    def sample(self, rng: np.random.Generator, index: int) -> Delay:
        return self.values[bisect.bisect_right(self._cumulative, float(rng.random()))]

    @property
    def max(self) -> Delay:
        return max(v for v, p in zip(self.values, self.probs) if p > 0)

    def _fields(self) -> dict[str, Any]:
        return {"values": list(self.values), "probs": list(self.probs)}

    def __repr__(self) -> str:
        return f"Categorical({_show(self.values)}, {_show(self.probs)}, unit={self.unit!r})"


class Trace(DelaySpec):
    """Recorded delays replayed in order: draw ``i`` is ``values[i % len(values)]``
    (after the last value the trace starts again from the first).

    ``source`` is a sequence of delays or the path of a file: ``.npy`` (a
    one-dimensional numeric array, loaded without pickle), ``.json`` (a list
    of numbers), otherwise text with numbers separated by whitespace or
    commas, ``#`` starting a comment. The file is read here, in the process
    that builds the spec; its values reach the sim in the launch's delay file
    (:mod:`remoteenv.wire.delays.delay_file`).
    """

    kind = "trace"
    values: tuple[Delay, ...]

    def __init__(self, source: Sequence[Delay] | np.ndarray | str | os.PathLike[str], unit: str = TICKS) -> None:
        unit = _check_unit(unit)
        if isinstance(source, (str, os.PathLike)):
            values = _read_trace_file(os.fspath(source), unit)
        else:
            values = _delay_values(source, unit, "Trace values")
        self._set(unit=unit, values=values)

    @classmethod
    def from_seconds(cls, seconds: Sequence[float] | np.ndarray, dt: float) -> Trace:
        """A trace in ticks from delays measured in seconds (e.g. a real-time
        run's ``latency_s``): each rounded up to whole ticks of ``dt`` seconds,
        since an action that arrives within a tick takes effect at the next
        tick boundary. Values within 1e-9 ticks of a whole number count as it."""
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {_show(dt)}")
        secs = _delay_values(seconds, SECONDS, "Trace.from_seconds values")
        return cls([max(0, math.ceil(s / dt - 1e-9)) for s in secs], unit=TICKS)

    def sample(self, rng: np.random.Generator, index: int) -> Delay:
        return self.values[index % len(self.values)]

    @property
    def max(self) -> Delay:
        return max(self.values)

    def _fields(self) -> dict[str, Any]:
        return {"values": list(self.values)}

    def __repr__(self) -> str:
        return f"Trace({_show(self.values)}, unit={self.unit!r})"


def _read_trace_file(path: str, unit: str) -> tuple[Delay, ...]:
    what = f"trace file {short_repr(path)}"
    limit = MAX_VALUES * 32
    data: Any
    try:
        # Never blocking, regular files only, bounded (a FIFO or /dev/zero is refused).
        if path.endswith(".npy"):
            data = _load_npy(read_bytes(path, limit + _NPY_HEADER_BYTES, what="trace file"), what)
        else:
            text = read_text(path, limit, what="trace file")
            data = parse_json(text, what=what) if path.endswith(".json") else _parse_text(text)
    except (OSError, ValueError) as exc:  # ValueError: bad JSON, text or .npy (e.g. an object array)
        raise ValueError(f"cannot read {what}: {exc}") from None
    if isinstance(data, np.ndarray):
        if data.ndim != 1 or not 1 <= data.size <= MAX_VALUES or data.dtype.kind not in "iuf":
            raise ValueError(
                f"{what} must hold a one-dimensional numeric array of 1..{MAX_VALUES} "
                f"delays, got shape {data.shape} and dtype {data.dtype}"
            )
        data = np.array(data)
        if unit == TICKS and data.dtype.kind == "f":
            if not np.all(np.isfinite(data) & (data == np.round(data))):
                raise ValueError(f"{what} holds fractional values; for delays in seconds pass unit='s'")
            data = data.astype(np.int64)
    elif not isinstance(data, list):
        raise ValueError(f"{what} must hold a list of delays, got {type(data).__name__}")
    return _delay_values(data, unit, what)


def _load_npy(data: bytes, what: str) -> np.ndarray:
    """The array of the ``.npy`` bytes ``data``, its header checked first: one
    dimension of at most :data:`MAX_VALUES` numbers, all of them present (a
    header may claim any size; ``np.load`` would allocate it before reading)."""
    from numpy.lib import format as npy

    buffer = io.BytesIO(data)
    version = npy.read_magic(buffer)
    if version == (1, 0):
        shape, _fortran, dtype = npy.read_array_header_1_0(buffer)
    elif version == (2, 0):
        shape, _fortran, dtype = npy.read_array_header_2_0(buffer)
    else:
        raise ValueError(f".npy format version {version} is not read here (1.0 and 2.0 are)")
    if len(shape) != 1 or not 1 <= shape[0] <= MAX_VALUES or dtype.kind not in "iuf":
        raise ValueError(
            f"it must hold a one-dimensional numeric array of 1..{MAX_VALUES} delays; "
            f"its header says shape {short_repr(shape)} and dtype {dtype}"
        )
    if len(data) - buffer.tell() < shape[0] * dtype.itemsize:
        raise ValueError(f"its header says {shape[0]} values, the file holds fewer")
    buffer.seek(0)
    return np.load(buffer, allow_pickle=False)


def _parse_text(text: str) -> list[Delay]:
    """Numbers separated by whitespace or commas; ``#`` starts a comment."""
    values: list[Delay] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        for token in line.split("#", 1)[0].replace(",", " ").split():
            try:
                values.append(int(token))
            except ValueError:
                try:
                    values.append(float(token))
                except ValueError:
                    raise ValueError(f"line {lineno}: {short_repr(token)} is not a number") from None
    return values


_KINDS: dict[str, tuple[type[DelaySpec], frozenset[str]]] = {
    Constant.kind: (Constant, frozenset({"value"})),
    Uniform.kind: (Uniform, frozenset({"low", "high"})),
    Categorical.kind: (Categorical, frozenset({"values", "probs"})),
    Trace.kind: (Trace, frozenset({"values"})),
}


def delay_from_wire(desc: Any) -> DelaySpec:
    """Rebuild a spec from :meth:`DelaySpec.to_wire`'s map. Anything else (an
    unknown kind or unit, a missing or extra key, a value of the wrong type or
    out of range, a list too long) raises :class:`ProtocolError`."""
    if not isinstance(desc, dict):
        raise ProtocolError(f"a delay spec must be a map, got {type(desc).__name__}")
    kind = desc.get("kind")
    entry = _KINDS.get(kind) if isinstance(kind, str) else None
    if entry is None:
        raise ProtocolError(f"unknown delay kind {short_repr(kind)}; expected one of {sorted(_KINDS)}")
    cls, fields = entry
    expected = fields | {"kind", "unit"}
    if set(desc) != expected:
        raise ProtocolError(
            f"a {kind} delay spec has keys {sorted(expected)}, got {short_repr(sorted(map(str, list(desc)[:20])))}"
        )
    for name in fields:
        value = desc[name]
        if name in ("values", "probs") and not isinstance(value, list):
            raise ProtocolError(f"{kind} delay {name} must be a list, got {type(value).__name__}")
        if name in ("values", "probs") and len(value) > MAX_VALUES:
            raise ProtocolError(f"{kind} delay {name} holds {len(value)} entries, more than {MAX_VALUES}")
    try:
        if cls is Constant:
            return Constant(desc["value"], unit=desc["unit"])
        if cls is Uniform:
            return Uniform(desc["low"], desc["high"], unit=desc["unit"])
        if cls is Categorical:
            return Categorical(desc["values"], desc["probs"], unit=desc["unit"])
        return Trace(desc["values"], unit=desc["unit"])
    except ValueError as exc:
        raise ProtocolError(f"invalid {kind} delay spec: {exc}") from None


def as_delay(value: DelaySpec | int | float, unit: str = TICKS) -> DelaySpec:
    """A delay spec from what a user passes: a spec (whose unit must be
    ``unit``) or a number, meaning :class:`Constant` of that many ``unit``."""
    unit = _check_unit(unit)
    if isinstance(value, DelaySpec):
        if value.unit != unit:
            raise ValueError(f"expected a delay in {unit}, got {value!r}")
        return value
    return Constant(value, unit=unit)


__all__ = [
    "Categorical",
    "Constant",
    "Delay",
    "DelaySpec",
    "MAX_DELAY_S",
    "MAX_DELAY_TICKS",
    "MAX_VALUES",
    "PROB_TOLERANCE",
    "SECONDS",
    "TICKS",
    "Trace",
    "UNITS",
    "Uniform",
    "as_delay",
    "delay_from_wire",
]
