"""Reacher scene, sim side: a two-link arm reaching for a random target.

Semantics follow the code of Gymnasium's Reacher-v5: obs is
``[cos q0, cos q1, sin q0, sin q1, target x, target y, q0_dot, q1_dot,
(fingertip - target) x, (fingertip - target) y]`` (float64, m and rad/s);
reward is ``-|fingertip - target| - |a|^2`` computed after stepping; the
episode never terminates (the agent side truncates after 50 steps).

Pixels: ``obs_mode="pixels"`` makes the observation the ``overhead``
camera's image (uint8 ``(image_size, image_size, 3)``), ``"state_pixels"`` a
Dict ``{"state": <the 10 numbers>, "pixels": <the image>}``; rendered in the
sim without multisampling and shadows unless ``camera_quality=True``
(docs/cameras.md). ``camera_kind`` and ``frame_stack`` as for CartPole.

Run by the launcher as ``python reacher_scene.py --address ... --seed ...``.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.sim import BaseEnv, BatchResult, Camera, camera_observation, run_scene, stacked

MODEL_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "reacher.xml")


class ReacherEnv(BaseEnv):
    env_id = "remoteenv/Reacher-v0"
    metadata = {"render_modes": ["rgb_array", "human"]}
    default_camera = "overhead"
    # The batched hooks read and write state through stacked(): the worlds of a
    # process step in one mujoco.batch call.
    stacked_hooks = True
    #: Counts every setting of any world's reward weight: the batched hooks' remembered
    #: weights (:func:`_stacked_weights`) are stale once it has moved.
    weights_version = 0

    def __init__(
        self,
        render_mode: str | None = None,
        reward_dist_weight: float = 1.0,
        reward_control_weight: float = 1.0,
        width: int = 480,
        height: int = 480,
        obs_mode: str = "state",
        image_size: int = 64,
        camera_quality: bool = False,
        camera_kind: str | Sequence[str] = "rgb",
        frame_stack: int = 1,
    ) -> None:
        kind = camera_kind if isinstance(camera_kind, str) else tuple(camera_kind)
        cameras = camera_observation(
            obs_mode,
            Camera("overhead", width=image_size, height=image_size, kind=kind),
            quality=camera_quality,
            frame_stack=frame_stack,
        )
        super().__init__(
            MODEL_PATH,
            frame_skip=2,
            observation_space=spaces.Box(-np.inf, np.inf, shape=(10,), dtype=np.float64),
            action_space=spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32),
            render_mode=render_mode,
            width=width,
            height=height,
            cameras=cameras,
        )
        self.reward_dist_weight = float(reward_dist_weight)
        self.reward_control_weight = float(reward_control_weight)
        self._fingertip = self.model.body("fingertip").id
        self._target = self.model.body("target").id

    @property
    def reward_dist_weight(self) -> float:
        """The distance term's weight in the reward (1: Gymnasium's)."""
        return self._reward_dist_weight

    @reward_dist_weight.setter
    def reward_dist_weight(self, value: float) -> None:
        self._reward_dist_weight = value
        ReacherEnv.weights_version += 1

    @property
    def reward_control_weight(self) -> float:
        """The control cost's weight in the reward (1: Gymnasium's)."""
        return self._reward_control_weight

    @reward_control_weight.setter
    def reward_control_weight(self, value: float) -> None:
        self._reward_control_weight = value
        ReacherEnv.weights_version += 1

    def reset_model(self, options: dict[str, Any] | None) -> tuple[np.ndarray, dict[str, Any]]:
        self.set_state(*self._draw_start())
        return self._obs(), {}

    def _draw_start(self) -> tuple[np.ndarray, np.ndarray]:
        """A start state ``(qpos, qvel)`` drawn from this world's RNG: the arm near
        its rest pose, barely moving, the target anywhere within 0.2 m."""
        rng = self.np_random
        model = self.model
        qpos = model.qpos0 + rng.uniform(low=-0.1, high=0.1, size=model.nq)
        while True:
            goal = rng.uniform(low=-0.2, high=0.2, size=2)
            if math.sqrt(goal.dot(goal)) < 0.2:  # np.linalg.norm's own sum for a vector, without its overhead
                break
        qpos[-2:] = goal
        qvel = rng.uniform(low=-0.005, high=0.005, size=model.nv)
        qvel[-2:] = 0.0
        return qpos, qvel

    @classmethod
    def reset_models(cls, envs: Sequence[BaseEnv], options: dict[str, Any] | None) -> tuple[np.ndarray, list]:
        """:meth:`reset_model` for all worlds at once: each world's draws, one stacked write and ``forward``."""
        reachers: Sequence[ReacherEnv] = envs  # type: ignore[assignment]
        n = len(reachers)
        first = reachers[0]
        qpos, qvel = np.empty((n, first.model.nq)), np.empty((n, first.model.nv))
        for j, env in enumerate(reachers):
            qpos[j], qvel[j] = env._draw_start()
        state = stacked(envs)
        state.set("qpos", qpos)
        state.set("qvel", qvel)
        state.forward()
        xpos = state.get("xpos")
        vec = xpos[:, first._fingertip] - xpos[:, first._target]
        return _stacked_obs(state.get("qpos"), state.get("qvel"), vec), [{} for _ in range(n)]

    def prepare_step(self, action: np.ndarray | None) -> None:
        self.data.ctrl[:] = 0.0 if action is None else action

    def post_step(self, action: np.ndarray | None) -> tuple[np.ndarray, float, bool, dict[str, Any]]:
        # Like Gymnasium, distance uses body positions as left by mj_step.
        vec = self.data.xpos[self._fingertip] - self.data.xpos[self._target]
        # Reacher-v5's types: reward_dist np.float64, reward_ctrl np.float32 (the
        # float32 sum of squares of a float32 action), reward their np.float64 sum.
        reward_dist = -np.linalg.norm(vec) * self.reward_dist_weight
        ctrl = np.float32(0.0) if action is None else np.square(action, dtype=np.float32).sum()
        reward_ctrl = -ctrl * np.float32(self.reward_control_weight)
        info = {"reward_dist": reward_dist, "reward_ctrl": reward_ctrl}
        return self._obs(vec), reward_dist + reward_ctrl, False, info

    @classmethod
    def prepare_steps(cls, envs: Sequence[BaseEnv], actions: np.ndarray) -> None:
        stacked(envs).set("ctrl", actions)

    @classmethod
    def post_steps(cls, envs: Sequence[BaseEnv], actions: np.ndarray) -> BatchResult:
        """:meth:`post_step` for all worlds at once, with numpy over their stacked state."""
        reachers: Sequence[ReacherEnv] = envs  # type: ignore[assignment]
        tip, target = reachers[0]._fingertip, reachers[0]._target
        state = stacked(envs)
        qpos, qvel, xpos = state.get("qpos"), state.get("qvel"), state.get("xpos")
        vec = xpos[:, tip] - xpos[:, target]
        dist_w, ctrl_w = _stacked_weights(reachers)
        # The same operations as post_step, so the numbers (and types) match
        # exactly: a stacked matmul is the dot product np.linalg.norm takes;
        # a weight of 1 everywhere is left out (multiplying by 1 changes no bit).
        reward_dist = -np.sqrt(np.matmul(vec[:, None, :], vec[:, :, None])[:, 0, 0])
        reward_ctrl = -np.square(actions, dtype=np.float32).sum(axis=1)
        if dist_w is not None:
            reward_dist *= dist_w
        if ctrl_w is not None:
            reward_ctrl *= ctrl_w
        return BatchResult(
            _stacked_obs(qpos, qvel, vec),
            reward_dist + reward_ctrl,
            np.zeros(len(reachers), dtype=np.bool_),
            {"reward_dist": reward_dist, "reward_ctrl": reward_ctrl},
        )

    def _obs(self, tip_minus_target: np.ndarray | None = None) -> np.ndarray:
        qpos, qvel = self.data.qpos, self.data.qvel
        if tip_minus_target is None:
            tip_minus_target = self.data.xpos[self._fingertip] - self.data.xpos[self._target]
        obs = np.empty(10)
        np.cos(qpos[:2], out=obs[0:2])
        np.sin(qpos[:2], out=obs[2:4])
        obs[4:6] = qpos[2:]
        obs[6:8] = qvel[:2]
        obs[8:10] = tip_minus_target[:2]
        return obs


def _stacked_obs(qpos: np.ndarray, qvel: np.ndarray, tip_minus_target: np.ndarray) -> np.ndarray:
    """The observations ``(n, 10)`` of worlds with stacked state, as :meth:`ReacherEnv._obs` per world."""
    angles = qpos[:, :2]
    return np.concatenate(
        (np.cos(angles), np.sin(angles), qpos[:, 2:], qvel[:, :2], tip_minus_target[:, :2]), axis=1, dtype=np.float64
    )


def _stacked_weights(reachers: Sequence[ReacherEnv]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """:func:`_weights` of the worlds ``reachers``, kept on that list of worlds
    while no world's weight has been set since (:attr:`ReacherEnv.weights_version`).
    The stepper hands every step of all its worlds the same list, built once and
    never changed, so such a step reads no world's weights; any other list is
    read when it comes, a plain ``list`` (which takes no attributes) every time."""
    memo = getattr(reachers, "__dict__", None)
    version = ReacherEnv.weights_version
    if memo is not None:
        known = memo.get("_reacher_weights")
        if known is not None and known[0] == version:
            return known[1]
    weights = _weights(
        tuple([env.reward_dist_weight for env in reachers]), tuple([env.reward_control_weight for env in reachers])
    )
    if memo is not None:
        memo["_reacher_weights"] = (version, weights)
    return weights


@functools.lru_cache(maxsize=16)
def _weights(dist: tuple[float, ...], control: tuple[float, ...]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The worlds' reward weights as arrays (float64 and float32, as post_step
    multiplies them), each None where every world's weight is 1."""
    dist_w = None if all(w == 1.0 for w in dist) else np.array(dist, dtype=np.float64)
    control_w = None if all(w == 1.0 for w in control) else np.array(control, dtype=np.float32)
    for weights in (dist_w, control_w):
        if weights is not None:
            weights.setflags(write=False)
    return dist_w, control_w


def main(argv: list[str] | None = None) -> None:
    run_scene(ReacherEnv, argv, description=__doc__)


if __name__ == "__main__":
    main()
