"""ActionHistory and ActionHistoryVector over Gymnasium's in-process envs
(CartPole-v1: Discrete actions; Pendulum-v1: Box actions)."""

from __future__ import annotations

import warnings
from collections import deque

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from remoteenv.latency.action_history import ActionHistory, ActionHistoryVector


class LatencyInfo(gym.Wrapper):
    """Puts a made-up ``latency_ticks`` in each info: 0.5 at reset, then the step count, None every 4th step."""

    def reset(self, **kwargs):
        self.t = 0
        obs, info = self.env.reset(**kwargs)
        return obs, {**info, "latency_ticks": 0.5}

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.t += 1
        info = {**info, "latency_ticks": None if self.t % 4 == 0 else float(self.t)}
        return obs, reward, terminated, truncated, info


def one_hot(a: int, n: int = 2) -> list[float]:
    return [1.0 if i == a else 0.0 for i in range(n)]


# --- single env ---------------------------------------------------------------------------------


def test_discrete_actions_are_one_hot_oldest_first_after_the_env_obs():
    env = ActionHistory(gym.make("CartPole-v1"), k=3)
    plain = gym.make("CartPole-v1")
    assert env.observation_space.shape == (4 + 3 * 2,) and env.observation_space.dtype == np.float32
    np.testing.assert_array_equal(env.observation_space.low[4:], 0)
    np.testing.assert_array_equal(env.observation_space.high[4:], 1)
    obs, _ = env.reset(seed=3)
    np.testing.assert_array_equal(obs[:4], plain.reset(seed=3)[0])
    np.testing.assert_array_equal(obs[4:], 0)
    sent: deque[list[float]] = deque([[0.0, 0.0]] * 3, maxlen=3)
    for a in [1, 0, 0, 1, 1]:
        obs, reward, terminated, truncated, _ = env.step(a)
        sent.append(one_hot(a))
        np.testing.assert_array_equal(obs[:4], plain.step(a)[0])
        np.testing.assert_array_equal(obs[4:], np.concatenate(list(sent)))
        assert env.observation_space.contains(obs)
    assert env.history.shape == (3, 2)
    obs, _ = env.reset(seed=4)
    np.testing.assert_array_equal(obs[4:], 0)


def test_box_actions_are_flattened_and_bounds_come_from_the_action_space():
    env = ActionHistory(gym.make("Pendulum-v1"), k=2)
    assert env.observation_space.shape == (3 + 2,)
    np.testing.assert_array_equal(env.observation_space.low[3:], [-2, -2])
    np.testing.assert_array_equal(env.observation_space.high[3:], [2, 2])
    env.reset(seed=0)
    actions = [np.array([0.5], np.float32), np.array([-1.5], np.float32), np.array([2.0], np.float32)]
    tails = [env.step(a)[0][3:] for a in actions]
    np.testing.assert_array_equal(tails, [[0, 0.5], [0.5, -1.5], [-1.5, 2.0]])


def test_action_bounds_are_widened_to_hold_the_zeros_of_a_fresh_history():
    env = ActionHistory(gym.wrappers.RescaleAction(gym.make("Pendulum-v1"), np.float32(1), np.float32(2)), k=2)
    np.testing.assert_array_equal(env.observation_space.low[3:], [0, 0])
    np.testing.assert_array_equal(env.observation_space.high[3:], [2, 2])
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)


@pytest.mark.filterwarnings("ignore::UserWarning")  # the checker warns about any wrapper and infinite bounds
def test_the_wrapped_env_passes_gymnasiums_checker():
    check_env(ActionHistory(gym.make("Pendulum-v1").unwrapped, k=2, include_latency=True), skip_render_check=True)
    check_env(ActionHistory(gym.make("CartPole-v1").unwrapped, k=4), skip_render_check=True)


def test_latency_feature_is_the_steps_latency_ticks_or_zero():
    env = ActionHistory(LatencyInfo(gym.make("CartPole-v1")), k=1, include_latency=True)
    assert env.observation_space.shape == (4 + 2 + 1,)
    assert env.observation_space.low[-1] == 0 and env.observation_space.high[-1] == np.inf
    obs, _ = env.reset(seed=0)
    assert obs[-1] == 0.5
    latencies = [env.step(i % 2)[0][-1] for i in range(5)]
    assert latencies == [1.0, 2.0, 3.0, 0.0, 5.0]


def test_k_zero_keeps_only_the_observation():
    env = ActionHistory(gym.make("CartPole-v1"), k=0)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4,) and env.step(1)[0].shape == (4,)


def test_a_refused_action_leaves_the_history_unchanged():
    env = ActionHistory(gym.make("CartPole-v1"), k=2)
    env.reset(seed=0)
    env.step(1)
    before = env.history
    with pytest.raises(ValueError, match="outside Discrete"):
        env.step(5)
    np.testing.assert_array_equal(env.history, before)


class MultiDiscreteActions(gym.Env):
    observation_space = gym.spaces.Box(-1, 1, (2,))
    action_space = gym.spaces.MultiDiscrete([2, 2])


def test_unsupported_spaces_and_k_are_refused_clearly():
    with pytest.raises(TypeError, match="Box and Dict observation spaces.*FlattenObservation"):
        ActionHistory(gym.make("Blackjack-v1"), k=1)
    with pytest.raises(TypeError, match="Box and Discrete action spaces, got MultiDiscrete"):
        ActionHistory(MultiDiscreteActions(), k=1)
    with pytest.raises(ValueError, match="k >= 0"):
        ActionHistory(gym.make("CartPole-v1"), k=-1)


class ImageObs(gym.Env):
    """Two-action env whose observation is an 8x6 uint8 image filled with the step count."""

    observation_space = gym.spaces.Box(0, 255, (8, 6, 3), dtype=np.uint8)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros((8, 6, 3), dtype=np.uint8), {}

    def step(self, action):
        self.t += 1
        return np.full((8, 6, 3), self.t, dtype=np.uint8), 1.0, False, self.t >= 3, {}


class DictObs(ImageObs):
    observation_space = gym.spaces.Dict(
        {"state": gym.spaces.Box(-1, 1, (2,), dtype=np.float32), "pixels": ImageObs.observation_space}
    )

    def reset(self, *, seed=None, options=None):
        image, info = super().reset(seed=seed)
        return {"state": np.zeros(2, dtype=np.float32), "pixels": image}, info

    def step(self, action):
        image, *rest = super().step(action)
        return ({"state": np.full(2, 0.5, dtype=np.float32), "pixels": image}, *rest)


@pytest.mark.parametrize("env_class", [ImageObs, DictObs])
def test_images_and_dicts_keep_the_action_features_as_a_separate_input(env_class):
    env = ActionHistory(env_class(), k=2, include_latency=True)
    space = env.observation_space
    assert isinstance(space, gym.spaces.Dict) and space["pixels"] == ImageObs.observation_space
    assert space["history"] == gym.spaces.Box(0.0, np.array([1, 1, 1, 1, np.inf], dtype=np.float32), dtype=np.float32)
    obs, _ = env.reset(seed=0)
    assert space.contains(obs) and not obs["history"].any()
    obs, *_ = env.step(1)
    obs, *_ = env.step(0)
    np.testing.assert_array_equal(obs["history"], [0, 1, 1, 0, 0])  # one-hot 1 then 0, latency 0
    assert (obs["pixels"] == 2).all() and space.contains(obs)  # the image untouched, still uint8
    if env_class is DictObs:
        np.testing.assert_array_equal(obs["state"], [0.5, 0.5])


def test_dicts_with_a_history_key_or_nested_entries_are_refused():
    class Clash(DictObs):
        observation_space = gym.spaces.Dict({"history": gym.spaces.Box(-1, 1, (2,))})

    class Nested(DictObs):
        observation_space = gym.spaces.Dict({"a": gym.spaces.Dict({"b": gym.spaces.Box(-1, 1, (2,))})})

    with pytest.raises(TypeError, match="without a 'history' key"):
        ActionHistory(Clash(), k=1)
    with pytest.raises(TypeError, match=r"flatten the nested entries \['a'\]"):
        ActionHistory(Nested(), k=1)


def test_vector_history_beside_images_in_every_autoreset_mode():
    for mode in (gym.vector.AutoresetMode.NEXT_STEP, gym.vector.AutoresetMode.SAME_STEP):
        envs = ActionHistoryVector(gym.vector.SyncVectorEnv([DictObs, DictObs], autoreset_mode=mode), k=1)
        obs, _ = envs.reset(seed=0)
        assert envs.observation_space.contains(obs)
        for _ in range(3):
            obs, _, _, truncated, infos = envs.step(np.array([1, 0]))
        assert truncated.all() and envs.observation_space.contains(obs)
        if mode == gym.vector.AutoresetMode.SAME_STEP:
            assert not obs["history"].any()  # the next episode's first observation
            np.testing.assert_array_equal(infos["final_obs"][0]["history"], [0, 1])
            assert (infos["final_obs"][1]["pixels"] == 3).all()
        else:
            np.testing.assert_array_equal(obs["history"], [[0, 1], [1, 0]])
        envs.close()


# --- vector env ---------------------------------------------------------------------------------


def cartpole_vector(n: int, mode: AutoresetMode, latency: bool = False) -> SyncVectorEnv:
    make = (lambda: LatencyInfo(gym.make("CartPole-v1"))) if latency else (lambda: gym.make("CartPole-v1"))
    return SyncVectorEnv([make for _ in range(n)], autoreset_mode=mode)


def run_vector(mode: AutoresetMode, steps: int = 80, n: int = 3, k: int = 3):
    """Step the wrapped and a plain vector env side by side with the same random actions;
    check each step against a plain per-world model of the history."""
    env = ActionHistoryVector(cartpole_vector(n, mode), k=k)
    plain = cartpole_vector(n, mode)
    assert env.single_observation_space.shape == (4 + 2 * k,)
    assert env.observation_space.shape == (n, 4 + 2 * k)
    obs, _ = env.reset(seed=1)
    np.testing.assert_array_equal(obs[:, :4], plain.reset(seed=1)[0])
    np.testing.assert_array_equal(obs[:, 4:], 0)
    model = [deque([[0.0, 0.0]] * k, maxlen=k) for _ in range(n)]
    restarting = [False] * n
    rng = np.random.default_rng(0)
    endings = 0
    for _ in range(steps):
        actions = rng.integers(0, 2, size=n)
        obs, _, term, trunc, infos = env.step(actions)
        pobs, _, pterm, ptrunc, pinfos = plain.step(actions)
        np.testing.assert_array_equal(obs[:, :4], pobs)
        assert env.observation_space.contains(obs)
        for w in range(n):
            ended = bool(term[w] or trunc[w])
            if mode == AutoresetMode.NEXT_STEP and restarting[w]:
                model[w] = deque([[0.0, 0.0]] * k, maxlen=k)  # the action was ignored
            else:
                model[w].append(one_hot(int(actions[w])))
            if mode == AutoresetMode.SAME_STEP and ended:
                final = infos["final_obs"][w]
                np.testing.assert_array_equal(final[:4], pinfos["final_obs"][w])
                np.testing.assert_array_equal(final[4:], np.concatenate(list(model[w])))
                model[w] = deque([[0.0, 0.0]] * k, maxlen=k)
            np.testing.assert_array_equal(obs[w, 4:], np.concatenate(list(model[w])), err_msg=f"world {w}")
            restarting[w] = ended
            endings += ended
    assert endings >= 3  # the autoreset paths did run
    return env


def test_vector_next_step_autoreset_zeros_the_history_of_a_restarted_world():
    run_vector(AutoresetMode.NEXT_STEP)


def test_vector_same_step_autoreset_zeros_the_history_and_augments_final_obs():
    run_vector(AutoresetMode.SAME_STEP)


def test_vector_disabled_autoreset_zeros_only_the_worlds_reset_by_mask():
    env = ActionHistoryVector(cartpole_vector(3, AutoresetMode.DISABLED), k=2)
    env.reset(seed=0)
    ended = np.zeros(3, dtype=bool)
    while not ended.any():
        _, _, term, trunc, _ = env.step(np.array([1, 1, 0]))
        ended = term | trunc
    before = env.history
    obs, _ = env.reset(options={"reset_mask": ended})
    np.testing.assert_array_equal(obs[ended, 4:], 0)
    np.testing.assert_array_equal(obs[~ended, 4:], before[~ended].reshape(int((~ended).sum()), -1))


def test_vector_latency_feature_per_world():
    env = ActionHistoryVector(cartpole_vector(2, AutoresetMode.NEXT_STEP, latency=True), k=1, include_latency=True)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs[:, -1], 0.5)
    seen = [env.step(np.array([0, 1]))[0][:, -1].tolist() for _ in range(4)]
    assert seen == [[1.0, 1.0], [2.0, 2.0], [3.0, 3.0], [0.0, 0.0]]


def test_vector_refuses_a_bad_action_batch_before_stepping():
    env = ActionHistoryVector(cartpole_vector(2, AutoresetMode.NEXT_STEP), k=1)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="do not fit 2"):
        env.step(np.array([0, 1, 1]))
    np.testing.assert_array_equal(env.history, 0)


# --- the RDMDP features and the buffer's length ------------------------------------------------


class DelayInfo(gym.Wrapper):
    """Puts made-up delayed lock-step keys in each info: alpha = t % 3, omega = t % 2, latency t."""

    def reset(self, **kwargs):
        self.t = 0
        return self.env.reset(**kwargs)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.t += 1
        info = {**info, "obs_action_delay_ticks": self.t % 3, "obs_delay_ticks": self.t % 2, "latency_ticks": self.t}
        return obs, reward, terminated, truncated, info


def test_alpha_omega_and_latency_follow_the_actions_in_that_order():
    env = ActionHistory(
        DelayInfo(gym.make("CartPole-v1")), k=2, include_latency=True, include_alpha=True, include_obs_delay=True
    )
    assert env.observation_space.shape == (4 + 2 * 2 + 3,)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs[-3:], 0)  # absent at the reset
    for t in range(1, 5):
        obs, *_ = env.step(1)
        assert obs[-3:].tolist() == [t % 3, t % 2, t]
    only_alpha = ActionHistory(DelayInfo(gym.make("CartPole-v1")), k=1, include_alpha=True)
    only_alpha.reset(seed=0)
    assert only_alpha.step(0)[0][-1] == 1 and only_alpha.observation_space.shape == (4 + 2 + 1,)


def test_vector_alpha_and_omega_per_world_and_in_final_obs():
    make = lambda: DelayInfo(gym.make("CartPole-v1"))  # noqa: E731
    venv = SyncVectorEnv([make, make], autoreset_mode=AutoresetMode.SAME_STEP)
    env = ActionHistoryVector(venv, k=1, include_alpha=True, include_obs_delay=True)
    env.reset(seed=0)
    obs = env.step(np.array([0, 1]))[0]
    assert obs[:, -2:].tolist() == [[1, 1], [1, 1]]
    ended = False
    while not ended:
        obs, _, term, trunc, infos = env.step(np.array([1, 1]))
        ended = bool((term | trunc).any())
    w = int(np.flatnonzero(term | trunc)[0])
    t = infos["final_info"]["obs_action_delay_ticks"][w]
    assert infos["final_obs"][w][-2:].tolist() == [t, infos["final_info"]["obs_delay_ticks"][w]]


def test_the_buffer_holds_the_action_in_force_at_the_largest_delays():
    """k = K_a + K_o + 1: at the largest alpha and omega the in-force action of the
    returned tick is the oldest entry, k - 1 - omega - alpha = 0; with k one shorter it is gone."""
    from remoteenv.delays import Uniform
    from remoteenv.latency.action_history import required_history
    from remoteenv.wire.delays.delay_line import LockStepDelays

    assert required_history(Uniform(0, 8)) == 9 and required_history(3, Uniform(1, 2)) == 6
    K_a, K_o = 4, 2
    k = required_history(Uniform(0, K_a), Uniform(0, K_o))
    engine = LockStepDelays(Uniform(0, K_a), Uniform(0, K_o))
    engine.reset(None, 0.0, None, seed=3)
    sent: list[int] = []
    worst = 0
    for t in range(1, 20_000):
        engine.apply(t)
        sent.append(t)
        _, record = engine.observe(t, 0.0)
        s = record.obs_tick - record.obs_action_delay_ticks  # who sent the in-force action of the returned tick
        if s == 0:
            continue  # the default
        buffer = ([0] * k + sent)[-k:]  # zeros before the first actions, as the wrapper keeps it
        assert buffer[k - 1 - record.obs_delay_ticks - record.obs_action_delay_ticks] == s
        worst = max(worst, record.obs_delay_ticks + record.obs_action_delay_ticks)
    assert worst == K_a + K_o  # the largest case happened, so k - 1 would have missed it


def test_include_alpha_warns_when_the_env_reports_delays_the_buffer_cannot_hold():
    from gymnasium.envs.classic_control import CartPoleEnv

    class Reported(CartPoleEnv):
        """An env that reports its delays as a remoteenv env's handshake does."""

        class _Hs:
            action_delay, obs_delay = 8, 2

        handshake = _Hs()

    with pytest.warns(UserWarning, match="k >= 11"):
        ActionHistory(Reported(), k=10, include_alpha=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ActionHistory(Reported(), k=11, include_alpha=True)
        ActionHistory(Reported(), k=8)  # without alpha: the constant-delay predictor's k
