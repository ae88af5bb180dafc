"""PhysicsThreads: threaded stepping gives each world exactly its serial trajectory."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import remoteenv
from remoteenv.sim.stepping.batch_physics import THREADS_ENV, PhysicsThreads, default_threads

XML = remoteenv.scene_path("reacher").replace("reacher_scene.py", "reacher.xml")


def _worlds(n: int) -> tuple[list[mujoco.MjModel], list[mujoco.MjData]]:
    model = mujoco.MjModel.from_xml_path(XML)
    datas = [mujoco.MjData(model) for _ in range(n)]
    rng = np.random.default_rng(0)
    for d in datas:
        d.qvel[:] = rng.uniform(-1, 1, size=model.nv)
        d.ctrl[:] = rng.uniform(-1, 1, size=model.nu)
    return [model] * n, datas


@pytest.mark.parametrize("n,threads", [(1, 3), (7, 2), (33, 3)])
def test_threads_match_serial_stepping(n: int, threads: int) -> None:
    models, serial = _worlds(n)
    _, threaded = _worlds(n)
    pool = PhysicsThreads(threads)
    try:
        for _ in range(20):
            for m, d in zip(models, serial):
                mujoco.mj_step(m, d, nstep=2)
            pool.step(models, threaded, 2)
    finally:
        pool.close()
    for a, b in zip(serial, threaded):
        np.testing.assert_array_equal(a.qpos, b.qpos)
        np.testing.assert_array_equal(a.xpos, b.xpos)


def test_an_error_in_a_worker_chunk_is_raised_to_the_caller() -> None:
    models, datas = _worlds(16)
    pool = PhysicsThreads(2)
    try:
        with pytest.raises(TypeError):
            pool.step(models, [*datas[:15], "not MjData"], 1)  # type: ignore[list-item]
        pool.step(models, datas, 1)  # the pool still works
    finally:
        pool.close()


def test_default_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(THREADS_ENV, raising=False)
    assert default_threads(64) == 1
    monkeypatch.setenv(THREADS_ENV, "3")
    assert default_threads(64) == 3
    assert default_threads(9) == 1  # at most one thread per 8 worlds
    monkeypatch.setenv(THREADS_ENV, "0")
    with pytest.raises(ValueError, match=THREADS_ENV):
        default_threads(8)
