"""Lock-step: a world advances only when asked, optionally with action and observation delays.

Runs in the sim process. The same seed and the same actions give the same
trajectory in any process. :class:`LockStepper` steps one world;
:class:`LockStepping` is the server loop's strategy for all of them (no
clock: the loop just waits for requests). Both satisfy the interfaces of
:mod:`remoteenv.sim.stepping.interfaces`. The delay rules themselves (counting, the
newest due action in force, the newest arrived observation returned,
seeding) are :class:`remoteenv.wire.delays.delay_line.LockStepDelays`'s, written
down in ``docs/delays.md``.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.transport.channels import Channel, Outgoing
from remoteenv.wire.codec.scalar_types import describe_scalars
from remoteenv.wire.delays.delay_line import LockStepDelays
from remoteenv.wire.delays.delay_specs import Constant
from remoteenv.wire.messages.handshake import LOCK_STEP
from remoteenv.wire.run_options.options import RunOptions

#: The options of a lock-step world without delays.
LOCK_STEP_OPTIONS = RunOptions()


class LockStepper:
    """Advances one world by one control tick per ``step`` request.

    Without delays each action is applied in its own tick and the reply's
    ``info`` is the scene's. With ``action_delay`` and/or ``obs_delay``
    (ticks: an int, or a :class:`~remoteenv.wire.delays.delay_specs.DelaySpec`) the
    action sent with step ``t`` arrives at tick ``t + d_t`` (or later, in
    order, with ``action_delivery="in_order"``) and the step returns the
    newest observation that has arrived; during the first ticks the scene's
    default action is applied (see :meth:`BaseEnv.default_action`). The
    reply's ``info`` then also carries :meth:`StepDelays.info`'s keys
    (``action_delay_ticks``, ``applied_action``, ``action_took_effect``,
    ``obs_delay_ticks``, ``obs_sim_time``, ``obs_action_delay_ticks``,
    ``obs_applied_action``, ``latency_ticks``) and real-time mode's timing
    keys with their exact values: ``sim_time`` (the world's time after the
    tick; after a delayed-rewards termination it runs on as if the physics
    did, since the agent cannot know yet that it froze), ``ticks_elapsed`` = 1, ``latency_s`` = ``latency_ticks * dt`` (None
    with it) and ``late`` (the tick ran on an older action than this step's:
    ``action_delay_ticks > 0``). Every one is known once the tick has run: none
    tells a delay that has not elapsed. With ``delayed_rewards`` the reward,
    ``terminated`` and the scene's info are the returned observation's and
    the physics freezes at termination (see
    :mod:`remoteenv.wire.delays.delay_line`). With ``action_delay=k`` alone
    that is the old rule: the default for ``k`` ticks, then each action ``k``
    ticks late.

    Args:
        env: the world.
        run: its lock-step options: the delay models ``action_delay`` and
            ``obs_delay`` (ticks) and the channel rules (delivery, delayed
            rewards; default: newest, not delayed).
        seed: the world's launch seed: seeds the delay streams at the first
            reset when that reset brings no seed (None: OS entropy).
    """

    def __init__(self, env: BaseEnv, run: RunOptions = LOCK_STEP_OPTIONS, seed: int | None = None) -> None:
        if run.real_time:
            raise ValueError("a lock-step world's run options need real_time=False")
        action_spec = run.action_delay_spec
        obs_spec = run.obs_delay_spec
        self.env = env
        self.delays = LockStepDelays(action_spec, obs_spec, run.channel)
        #: The largest action delay (ticks); the handshake's ``action_delay``.
        self.action_delay = int(action_spec.max)
        self.has_reset = False
        self._sim_time = 0.0  # the world's time after the last tick (its clock runs on while frozen)
        self._launch_seed = seed
        self._seeded = False

    def describe(self) -> dict[str, Any]:
        """``action_delay`` (ticks; the largest one for a random model), and when
        the models are more than a constant action delay: ``obs_delay`` (the
        largest, ticks) and both specs' wire forms; with delays and rules other
        than the default, ``channel`` (:meth:`ChannelRules.to_wire`)."""
        out: dict[str, Any] = {"mode": LOCK_STEP, "action_delay": self.action_delay}
        action, obs = self.delays.action_delay, self.delays.obs_delay
        if not (isinstance(action, Constant) and obs.is_zero):
            out.update(obs_delay=int(obs.max), action_delay_spec=action.to_wire(), obs_delay_spec=obs.to_wire())
        if not self.delays.is_zero and not self.delays.rules.is_default:
            out["channel"] = self.delays.rules.to_wire()
        return out

    def reset(self, *, seed: int | None, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self.started(obs, seed, float(self.env.data.time))
        return obs, info

    def started(self, obs: Any, seed: int | None, sim_time: float) -> None:
        """The bookkeeping of a reset: the world reset with ``seed`` (None: the
        stream continued) now observes ``obs`` at ``sim_time`` (seconds).
        :meth:`reset` calls it; so does the worlds' batched reset, which
        resets the scene's worlds together (:meth:`WorldsStepper.reset`)."""
        self.has_reset = True
        if seed is None and not self._seeded:
            seed = self._launch_seed
        self._seeded = self._seeded or seed is not None
        self._sim_time = sim_time
        self.delays.reset(obs, self._sim_time, self.env.default_action(), seed=seed)

    def _tick_later(self, sim_time: float) -> float:
        """``sim_time`` one control tick later, added substep by substep as
        ``mj_step`` adds them, so a frozen world's clock reads bit for bit as a
        running one's would."""
        env = self.env
        timestep = float(env.model.opt.timestep)
        for _ in range(int(env.frame_skip)):
            sim_time += timestep
        return sim_time

    def submit(self, seq: int, action: Any, channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        """A ``step`` request: answered at once (see :meth:`step`)."""
        return self.step(action)

    def step(self, action: Any) -> dict[str, Any]:
        """One control tick with ``action`` (already checked); the reply's fields."""
        delays = self.delays
        if delays.is_zero:
            obs, reward, terminated, info = self.env.step(action)
        else:
            in_force, _ = delays.apply(action)
            tick_reward: Any
            tick_info: dict[str, Any]
            if delays.frozen:
                _, record = delays.observe_frozen()
                tick_reward, tick_terminated, tick_info = 0.0, True, {}
                self._sim_time = self._tick_later(self._sim_time)
            else:
                tick_obs, tick_reward, tick_terminated, tick_info = self.env.step(in_force)
                self._sim_time = float(self.env.data.time)
                _, record = delays.observe(
                    tick_obs, self._sim_time, float(tick_reward), bool(tick_terminated), tick_info
                )
            sent = delays.deliver(tick_reward, tick_terminated, tick_info)
            obs, reward, terminated = sent.obs, sent.reward, sent.terminated
            info = dict(sent.scene_info or {})
            info.update(record.info())
            # The timing keys of real-time mode, exact by construction here.
            info["sim_time"] = self._sim_time
            info["ticks_elapsed"] = 1
            info["latency_s"] = None if record.latency_ticks is None else record.latency_ticks * self.env.dt
            info["late"] = record.action_delay_ticks > 0
        return describe_scalars(
            {
                "obs": obs,
                # A float subclass (np.float64, as Gymnasium's MuJoCo envs return) keeps its type.
                "reward": reward if isinstance(reward, float) else float(reward),
                "terminated": bool(terminated),
                "truncated": False,
                "info": info,
            }
        )


class LockStepping:
    """The loop strategy of a lock-step server: no deadlines, every reply at once.

    Args:
        envs: the worlds, one :class:`LockStepper` each.
        run: the lock-step options of every world (the delay models and their
            channel rules); each world draws from its own streams.
        seed: launch seed of world 0 (world ``w`` uses ``seed + w``), seeding
            the delay streams until a reset brings a seed; None: OS entropy.
    """

    #: Lock-step has no clock to start.
    clock_waiting = False

    def __init__(self, envs: Sequence[BaseEnv], run: RunOptions = LOCK_STEP_OPTIONS, seed: int | None = None) -> None:
        self._worlds = [LockStepper(env, run, seed=None if seed is None else seed + w) for w, env in enumerate(envs)]

    @property
    def worlds(self) -> list[LockStepper]:
        return self._worlds

    def next_deadline(self) -> float | None:
        return None

    def start_clocks(self, now: float) -> None:
        pass

    def run_due(self, now: float) -> Iterator[Outgoing]:
        return iter(())


__all__ = ["LockStepper", "LockStepping"]
