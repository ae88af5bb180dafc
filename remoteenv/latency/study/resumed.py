"""Checking the records of a study file before ``--resume`` keeps them (agent side).

A resumed record is published as it is, so each one must be what this
study's own run could have written: its cell (variant, delay model, delay,
seed) in the study's design and not repeated, the fields a cell's record
has with their types, ``history_length`` and ``include_alpha`` as the cell
defines them, ``mean_age_ticks`` and ``dropped_fraction`` null or in range, ``steps`` the study's budget, ``eval_episodes`` finite returns,
each within the scene's bounds where they are known (see
:func:`return_bounds`), and ``mean_return`` their mean.
"""

from __future__ import annotations

import math
from typing import Any

from remoteenv.latency.study.design import Cell, StudyConfig, cells

#: Per control tick reward bounds of the shipped scenes (their docs): CartPole
#: +1 per tick alive; Reacher ``-dist - |a|^2`` with ``dist`` under 0.41 m (arm
#: 0.21 m, target within 0.2 m) and ``|a|^2`` at most 2.
REWARD_PER_TICK: dict[str, tuple[float, float]] = {
    "remoteenv/CartPole-v0": (0.0, 1.0),
    "remoteenv/Reacher-v0": (-2.5, 0.0),
}


class BadRecord(ValueError):
    """A resumed record is not one this study could have written."""


def return_bounds(config: StudyConfig) -> tuple[float, float] | None:
    """The lowest and highest episode return of ``config``'s env (per-tick
    bounds times its step limit), None where either is unknown."""
    per_tick = REWARD_PER_TICK.get(config.env_id)
    limit = config.env_kwargs.get("max_episode_steps")
    if limit is None:
        try:
            import gymnasium as gym

            limit = gym.spec(config.env_id).max_episode_steps
        except Exception:  # an id gymnasium cannot resolve here: no bound
            limit = None
    if per_tick is None or not isinstance(limit, int) or isinstance(limit, bool) or limit < 1:
        return None
    return per_tick[0] * limit, per_tick[1] * limit


def check_records(records: Any, config: StudyConfig) -> list[dict[str, Any]]:
    """``records`` if every one is a record of ``config`` (see the module docs); else :class:`BadRecord`."""
    if not isinstance(records, list):
        raise BadRecord(f"'records' is a {type(records).__name__}, not a list")
    design = {cell.key: cell for cell in cells(config)}
    bounds = return_bounds(config)
    seen: set[tuple[str, str, int | str, int]] = set()
    for i, record in enumerate(records):
        try:
            key = _check_record(record, config, design, bounds)
        except BadRecord as exc:
            raise BadRecord(f"record {i}: {exc}") from None
        if key in seen:
            raise BadRecord(f"record {i}: cell {key} appears twice")
        seen.add(key)
    return records


def _check_record(
    record: Any,
    config: StudyConfig,
    design: dict[tuple[str, str, int | str, int], Cell],
    bounds: tuple[float, float] | None,
) -> tuple[str, str, int | str, int]:
    if not isinstance(record, dict):
        raise BadRecord(f"a {type(record).__name__}, not a map")
    variant, kind = _field(record, "variant", str), _field(record, "kind", str)
    delay, seed = _field(record, "delay", str if kind == "random" else int), _field(record, "seed", int)
    key = (variant, kind, delay, seed)
    cell = design.get(key)
    if cell is None:
        raise BadRecord(f"cell {_short(key)} is not in this study's design")
    if _field(record, "history_length", int) != cell.history_length:
        raise BadRecord(f"history_length {record['history_length']} is not the cell's {cell.history_length}")
    if _field(record, "include_alpha", bool) != cell.include_alpha:
        raise BadRecord(f"include_alpha {record['include_alpha']} is not the cell's {cell.include_alpha}")
    if record.get("mean_age_ticks") is not None:
        _finite(record["mean_age_ticks"], "mean_age_ticks", (0.0, math.inf))
    if record.get("dropped_fraction") is not None:
        _finite(record["dropped_fraction"], "dropped_fraction", (0.0, 1.0))
    if _field(record, "steps", int) != config.steps:
        raise BadRecord(f"steps {record['steps']} is not the study's {config.steps}")
    returns = _field(record, "returns", list)
    if len(returns) != config.eval_episodes:
        raise BadRecord(f"{len(returns)} returns, the study evaluates {config.eval_episodes} episodes")
    for value in returns:
        _finite(value, "a return", bounds)
    mean = _finite(record.get("mean_return"), "mean_return", bounds)
    if not math.isclose(mean, math.fsum(returns) / len(returns), rel_tol=1e-9, abs_tol=1e-9):
        raise BadRecord(f"mean_return {mean!r} is not the mean of its returns")
    _finite(record.get("train_s"), "train_s", (0.0, math.inf))
    if record.get("train_return") is not None:
        _finite(record["train_return"], "train_return", None)
    curve = _field(record, "curve", list)
    for point in curve:
        if not isinstance(point, list) or len(point) != 2:
            raise BadRecord("a curve point is not a [steps, return] pair")
        _finite(point[0], "a curve point's steps", (0.0, math.inf))
        if not (_is_number(point[1]) and (math.isnan(point[1]) or math.isfinite(point[1]))):
            raise BadRecord(f"a curve point's return {_short(point[1])} is not a number")
    return key


def _field(record: dict[str, Any], name: str, kind: type) -> Any:
    value = record.get(name)
    ok = isinstance(value, kind) and (kind is bool or not isinstance(value, bool))
    if not ok:
        raise BadRecord(f"{name} is {_short(value)}, not a {kind.__name__}")
    return value


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _finite(value: Any, what: str, bounds: tuple[float, float] | None) -> float:
    if not _is_number(value) or not math.isfinite(value):
        raise BadRecord(f"{what} {_short(value)} is not a finite number")
    if bounds is not None and not bounds[0] <= value <= bounds[1]:
        raise BadRecord(f"{what} {_short(value)} is outside the scene's bounds [{bounds[0]:g}, {bounds[1]:g}]")
    return float(value)


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


__all__ = ["REWARD_PER_TICK", "BadRecord", "check_records", "return_bounds"]
