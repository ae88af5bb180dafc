"""What a scene's step hooks return, checked where the scene returns it.

Runs in the sim process. :class:`BaseEnv` checks ``post_step``'s result
(every step of a single world, lock-step or real time) and the batched path
checks ``post_steps``'s :class:`~remoteenv.sim.scene.batch_result.BatchResult`
and ``reset_models``'s ``(obs, infos)``,
so a scene mistake fails at once with a :class:`StepResultError` naming the
scene, the hook and the value, instead of a numpy error deep in the server or
a silently wrong value (``terminated=None`` read as False):

- ``reset_model`` returns two values ``(obs, info)``, ``info`` a dict;
- ``post_step`` returns four values ``(obs, reward, terminated, info)``;
- the reward is one real number (python or numpy int or float; a 0-d array
  counts), not a bool, an array of several values or None;
- ``terminated`` is a bool (python or numpy), not None, an int or an array;
- ``info`` is a dict;
- with ``check_finite`` (the scene's ``check_finite = True``): the
  observation's arrays and the reward hold no NaN or infinity.

A batch is checked with numpy over the whole result (a dtype and a shape per
array, one ``isfinite`` per array with ``check_finite``), never world by world
unless its observations or infos are lists. Observations' dtype and shape are
:mod:`remoteenv.sim.scene.obs_check`'s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.wire.wire_errors import short_repr


class StepResultError(TypeError):
    """A scene hook returned a step result of the wrong kind (see the module docstring)."""


def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of dtype {value.dtype} and shape {value.shape}"
    return f"{short_repr(value, 80)} ({type(value).__name__})"


def _fail(scene: str, hook: str, what: str, fix: str) -> StepResultError:
    return StepResultError(f"{scene}.{hook} returned {what}; {fix}")


def _is_number(value: Any) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, (int, float, np.integer, np.floating)):
        return True
    return isinstance(value, np.ndarray) and value.shape == () and value.dtype.kind in "iuf"


def unpack_step(result: Any, *, scene: str, hook: str, finite: bool = False) -> tuple[Any, Any, Any, dict[str, Any]]:
    """``(obs, reward, terminated, info)`` of one ``post_step`` result, checked
    (see the module docstring); ``finite``: the reward too. The observation
    (its space, and with ``check_finite`` its values) is checked by the caller."""
    if not isinstance(result, tuple) or len(result) != 4:
        count = f"{len(result)} values" if isinstance(result, (tuple, list)) else _describe(result)
        raise _fail(
            scene,
            hook,
            count,
            "it returns the tuple (obs, reward, terminated, info): truncation is the agent side's "
            "business (max_episode_steps at registration)",
        )
    obs, reward, terminated, info = result
    if not _is_number(reward):
        raise _fail(scene, hook, f"reward {_describe(reward)}", "a reward is one number per step: return float(...)")
    if not isinstance(terminated, (bool, np.bool_)):
        raise _fail(
            scene,
            hook,
            f"terminated {_describe(terminated)}",
            "return a bool: True when the episode has ended (e.g. bool(x > limit))",
        )
    if not isinstance(info, Mapping):
        raise _fail(scene, hook, f"info {_describe(info)}", "return a dict (empty if there is nothing to report)")
    if finite and not math.isfinite(float(reward)):
        raise _fail(scene, hook, f"reward {float(reward)!r}", "rewards must be finite (check_finite = True)")
    return obs, reward, terminated, info  # type: ignore[return-value]


def unpack_reset(result: Any, *, scene: str) -> tuple[Any, dict[str, Any]]:
    """``(obs, info)`` of one ``reset_model`` result, checked: a tuple of two, info
    a dict. The observation is checked by the caller."""
    if not isinstance(result, tuple) or len(result) != 2 or not isinstance(result[1], dict):
        raise StepResultError(
            f"{scene}.reset_model returned {short_repr(result, 80)} "
            f"({type(result).__name__}); it returns the tuple (obs, info), info a dict"
        )
    return result[0], result[1]


def check_finite_obs(obs: Any, *, scene: str, hook: str, what: str = "an observation") -> None:
    """Raise unless every float array in ``obs`` (an array, or a dict/tuple of them) is finite."""
    for path, array in _float_arrays(obs, ""):
        if not np.isfinite(array).all():
            bad = int(np.size(array) - np.count_nonzero(np.isfinite(array)))
            raise _fail(
                scene,
                hook,
                f"{what}{path} with {bad} NaN or infinite value(s): {short_repr(array, 120)}",
                "the physics may have diverged (a smaller timestep or softer contacts help); "
                "observations must be finite (check_finite = True)",
            )


def _float_arrays(obs: Any, path: str) -> list[tuple[str, np.ndarray]]:
    if isinstance(obs, np.ndarray):
        return [(path, obs)] if obs.dtype.kind in "fc" else []
    if isinstance(obs, dict):
        return [found for key, value in obs.items() for found in _float_arrays(value, f"{path}[{key!r}]")]
    if isinstance(obs, (tuple, list)):
        return [found for i, value in enumerate(obs) for found in _float_arrays(value, f"{path}[{i}]")]
    if isinstance(obs, (float, np.floating)):
        return [(path, np.asarray(obs))]
    return []


def check_batch(result: Any, n: int, *, scene: str, hook: str, finite: bool = False) -> BatchResult:
    """``post_steps``'s result for ``n`` worlds, checked with numpy over the batch:
    a :class:`BatchResult` whose ``reward`` is a real array ``(n,)``, whose
    ``terminated`` is a bool array ``(n,)`` and whose obs and infos have ``n``
    entries (with ``finite``: no NaN or infinity in obs and rewards)."""
    if not isinstance(result, BatchResult):
        raise _fail(
            scene, hook, _describe(result), "return a remoteenv.sim.BatchResult(obs, reward, terminated, infos)"
        )
    reward, terminated = result.reward, result.terminated
    if not isinstance(reward, np.ndarray) or reward.shape != (n,) or reward.dtype.kind not in "iuf":
        raise _fail(
            scene,
            hook,
            f"reward {_describe(reward)} for {n} worlds",
            f"return one number per world: a float array of shape ({n},)",
        )
    if not isinstance(terminated, np.ndarray) or terminated.shape != (n,) or terminated.dtype != np.bool_:
        raise _fail(
            scene,
            hook,
            f"terminated {_describe(terminated)} for {n} worlds",
            f"return a bool array of shape ({n},) (e.g. np.abs(x) > limit)",
        )
    obs = result.obs
    _check_rows(obs, n, scene=scene, hook=hook)
    infos = result.infos
    if isinstance(infos, list):
        if len(infos) != n or not all(isinstance(info, Mapping) for info in infos):
            raise _fail(scene, hook, f"infos {short_repr(infos, 80)}", f"return a list of {n} dicts, or columns")
    elif not isinstance(infos, Mapping):
        raise _fail(scene, hook, f"infos {_describe(infos)}", f"return a list of {n} dicts, or a dict of columns")
    if finite:
        if not np.isfinite(reward).all():
            raise _fail(
                scene, hook, f"rewards {short_repr(reward, 120)}", "rewards must be finite (check_finite = True)"
            )
        _check_finite_rows(obs, n, scene=scene, hook=hook)
    return result


def check_reset_batch(
    result: Any, n: int, *, scene: str, hook: str = "reset_models", finite: bool = False
) -> tuple[Any, list[dict[str, Any]]]:
    """``reset_models``'s result for ``n`` worlds, checked: ``(obs, infos)``,
    ``obs`` an array of ``n`` rows or a list of ``n`` obs, ``infos`` a list of
    ``n`` dicts (with ``finite``: no NaN or infinity in obs)."""
    if not isinstance(result, tuple) or len(result) != 2:
        raise _fail(scene, hook, _describe(result), f"return the tuple (obs, infos) for the {n} worlds")
    obs, infos = result
    _check_rows(obs, n, scene=scene, hook=hook)
    if not isinstance(infos, list) or len(infos) != n or not all(isinstance(info, dict) for info in infos):
        raise _fail(scene, hook, f"infos {short_repr(infos, 80)}", f"return a list of {n} dicts")
    if finite:
        _check_finite_rows(obs, n, scene=scene, hook=hook)
    return obs, infos


def _check_rows(obs: Any, n: int, *, scene: str, hook: str) -> None:
    """Raise unless ``obs`` is an array of ``n`` rows or a list of ``n`` obs."""
    rows = obs.shape[0] if isinstance(obs, np.ndarray) and obs.ndim >= 1 else len(obs) if isinstance(obs, list) else -1
    if rows != n:
        raise _fail(
            scene, hook, f"obs {_describe(obs)} for {n} worlds", f"return an array of {n} rows or a list of {n} obs"
        )


def _check_finite_rows(obs: Any, n: int, *, scene: str, hook: str) -> None:
    """Raise naming the first world whose observation holds a NaN or infinity."""
    if isinstance(obs, np.ndarray):
        if obs.dtype.kind in "fc" and not np.isfinite(obs).all():
            world = int(np.flatnonzero(~np.isfinite(obs.reshape(n, -1)).all(axis=1))[0])
            check_finite_obs(obs[world], scene=scene, hook=hook, what=f"world {world}'s observation")
    else:
        for world, one in enumerate(obs):
            check_finite_obs(one, scene=scene, hook=hook, what=f"world {world}'s observation")


__all__ = ["StepResultError", "check_batch", "check_finite_obs", "check_reset_batch", "unpack_reset", "unpack_step"]
