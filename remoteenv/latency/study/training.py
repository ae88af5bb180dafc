"""Train and evaluate one cell of the delay-effect study (agent side; needs
Stable-Baselines3 and torch).

:func:`run_cell` trains SB3 PPO (:data:`~remoteenv.latency.study.design.PPO_SETTINGS`)
on ``n_envs`` lock-step worlds of the study's env, all in one sim process,
with the cell's action delay, then evaluates the deterministic policy on a
fresh single env under the same delay model. Lock-step makes a cell repeat:
the same configuration and seed give the same record (up to torch's own
floating-point determinism on the host).
"""

from __future__ import annotations

import io
import os
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from remoteenv.latency.action_history import ActionHistory, ActionHistoryVector, is_image
from remoteenv.latency.study.design import Cell, StudyConfig
from remoteenv.latency.study.trainable_spaces import policy_for
from remoteenv.wire.files.file_reads import read_bytes

#: Largest saved policy file read back (an SB3 zip of an MLP policy is well under 1 MiB).
MAX_POLICY_BYTES = 256 << 20
#: Training curve resolution: one point per this many environment steps.
CURVE_EVERY = 10_000
#: Episodes averaged into one point of the training curve.
CURVE_WINDOW = 20

Policy = Callable[[np.ndarray], Any]


class TrainedPolicy:
    """A trained PPO policy as a function of one observation: the deterministic
    (mean) action, after the observation normalisation it was trained with.

    Saved as two files: the SB3 model (``<path>.zip``, SB3's format) and the
    normalisation statistics (``<path>.npz``: ``mean``, ``var``, ``clip``,
    ``epsilon``, and for a Dict observation ``mean/<key>`` and ``var/<key>``
    for each normalised key instead; absent when the policy was trained without it)."""

    def __init__(self, model: Any, obs_stats: dict[str, np.ndarray] | None) -> None:
        self.model = model
        self.obs_stats = obs_stats

    def _scaled(self, obs: Any, mean: np.ndarray, var: np.ndarray) -> np.ndarray:
        s = self.obs_stats
        assert s is not None
        scaled = (np.asarray(obs, dtype=np.float64) - mean) / np.sqrt(var + float(s["epsilon"]))
        return np.clip(scaled, -float(s["clip"]), float(s["clip"])).astype(np.float32)

    def normalize(self, obs: Any) -> Any:
        s = self.obs_stats
        if isinstance(obs, dict):  # normalised keys as trained; images and the rest as they are
            if s is None:
                return obs
            return {
                k: self._scaled(v, s[f"mean/{k}"], s[f"var/{k}"]) if f"mean/{k}" in s else v for k, v in obs.items()
            }
        if s is None:
            return obs if np.asarray(obs).dtype == np.uint8 else np.asarray(obs, dtype=np.float32)
        return self._scaled(obs, s["mean"], s["var"])

    def __call__(self, obs: np.ndarray) -> Any:
        action, _ = self.model.predict(self.normalize(obs), deterministic=True)
        return action

    def save(self, path: str) -> None:
        self.model.save(path + ".zip")
        if self.obs_stats is not None:
            np.savez(path + ".npz", **self.obs_stats)  # type: ignore[arg-type]

    @classmethod
    def load(cls, path: str) -> TrainedPolicy:
        from stable_baselines3 import PPO

        # Through the bounded reader (regular files, no blocking open, a size bound).
        model = PPO.load(io.BytesIO(read_bytes(path + ".zip", MAX_POLICY_BYTES, what="policy")), device="cpu")
        stats = None
        if os.path.exists(path + ".npz"):
            data = read_bytes(path + ".npz", MAX_POLICY_BYTES, what="policy statistics")
            with np.load(io.BytesIO(data), allow_pickle=False) as f:
                stats = {k: np.array(f[k]) for k in f.files}
        return cls(model, stats)


def make_train_env(config: StudyConfig, cell: Cell) -> Any:
    """The SB3 vector env a cell trains on (SAME_STEP autoreset: one round
    trip per step even when an episode ends), observations normalised if the
    settings say so (the returns the monitor records are the env's own):
    a Box of values whole, a Dict's non-image entries; images never (SB3's
    CNN scales them itself)."""
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from remoteenv.integrations.sb3 import SB3VecEnv

    venv = gym.make_vec(
        config.env_id,
        num_envs=int(config.ppo_settings["n_envs"]),
        vectorization_mode="vector_entry_point",
        action_delay=cell.delay_spec(),
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
        **config.env_kwargs,
    )
    if cell.uses_wrapper:
        venv = ActionHistoryVector(venv, cell.history_length, include_alpha=cell.include_alpha)
    env: Any = VecMonitor(SB3VecEnv(venv))
    if config.ppo_settings["normalize_obs"]:
        space = env.observation_space
        if isinstance(space, gym.spaces.Dict):
            keys = [k for k, sub in space.spaces.items() if isinstance(sub, gym.spaces.Box) and not is_image(sub)]
            if keys:
                env = VecNormalize(env, norm_obs=True, norm_reward=False, norm_obs_keys=keys)
        elif not is_image(space):
            env = VecNormalize(env, norm_obs=True, norm_reward=False)
    return env


def make_eval_env(config: StudyConfig, cell: Cell) -> gym.Env:
    """A single env with the cell's delay model and observation."""
    env = gym.make(config.env_id, action_delay=cell.delay_spec(), **config.env_kwargs)
    if cell.uses_wrapper:
        env = ActionHistory(env, cell.history_length, include_alpha=cell.include_alpha)
    return env


def evaluate(env: gym.Env, policy: Policy, episodes: int, first_seed: int) -> list[float]:
    """Returns of ``episodes`` episodes; episode ``i`` resets with ``first_seed + i``."""
    returns = []
    for i in range(episodes):
        obs, _ = env.reset(seed=first_seed + i)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total += float(reward)
            done = bool(terminated or truncated)
        returns.append(total)
    return returns


def delay_facts(env: gym.Env) -> dict[str, float | None]:
    """What the delays did over the episodes ``env`` ran, from its
    ``env.unwrapped.latency_stats``: ``mean_age_ticks``, the mean age of the
    action in force per tick (alpha), and ``dropped_fraction``, the fraction of
    the actions sent that never took effect (overtaken by a newer one, or in
    flight when their episode ended). None where the env reported no delays
    (no action delay: every action acts at once, aged 0)."""
    stats = getattr(env.unwrapped, "latency_stats", None)
    if stats is None or not stats.action_age_ticks.count:
        return {"mean_age_ticks": None, "dropped_fraction": None}
    return {
        "mean_age_ticks": float(stats.action_age_ticks.mean),
        "dropped_fraction": stats.never_acted_fraction,
    }


def _linear(start: float) -> Callable[[float], float]:
    def schedule(progress_remaining: float) -> float:
        return progress_remaining * start

    return schedule


def train(
    config: StudyConfig, cell: Cell, progress: Callable[[int], None] | None = None
) -> tuple[TrainedPolicy, dict[str, Any]]:
    """Train PPO on ``cell``; the policy and a dict with the training curve and time.

    ``progress(steps)`` is called at every curve point with the steps done.
    """
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import Logger

    settings = config.ppo_settings
    curve: list[list[float]] = []

    class Curve(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps - (len(curve) * CURVE_EVERY) >= CURVE_EVERY:
                returns = [float(e["r"]) for e in list(self.model.ep_info_buffer or ())[-CURVE_WINDOW:]]
                curve.append([float(self.num_timesteps), float(np.mean(returns)) if returns else float("nan")])
                if progress is not None:
                    progress(self.num_timesteps)
            return True

    torch.set_num_threads(1)
    env = make_train_env(config, cell)
    started = time.perf_counter()
    try:
        model = PPO(
            policy_for(env.observation_space),
            env,
            n_steps=int(settings["n_steps"]),
            batch_size=int(settings["batch_size"]),
            n_epochs=int(settings["n_epochs"]),
            gae_lambda=float(settings["gae_lambda"]),
            gamma=float(settings["gamma"]),
            ent_coef=float(settings["ent_coef"]),
            learning_rate=_linear(float(settings["learning_rate"])),
            clip_range=_linear(float(settings["clip_range"])),
            policy_kwargs={"net_arch": [int(n) for n in settings["net_arch"]]},
            seed=cell.seed,
            device="cpu",
            verbose=0,
        )
        model.set_logger(Logger(None, []))  # SB3's default logger makes a /tmp/SB3-<time> folder
        model.learn(config.steps, callback=Curve())
        recent = [float(e["r"]) for e in list(model.ep_info_buffer or ())[-CURVE_WINDOW:]]
        stats = None
        if hasattr(env, "obs_rms"):
            rms = env.obs_rms
            stats = {"clip": np.array(env.clip_obs), "epsilon": np.array(env.epsilon)}
            for key, one in rms.items() if isinstance(rms, dict) else [(None, rms)]:
                suffix = "" if key is None else f"/{key}"
                stats[f"mean{suffix}"], stats[f"var{suffix}"] = np.array(one.mean), np.array(one.var)
    finally:
        env.close()
    return TrainedPolicy(model, stats), {
        "train_s": time.perf_counter() - started,
        "train_return": float(np.mean(recent)) if recent else None,
        "curve": curve,
    }


def policy_path(policy_dir: str, cell: Cell) -> str:
    """Where :func:`run_cell` saves a cell's trained policy (see :class:`TrainedPolicy`)."""
    return os.path.join(policy_dir, f"{cell.variant}-{cell.kind}-{cell.delay}-seed{cell.seed}")


def run_cell(
    config: StudyConfig, cell: Cell, policy_dir: str | None = None, progress: Callable[[int], None] | None = None
) -> dict[str, Any]:
    """Train and evaluate one cell; its record for ``delay_effect.json``. With
    ``policy_dir`` the trained policy is saved at :func:`policy_path`;
    ``progress(steps)`` is told the training steps done (see :func:`train`)."""
    policy, trained = train(config, cell, progress)
    if policy_dir is not None:
        policy.save(policy_path(policy_dir, cell))
    env = make_eval_env(config, cell)
    try:
        returns = evaluate(env, policy, config.eval_episodes, config.eval_seed)
        ages = delay_facts(env)
    finally:
        env.close()
    return {
        "variant": cell.variant,
        "kind": cell.kind,
        "delay": cell.delay,
        "seed": cell.seed,
        "mean_return": float(np.mean(returns)),
        "returns": returns,
        "history_length": cell.history_length,
        "include_alpha": cell.include_alpha,
        "steps": config.steps,
        **ages,
        **trained,
    }
