"""What the delay-effect study trains: its grid of cells and the learner's settings.

Agent side. A *cell* is one training run: a variant (what the policy sees),
a delay model (a constant ``k`` ticks, or a random model ``U(low,high)``:
each action's delay drawn independently and uniformly from ``low .. high``
ticks, both ends included, newest-due rule), and a seed. :func:`cells`
lists every cell of a :class:`StudyConfig` in a fixed order, so a study can
be resumed and its records compared across runs. A record's ``delay`` names
the model: the int ``k`` for a constant delay, the string ``"U(6,10)"`` for
a random one.

Runs in the agent process.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from typing import Any

from remoteenv.wire.delays.delay_specs import DelaySpec, Uniform

#: What the policy sees. ``plain``: the env's observation only (delay-unaware).
#: ``history``: the observation followed by the last actions sent
#: (:class:`remoteenv.latency.action_history.ActionHistory`): ``k`` of them for a constant
#: delay ``k``; for a random model ``high + 1`` (enough to hold the action in
#: force at any delay, :func:`remoteenv.latency.action_history.required_history`) and the
#: age of that action, alpha (``include_alpha``): the RDMDP state of
#: Bouteiller et al. (2021) without observation delay. Nothing from the future.
VARIANTS = ("plain", "history")

#: Delay models: ``constant`` is ``action_delay=k``; ``random`` is
#: ``action_delay=Uniform(low, high)``.
KINDS = ("constant", "random")

_RANDOM_NAME = re.compile(r"U\((\d{1,4}),(\d{1,4})\)")


def random_model(name: str) -> Uniform:
    """The delay spec a random model's name stands for: ``"U(6,10)"`` is
    ``Uniform(6, 10)`` in ticks (no spaces; ``low <= high``)."""
    match = _RANDOM_NAME.fullmatch(name) if isinstance(name, str) else None
    if match is None:
        raise ValueError(f"a random delay model is named like 'U(6,10)' (ticks, low <= high), got {name!r:.60}")
    low, high = int(match.group(1)), int(match.group(2))
    if low > high:
        raise ValueError(f"random delay model {name!r}: low {low} > high {high}")
    return Uniform(low, high)


def random_name(low: int, high: int) -> str:
    """The name of ``Uniform(low, high)`` in a study: ``"U(low,high)"``."""
    return f"U({int(low)},{int(high)})"


#: Stable-Baselines3 PPO settings: rl-baselines3-zoo's tuned set for
#: CartPole-v1 (8 envs, batch 256, learning rate and clip range decaying
#: linearly from 1e-3 and 0.2, no entropy bonus), with SB3's default MLP
#: policy (64-64, tanh), and three changes, each measured:
#:
#: - observations normalised by running statistics (SB3's ``VecNormalize``,
#:   observations only), as rl-baselines3-zoo does for its continuous-control
#:   tasks: the action history's entries and the state's velocities differ in
#:   scale; without it the history policy at k = 12 stopped at a return of ~150;
#: - ``gamma`` 0.995 instead of 0.98: with 0.98 a policy that balances the pole
#:   but lets the cart drift off the track ~150 steps later loses almost
#:   nothing it can see (0.98**150 ~ 0.05), and PPO settled on such policies
#:   (returns 135-180 on 2 of 3 seeds of the history variant at k = 4);
#: - 128 steps per env per update (1,024 in all), 10 epochs and GAE lambda
#:   0.95 instead of the zoo's 32, 20 and 0.8: an action acts 6 to 16 ticks
#:   after it is sent, and lambda 0.8 discounts its effect on the advantage
#:   by 0.8**8 ~ 0.17 before it shows. With the zoo's values the history +
#:   alpha policy under U(6,10) reached 168 in 300,000 steps (a 256-256
#:   network: 62); with these, 446 (seed 0), and the history policy at the
#:   constant delay 12 on its weakest seed (2) went from 353 to 500.
#:
#: The decaying schedules and the normalisation are applied in
#: :mod:`remoteenv.latency.study.training`.
PPO_SETTINGS: dict[str, Any] = {
    "normalize_obs": True,
    "n_envs": 8,
    "n_steps": 128,
    "batch_size": 256,
    "n_epochs": 10,
    "gae_lambda": 0.95,
    "gamma": 0.995,
    "ent_coef": 0.0,
    "learning_rate": 1e-3,
    "clip_range": 0.2,
    "net_arch": [64, 64],
}


@dataclass(frozen=True)
class StudyConfig:
    """One study: the env, the delays, the seeds and the training budget.

    Args:
        env_id: a registered Gymnasium id whose env has a Box observation and
            a Box or Discrete action space (e.g. ``remoteenv/CartPole-v0``).
        env_kwargs: keyword arguments for ``gym.make``/``gym.make_vec``.
        delays: constant action delays to train at, in control ticks.
        random_delays: random delay models to train at, by name (``"U(6,10)"``,
            :func:`random_model`).
        seeds: one training run per seed and cell.
        steps: environment steps (over all training worlds) per training run.
        eval_episodes: deterministic evaluation episodes per trained policy.
        eval_seed: evaluation episode ``i`` resets with seed ``eval_seed + i``.
        ppo: overrides of :data:`PPO_SETTINGS`.
    """

    env_id: str = "remoteenv/CartPole-v0"
    env_kwargs: dict[str, Any] = field(default_factory=lambda: {"continuous": True})
    delays: tuple[int, ...] = (0, 8, 12)
    random_delays: tuple[str, ...] = ("U(4,8)", "U(6,10)", "U(8,16)", "U(0,16)")
    seeds: tuple[int, ...] = (0, 1, 2)
    steps: int = 400_000
    eval_episodes: int = 10
    eval_seed: int = 10_000
    ppo: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("delays", "seeds"):
            values = getattr(self, name)
            if any(isinstance(v, bool) or not isinstance(v, int) or v < 0 for v in values):
                raise ValueError(f"StudyConfig.{name} must be integers >= 0, got {values!r:.100}")
        for model in self.random_delays:
            random_model(model)
        if len(set(self.random_delays)) != len(self.random_delays) or len(set(self.delays)) != len(self.delays):
            raise ValueError(f"StudyConfig lists a delay twice: {self.delays!r:.100}, {self.random_delays!r:.100}")
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
    """One training run of the study (see the module docs): ``delay`` is the
    int ``k`` for ``kind="constant"``, a model name (``"U(6,10)"``) for ``"random"``."""

    variant: str
    kind: str
    delay: int | str
    seed: int

    @property
    def key(self) -> tuple[str, str, int | str, int]:
        return (self.variant, self.kind, self.delay, self.seed)

    @property
    def history_length(self) -> int:
        """Actions the policy sees, none for ``plain``; for ``history`` the
        most that can be in flight (``k``) under a constant delay, and under a
        random model one more than its largest delay, so the buffer holds the
        action in force even at its largest age
        (:func:`remoteenv.latency.action_history.required_history`)."""
        if self.variant != "history":
            return 0
        if self.kind == "random":
            return int(random_model(str(self.delay)).high) + 1
        return int(self.delay)

    @property
    def include_alpha(self) -> bool:
        """``history`` under random delays also sees alpha, the age of the action in force."""
        return self.variant == "history" and self.kind == "random"

    @property
    def uses_wrapper(self) -> bool:
        return self.history_length > 0 or self.include_alpha

    def delay_spec(self) -> int | DelaySpec:
        """The ``action_delay`` to pass to the env."""
        return random_model(str(self.delay)) if self.kind == "random" else int(self.delay)

    def label(self) -> str:
        return f"{self.variant} delay={self.delay} seed={self.seed}"


def cells(config: StudyConfig) -> Iterator[Cell]:
    """Every cell of ``config``: constant delays first, then random ones; per
    delay each variant, per variant each seed. The history variant at the
    constant delay 0 is the plain one (no action in flight) and is not repeated."""
    grid: tuple[tuple[str, tuple[int | str, ...]], ...] = (
        ("constant", config.delays),
        ("random", config.random_delays),
    )
    for kind, delays in grid:
        for delay in delays:
            for variant in VARIANTS:
                if kind == "constant" and delay == 0 and variant == "history":
                    continue
                for seed in config.seeds:
                    yield Cell(variant, kind, delay, seed)
