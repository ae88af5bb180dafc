"""Nothing from the future: no lock-step info field tells a delay that has not elapsed.

Over 10^5 steps of random delays (the pure engine, both delivery rules,
delayed rewards, episodes that end), every value a delayed step reports is
correlated with every *undelivered* delay: at step ``t``, the delay ``d_s`` of
each action sent at ``s <= t`` whose own delay has not elapsed
(``s + d_s > t``), and the delay ``o_n`` of each observation produced at
``n <= t`` with ``n + o_n > t``. What a delayed agent may know about such a
delay is only that it has not elapsed, which says more the younger the item
is; so the delays are compared within their age ``t - s`` (or ``t - n``):
centred and scaled per age, then pooled. Without a leak every such
correlation is 0 in expectation; ``|corr| <= 0.01`` is asserted. The
``latency_ticks`` lock-step reported before (``t + d_t - 1 - m_{t-1}``, from
the delay drawn for the action just sent, which the engine keeps for
debugging as ``sent_delay_ticks``) is the control: the same statistic must
find it.

The second half does the same for the sim's lock-step stepper itself, on a
stand-in world, in every combination of delayed rewards, observation delay
and delivery rule, over every key its replies carry (and each key's change
since the previous step). A termination is not a delay: under delayed
rewards it must stay unknown until the terminal observation arrives, which
the last test checks exactly, by running each episode twice (terminating
at tick ``N`` and not) and requiring identical replies until ``x_N`` arrives.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from remoteenv.delays import Uniform
from remoteenv.wire.delays.channel_rules import ChannelRules
from remoteenv.wire.delays.delay_line import OBS_STREAM, LockStepDelays, delay_rng
from remoteenv.wire.run_options.options import RunOptions

K = 8
STEPS = 100_000
DT = 0.02
SEED = 11


def _number(value: Any) -> float:
    """An action or info value as a number (the toy actions are their step; None: -1)."""
    return -1.0 if value is None else float(value)


#: The values a delayed step reports, as numbers: every key of the reply's
#: info (timing keys included), the returned observation, reward and flag,
#: and the engine's drop count. ActionHistory's features are among them:
#: include_alpha = obs_action_delay_ticks, include_obs_delay = obs_delay_ticks,
#: include_latency = latency_ticks (None as 0); its action buffer holds the
#: agent's own actions, which no delay changes.
FIELDS: dict[str, Callable[[dict[str, Any]], float]] = {
    "action_delay_ticks": lambda r: r["info"]["action_delay_ticks"],
    "applied_action": lambda r: _number(r["info"]["applied_action"]),
    "action_took_effect": lambda r: float(r["info"]["action_took_effect"]),
    "obs_delay_ticks": lambda r: r["info"]["obs_delay_ticks"],
    "obs_sim_time": lambda r: r["info"]["obs_sim_time"],
    "obs_action_delay_ticks": lambda r: r["info"]["obs_action_delay_ticks"],
    "obs_applied_action": lambda r: _number(r["info"]["obs_applied_action"]),
    "latency_ticks": lambda r: _number(r["info"]["latency_ticks"]),
    "latency known": lambda r: float(r["info"]["latency_ticks"] is not None),
    "late": lambda r: float(r["info"]["action_delay_ticks"] > 0),
    "sim_time": lambda r: r["step"] * DT,
    "returned obs": lambda r: float(r["obs"]),
    "reward": lambda r: r["reward"],
    "terminated": lambda r: float(r["terminated"]),
    "actions dropped so far": lambda r: r["dropped"],
}


def run(rules: ChannelRules, steps: int = STEPS) -> tuple[list[dict[str, Any]], list, list]:
    """``steps`` steps of the engine; per step its report, and the (step, age, delay)
    pairs of the undelivered action and observation delays."""
    engine = LockStepDelays(Uniform(0, K), Uniform(0, K), rules)
    obs_rng = delay_rng(SEED, OBS_STREAM)  # the documented stream: one draw per tick that runs physics
    obs_draws = 0
    world = np.random.default_rng(0)  # the toy world: random rewards, episodes ending at random ticks
    rows: list[dict[str, Any]] = []
    action_pairs: list[tuple[int, int, int]] = []
    obs_pairs: list[tuple[int, int, int]] = []
    t_global = 0
    seed: int | None = SEED
    while t_global < steps:
        engine.reset(0, 0.0, None, seed=seed)
        seed = None  # later episodes continue the streams
        actions: list[tuple[int, int]] = []  # (sent, delay) whose delay has not elapsed
        observations: list[tuple[int, int]] = []
        done = False
        held = 0  # the observation tick the agent holds when sending
        while not done and t_global < steps:
            t_global += 1
            t = engine.step + 1
            engine.apply(t)
            if engine.frozen:
                _, record = engine.observe_frozen()
            else:
                terminated = bool(world.random() < 0.01)
                _, record = engine.observe(t, t * DT, float(world.normal()), terminated)
                o = int(Uniform(0, K).sample(obs_rng, obs_draws))
                obs_draws += 1
                observations.append((t, o))
            delivered = engine.deliver(0.0, False, None)
            actions.append((t, record.sent_delay_ticks))
            actions = [(s, d) for s, d in actions if s + d > t]
            observations = [(n, o) for n, o in observations if n + o > t]
            row = len(rows)
            action_pairs += [(row, t - s, d) for s, d in actions]
            obs_pairs += [(row, t - n, o) for n, o in observations]
            rows.append(
                {
                    "step": t,
                    "info": record.info(),
                    "obs": delivered.obs,
                    "reward": delivered.reward,
                    "terminated": delivered.terminated,
                    "dropped": engine.actions_dropped,
                    "old latency_ticks": t + record.sent_delay_ticks - 1 - held,
                }
            )
            held = record.obs_tick
            done = delivered.terminated
    return rows, action_pairs, obs_pairs


def within_age_z(pairs: list[tuple[int, int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``pairs`` and their delays centred and scaled within each age."""
    p = np.asarray(pairs)
    rows, ages, delays = p[:, 0], p[:, 1], p[:, 2].astype(float)
    z = np.zeros_like(delays)
    for age in np.unique(ages):
        sel = ages == age
        sd = delays[sel].std()
        if sd > 0:
            z[sel] = (delays[sel] - delays[sel].mean()) / sd
    return rows, z


def within_age_corr(values: np.ndarray, pairs: list[tuple[int, int, int]] | tuple[np.ndarray, np.ndarray]) -> float:
    """Correlation of ``values[row]`` with the delays of ``pairs``, the delays
    centred and scaled within each age (see the module docstring); ``pairs``
    may be :func:`within_age_z`'s result."""
    rows, z = pairs if isinstance(pairs, tuple) else within_age_z(pairs)
    f = values[rows]
    if f.std() == 0:
        return 0.0
    return float(np.corrcoef(f, z)[0, 1])


RULES = {
    "newest": ChannelRules(delayed_rewards=True),
    "in_order": ChannelRules(action_delivery="in_order", obs_delivery="in_order", delayed_rewards=True),
}


@pytest.mark.parametrize("rule", list(RULES))
def test_no_reported_value_correlates_with_an_undelivered_delay(rule):
    rows, action_pairs, obs_pairs = run(RULES[rule])
    assert len(rows) == STEPS and len(action_pairs) > STEPS and len(obs_pairs) > STEPS
    found = {}
    for name, field in FIELDS.items():
        values = np.array([field(r) for r in rows], dtype=float)
        found[name] = (within_age_corr(values, action_pairs), within_age_corr(values, obs_pairs))
    print(f"\n{rule}: within-age corr with undelivered (action, observation) delays")
    for name, (ca, co) in found.items():
        print(f"  {name:24s} {ca:+.4f} {co:+.4f}")
    worst = max(found, key=lambda k: max(abs(found[k][0]), abs(found[k][1])))
    assert max(abs(c) for c in found[worst]) <= 0.01, f"{worst} leaks: {found[worst]}"
    # The control: lock-step's former latency_ticks, the delay of the action
    # just sent plus the agent's observation age, is found at once.
    old = np.array([r["old latency_ticks"] for r in rows], dtype=float)
    lag0 = [pair for pair in action_pairs if pair[1] == 0]
    pooled, newest = within_age_corr(old, action_pairs), within_age_corr(old, lag0)
    print(f"  former latency_ticks     {pooled:+.4f} (age 0 only: {newest:+.4f})")
    assert pooled > 0.1 and newest > 0.5


# ---------------------------------------------------------------------------
# Every key the sim's lock-step stepper reports, in every combination of
# delayed rewards, observation delay and delivery rule, terminations included.

FS = 4  # substeps per tick of the toy world
OBS_DELAYS = {"no obs delay": 0, "obs U(0,8)": Uniform(0, K)}
COMBOS = [(delayed, obs, rule) for delayed in (False, True) for obs in OBS_DELAYS for rule in ("newest", "in_order")]


def combo_id(combo: tuple[bool, str, str]) -> str:
    delayed, obs, rule = combo
    return f"{'delayed' if delayed else 'immediate'} rewards, {obs}, {rule}"


class ToyWorld:
    """Stands in for a BaseEnv under the lock-step stepper: observation = the
    tick's number, a random reward, the scene's own info keys, and a
    termination either at random (``p_end`` per tick) or at tick ``end_at``."""

    def __init__(self, rng: np.random.Generator, p_end: float = 0.0, end_at: int | None = None) -> None:
        from types import SimpleNamespace

        self.model = SimpleNamespace(opt=SimpleNamespace(timestep=DT / FS))
        self.frame_skip = FS
        self.dt = DT
        self.data = SimpleNamespace(time=0.0)
        self.rng, self.p_end, self.end_at = rng, p_end, end_at
        self.tick = 0

    def reset(self, *, seed: int | None, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        self.data.time = 0.0
        self.tick = 0
        return 0.0, {}

    def default_action(self) -> Any:
        return None

    def step(self, action: Any) -> tuple[Any, float, bool, dict[str, Any]]:
        self.tick += 1
        for _ in range(FS):
            self.data.time += self.model.opt.timestep
        reward = float(self.rng.normal())
        if self.p_end:
            terminated = bool(self.rng.random() < self.p_end)
        else:
            terminated = self.tick == self.end_at
        return float(self.tick), reward, terminated, {"scene_tick": self.tick, "scene_reward": reward}


def make_stepper(combo: tuple[bool, str, str], world: ToyWorld) -> Any:
    from remoteenv.sim.stepping.lock_step import LockStepper

    delayed, obs, rule = combo
    run = RunOptions(
        action_delay=Uniform(0, K),
        obs_delay=OBS_DELAYS[obs],
        action_delivery=rule,
        obs_delivery=rule,
        delayed_rewards=delayed,
    )
    return LockStepper(world, run)  # type: ignore[arg-type]


def reply_values(reply: dict[str, Any]) -> dict[str, float]:
    """Every value of a reply as a number: each info key (None as -1, with a
    ``<key> is None`` companion), the observation, reward and flag."""
    out = {
        "returned obs": float(reply["obs"]),
        "reward": float(reply["reward"]),
        "terminated": float(reply["terminated"]),
    }
    for key, value in reply["info"].items():
        out[key] = -1.0 if value is None else float(value)
        out[f"{key} is None"] = float(value is None)
    return out


#: Not reported: the delay drawn for the action just sent, which the statistic must find.
CONTROL = "control: delay drawn for the action just sent"


def run_stepper(combo: tuple[bool, str, str], steps: int) -> tuple[list[dict[str, float]], list, list]:
    """``steps`` steps of the sim's lock-step stepper on the toy world (episodes
    ending at random); per step every reported value and its change since the
    previous step (and the :data:`CONTROL`), and the (step, age, delay) pairs of
    the undelivered action and observation delays (re-drawn from the documented streams)."""
    from remoteenv.wire.delays.delay_line import ACTION_STREAM

    world = ToyWorld(np.random.default_rng(0), p_end=0.01)
    stepper = make_stepper(combo, world)
    obs_spec = OBS_DELAYS[combo[1]]
    action_rng, obs_rng = delay_rng(SEED, ACTION_STREAM), delay_rng(SEED, OBS_STREAM)
    action_draws = obs_draws = 0
    rows: list[dict[str, float]] = []
    action_pairs: list[tuple[int, int, int]] = []
    obs_pairs: list[tuple[int, int, int]] = []
    seed: int | None = SEED
    while len(rows) < steps:
        stepper.reset(seed=seed, options=None)
        seed = None  # later episodes continue the streams
        actions: list[tuple[int, int]] = []
        observations: list[tuple[int, int]] = []
        previous: dict[str, float] = {}
        t, done = 0, False
        while not done and len(rows) < steps:
            t += 1
            ticks_before = world.tick
            reply = stepper.step(t)
            sent_delay = int(Uniform(0, K).sample(action_rng, action_draws))
            actions.append((t, sent_delay))
            action_draws += 1
            if world.tick > ticks_before:  # a physics tick ran: it drew an observation delay
                o = 0 if not isinstance(obs_spec, Uniform) else int(obs_spec.sample(obs_rng, obs_draws))
                obs_draws += isinstance(obs_spec, Uniform)
                observations.append((t, o))
            actions = [(s, d) for s, d in actions if s + d > t]
            observations = [(n, o) for n, o in observations if n + o > t]
            values = reply_values(reply)
            row = dict(values)
            for key, value in values.items():
                row[f"change of {key}"] = value - previous.get(key, value)
            previous = values
            row[CONTROL] = float(sent_delay)
            action_pairs += [(len(rows), t - s, d) for s, d in actions]
            obs_pairs += [(len(rows), t - n, o) for n, o in observations]
            rows.append(row)
            done = bool(reply["terminated"])
    return rows, action_pairs, obs_pairs


@pytest.mark.parametrize("combo", COMBOS, ids=combo_id)
def test_no_key_the_stepper_reports_correlates_with_an_undelivered_delay(combo):
    rows, action_pairs, obs_pairs = run_stepper(combo, STEPS // 2)
    keys = sorted({k for r in rows for k in r})
    # Every key of the reply is here (the scene's and the delays' and the timing keys).
    for key in ("sim_time", "obs_sim_time", "action_delay_ticks", "latency_ticks", "late", "scene_reward"):
        assert key in keys
    hidden = [within_age_z(pairs) for pairs in (action_pairs, obs_pairs) if pairs]
    found = {}
    for key in keys:
        values = np.array([r.get(key, 0.0) for r in rows], dtype=float)
        found[key] = tuple(within_age_corr(values, z) for z in hidden)
    control = found.pop(CONTROL)[0]
    worst = max(found, key=lambda k: max(abs(c) for c in found[k]))
    print(f"\n{combo_id(combo)}: worst {worst} {found[worst]}, control {control:+.3f}")
    assert max(abs(c) for c in found[worst]) <= 0.01, f"{worst} leaks: {found[worst]}"
    assert control > 0.1  # the statistic finds a value that does depend on an undelivered delay


def run_to(combo: tuple[bool, str, str], seed: int, end_at: int | None, steps: int) -> list[tuple[dict, float]]:
    """One episode on the toy world ending at tick ``end_at`` (None: never), at
    most ``steps`` steps: each reply with the world's own clock after it."""
    world = ToyWorld(np.random.default_rng(seed), end_at=end_at)
    stepper = make_stepper(combo, world)
    stepper.reset(seed=seed, options=None)
    out = []
    for t in range(1, steps + 1):
        reply = stepper.step(t)
        out.append((reply, float(world.data.time)))
        if reply["terminated"]:
            break
    return out


@pytest.mark.parametrize("combo", COMBOS, ids=combo_id)
def test_no_key_tells_a_termination_before_its_observation_arrives(combo):
    """The same episode twice, alike up to tick ``N`` and the delays drawn: once
    terminating at ``N``, once not. Until the step that delivers ``x_N`` (and
    while the running twin has delivered nothing newer), a delayed agent
    cannot tell them apart, so every value reported must be identical. The
    world's own clock (what ``sim_time`` reported before: it stops when the
    physics freezes) is the control: the comparison finds it."""
    compared = frozen = 0
    control_differs = False
    for seed in range(60):
        end = 5 + seed % 30
        ended, running = run_to(combo, seed, end, 200), run_to(combo, seed, None, 200)
        for (a, clock_a), (b, clock_b) in zip(ended, running):
            if a["terminated"] or float(b["obs"]) > end:
                break
            assert a == b, f"seed {seed}, step {a['info'].get('sim_time')}: {a} != {b}"
            compared += 1
            if float(a["info"]["sim_time"]) > end * DT + 1e-9:
                frozen += 1
                control_differs = control_differs or clock_a != clock_b
    assert compared > 500
    delayed, obs, _ = combo
    if delayed and OBS_DELAYS[obs] != 0:  # the physics froze while the terminal observation travelled
        assert frozen > 50 and control_differs
