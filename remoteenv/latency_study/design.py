"""What the delay-effect study trains: its grid of cells and the learner's settings.

Agent side. A *cell* is one training run: a variant (what the policy sees), a
delay model (constant ``k`` ticks or ``Uniform(0, k)``), the delay ``k`` in
control ticks, and a seed. :func:`cells` lists every cell of a
:class:`StudyConfig` in a fixed order, so a study can be resumed and its
records compared across runs.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from typing import Any

from remoteenv.delays import DelaySpec, Uniform

#: What the policy sees. ``plain``: the env's observation only (delay-unaware).
#: ``history``: the observation followed by the last actions sent
#: (:class:`remoteenv.wrappers.ActionHistory`): ``k`` of them for a constant
#: delay ``k``; for random delays ``k + 1`` (enough to hold the action in
#: force at any delay, :func:`remoteenv.wrappers.required_history`) and the
#: age of that action, alpha (``include_alpha``).
VARIANTS = ("plain", "history")

#: Delay models: ``constant`` is ``action_delay=k``; ``uniform`` is
#: ``action_delay=Uniform(0, k)`` (each action's delay drawn independently).
KINDS = ("constant", "uniform")

#: Stable-Baselines3 PPO settings: rl-baselines3-zoo's tuned set for
#: CartPole-v1 (8 envs, 32 steps each per update, batch 256, 20 epochs, GAE
#: lambda 0.8, learning rate and clip range decaying linearly from 1e-3 and
#: 0.2, no entropy bonus), with SB3's default MLP policy (64-64, tanh), and two
#: changes, both measured:
#:
#: - observations normalised by running statistics (SB3's ``VecNormalize``,
#:   observations only), as rl-baselines3-zoo does for its continuous-control
#:   tasks: the action history's entries and the state's velocities differ in
#:   scale; without it the history policy at k = 12 stopped at a return of ~150;
#: - ``gamma`` 0.995 instead of 0.98: with 0.98 a policy that balances the pole
#:   but lets the cart drift off the track ~150 steps later loses almost
#:   nothing it can see (0.98**150 ~ 0.05), and PPO settled on such policies
#:   (returns 135-180 on 2 of 3 seeds of the history variant at k = 4).
#:
#: The decaying schedules and the normalisation are applied in
#: :mod:`remoteenv.latency_study.training`.
PPO_SETTINGS: dict[str, Any] = {
    "normalize_obs": True,
    "n_envs": 8,
    "n_steps": 32,
    "batch_size": 256,
    "n_epochs": 20,
    "gae_lambda": 0.8,
    "gamma": 0.995,
    "ent_coef": 0.0,
    "learning_rate": 1e-3,
    "clip_range": 0.2,
}


@dataclass(frozen=True)
class StudyConfig:
    """One study: the env, the delays, the seeds and the training budget.

    Args:
        env_id: a registered Gymnasium id whose env has a Box observation and
            a Box or Discrete action space (e.g. ``remoteenv/CartPole-v0``).
        env_kwargs: keyword arguments for ``gym.make``/``gym.make_vec``.
        delays: constant action delays to train at, in control ticks.
        random_delays: ``k`` of the ``Uniform(0, k)`` delays to train at (ticks).
        seeds: one training run per seed and cell.
        steps: environment steps (over all training worlds) per training run.
        eval_episodes: deterministic evaluation episodes per trained policy.
        eval_seed: evaluation episode ``i`` resets with seed ``eval_seed + i``.
        ppo: overrides of :data:`PPO_SETTINGS`.
    """

    env_id: str = "remoteenv/CartPole-v0"
    env_kwargs: dict[str, Any] = field(default_factory=lambda: {"continuous": True})
    delays: tuple[int, ...] = (0, 4, 8, 12)
    random_delays: tuple[int, ...] = (8, 16, 24)
    seeds: tuple[int, ...] = (0, 1, 2)
    steps: int = 300_000
    eval_episodes: int = 10
    eval_seed: int = 10_000
    ppo: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("delays", "random_delays", "seeds"):
            values = getattr(self, name)
            if any(isinstance(v, bool) or not isinstance(v, int) or v < 0 for v in values):
                raise ValueError(f"StudyConfig.{name} must be integers >= 0, got {values!r:.100}")
        if not self.delays and not self.random_delays:
            raise ValueError("StudyConfig needs at least one delay (delays or random_delays)")
        if not self.seeds:
            raise ValueError("StudyConfig needs at least one seed")
        if self.steps < 1 or self.eval_episodes < 1:
            raise ValueError(
                f"StudyConfig needs steps >= 1 and eval_episodes >= 1, got {self.steps}, {self.eval_episodes}"
            )
        unknown = set(self.ppo) - set(PPO_SETTINGS)
        if unknown:
            raise ValueError(f"unknown PPO settings {sorted(unknown)}; known: {sorted(PPO_SETTINGS)}")

    @property
    def ppo_settings(self) -> dict[str, Any]:
        """:data:`PPO_SETTINGS` with this study's overrides."""
        return {**PPO_SETTINGS, **self.ppo}

    def to_json(self) -> dict[str, Any]:
        """A JSON map of the configuration (lists for tuples)."""
        return json.loads(json.dumps(asdict(self)))

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> StudyConfig:
        fields = dict(data)
        for name in ("delays", "random_delays", "seeds"):
            fields[name] = tuple(fields.get(name, ()))
        return cls(**fields)


@dataclass(frozen=True)
class Cell:
    """One training run of the study (see the module docs)."""

    variant: str
    kind: str
    delay: int
    seed: int

    @property
    def key(self) -> tuple[str, str, int, int]:
        return (self.variant, self.kind, self.delay, self.seed)

    @property
    def history_length(self) -> int:
        """Actions the policy sees, none for ``plain``; for ``history`` the
        most that can be in flight (``k``) under a constant delay, and under
        random delays one more, so the buffer holds the action in force even
        at its largest age ``k`` (:func:`remoteenv.wrappers.required_history`)."""
        if self.variant != "history":
            return 0
        return self.delay + 1 if self.kind == "uniform" else self.delay

    @property
    def include_alpha(self) -> bool:
        """``history`` under random delays also sees alpha, the age of the action in force."""
        return self.variant == "history" and self.kind == "uniform"

    @property
    def uses_wrapper(self) -> bool:
        return self.history_length > 0 or self.include_alpha

    def delay_spec(self) -> int | DelaySpec:
        """The ``action_delay`` to pass to the env."""
        return Uniform(0, self.delay) if self.kind == "uniform" else self.delay

    def label(self) -> str:
        model = f"Uniform(0, {self.delay})" if self.kind == "uniform" else f"{self.delay}"
        return f"{self.variant} delay={model} seed={self.seed}"


def cells(config: StudyConfig) -> Iterator[Cell]:
    """Every cell of ``config``: constant delays first, then random ones; per
    delay each variant, per variant each seed."""
    for kind, delays in (("constant", config.delays), ("uniform", config.random_delays)):
        for delay in delays:
            for variant in VARIANTS:
                for seed in config.seeds:
                    yield Cell(variant, kind, delay, seed)
