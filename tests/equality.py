"""Deep equality for what envs return (importable by every test: pytest puts
``tests/`` on the path, see ``pythonpath`` in pyproject.toml)."""

from __future__ import annotations

from typing import Any

import numpy as np


def assert_same(a: Any, b: Any, where: str = "value") -> None:
    """``a`` and ``b`` are equal all the way down: maps key by key, sequences and
    object arrays item by item, arrays with their dtype and shape, other values
    with their type."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{where}: keys {sorted(a)} != {sorted(b)}"
        for key in a:
            assert_same(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, (tuple, list)):
        assert type(a) is type(b) and len(a) == len(b), f"{where}: {a!r} != {b!r}"
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert isinstance(b, np.ndarray) and a.shape == b.shape, f"{where}: {a!r} != {b!r}"
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray), f"{where}: {type(b)} is not an array"
        assert a.dtype == b.dtype and a.shape == b.shape, f"{where}: {a.dtype}{a.shape} != {b.dtype}{b.shape}"
        np.testing.assert_array_equal(a, b, err_msg=where)
    else:
        assert type(a) is type(b) and a == b, f"{where}: {a!r} ({type(a).__name__}) != {b!r} ({type(b).__name__})"


def assert_same_reacher_episodes(a: Any, b: Any, num_envs: int) -> int:
    """Step two vector envs of ``num_envs`` Reacher worlds, reset alike, with the
    same random actions through two episodes of Reacher's 50 steps (each world
    reset on the step after) and three steps more; their observations, rewards
    and flags are equal at every step. Returns how many steps truncated every world."""
    rng = np.random.default_rng(0)
    truncations = 0
    for _ in range(2 * 51 + 3):
        actions = rng.uniform(-1, 1, size=(num_envs, 2)).astype(np.float32)
        obs_a, rew_a, term_a, trunc_a, _ = a.step(actions)
        obs_b, rew_b, term_b, trunc_b, _ = b.step(actions)
        np.testing.assert_array_equal(obs_a, obs_b)
        np.testing.assert_array_equal(rew_a, rew_b)
        np.testing.assert_array_equal(term_a, term_b)
        np.testing.assert_array_equal(trunc_a, trunc_b)
        truncations += int(trunc_a.all())
    return truncations
