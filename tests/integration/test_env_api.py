"""OpenAIRemoteEnv through gymnasium.make: Gymnasium semantics, scenes, errors, cleanup."""

from __future__ import annotations

import os
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import remoteenv
from remoteenv import controllers

HERE = os.path.dirname(os.path.abspath(__file__))


@pytest.fixture
def make():
    """gym.make that closes every env the test made."""
    envs = []

    def _make(env_id, **kwargs):
        env = gym.make(env_id, **kwargs)
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()


@pytest.mark.parametrize("env_id", ["remoteenv/CartPole-v0", "remoteenv/Reacher-v0"])
def test_gymnasium_env_checker_passes(make, env_id):
    from gymnasium.utils.passive_env_checker import env_render_passive_checker

    env = make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # check_env's render check opens every declared render mode, "human"
        # included, which needs a display; check rgb_array rendering by hand.
        check_env(env.unwrapped, skip_render_check=True)
        env_render_passive_checker(env.unwrapped)
    # Reacher's observation space is unbounded, as Gymnasium's Reacher-v5's is.
    unexpected = [str(w.message) for w in caught if "infinity" not in str(w.message)]
    assert not unexpected


def test_cartpole_continuous_passes_env_checker(make):
    env = make("remoteenv/CartPole-v0", continuous=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
    assert not [str(w.message) for w in caught]


def test_spaces_and_metadata_come_from_the_scene(make):
    cart = make("remoteenv/CartPole-v0")
    assert cart.action_space == gym.spaces.Discrete(2)
    assert cart.observation_space.shape == (4,) and cart.observation_space.dtype == np.float32
    assert cart.metadata["render_fps"] == 50
    assert cart.unwrapped.dt == pytest.approx(0.02)
    assert cart.spec.max_episode_steps == 500
    cont = make("remoteenv/CartPole-v0", continuous=True)  # kwargs reach the scene
    assert cont.action_space == gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    reacher = make("remoteenv/Reacher-v0")
    assert reacher.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    assert reacher.observation_space == gym.spaces.Box(-np.inf, np.inf, (10,), np.float64)
    assert reacher.spec.max_episode_steps == 50


def _rollout(env, seed, actions):
    obs, _ = env.reset(seed=seed)
    traj = [obs]
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        traj.append((obs, reward, terminated, truncated, sorted(info.items())))
        if terminated or truncated:
            traj.append(env.reset()[0])
    return traj


def _assert_same(t1, t2):
    assert len(t1) == len(t2)
    for a, b in zip(t1, t2):
        if isinstance(a, tuple):
            np.testing.assert_array_equal(a[0], b[0])
            assert a[1:] == b[1:]
        else:
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("env_id", ["remoteenv/CartPole-v0", "remoteenv/Reacher-v0"])
def test_same_seed_same_trajectory_in_separate_processes(make, env_id):
    env1, env2 = make(env_id), make(env_id)
    assert env1.unwrapped.pid != env2.unwrapped.pid
    env1.action_space.seed(5)
    actions = [env1.action_space.sample() for _ in range(120)]
    t1 = _rollout(env1, 123, actions)
    t2 = _rollout(env2, 123, actions)
    _assert_same(t1, t2)
    t3 = _rollout(env1, 124, actions)
    assert not np.array_equal(t1[0], t3[0])


def test_pipe_and_zeromq_transports_give_the_same_trajectory(make):
    pipe = make("remoteenv/Reacher-v0", transport="pipe")
    zmq_env = make("remoteenv/Reacher-v0", transport="ipc")
    assert type(pipe.unwrapped._conn).__name__ == "PipeConnection"
    assert type(zmq_env.unwrapped._conn).__name__ == "ZmqConnection"
    pipe.action_space.seed(3)
    actions = [pipe.action_space.sample() for _ in range(60)]
    _assert_same(_rollout(pipe, 9, actions), _rollout(zmq_env, 9, actions))


def test_reset_seed_semantics(make):
    env = make("remoteenv/Reacher-v0")
    a, _ = env.reset(seed=7)
    b, _ = env.reset()  # continues the seeded stream
    c, _ = env.reset(seed=7)
    d, _ = env.reset()
    np.testing.assert_array_equal(a, c)
    np.testing.assert_array_equal(b, d)
    assert not np.array_equal(a, b)


def test_reacher_matches_gymnasium_reacher_v5(make):
    ours = make("remoteenv/Reacher-v0")
    ref = gym.make("Reacher-v5").unwrapped
    try:
        # Same seed gives the same start state: both draw from the RNG in the same order.
        obs, _ = ours.reset(seed=11)
        ref_obs, _ = ref.reset(seed=11)
        np.testing.assert_allclose(obs, ref_obs, rtol=0, atol=1e-9)
        rng = np.random.default_rng(0)
        for t in range(200):
            if t % 50 == 0 and t:
                # Re-synchronise from a state set explicitly on the reference.
                obs, _ = ours.reset(seed=1000 + t)
                qpos = np.concatenate([np.arctan2(obs[2:4], obs[0:2]), obs[4:6]])
                qvel = np.concatenate([obs[6:8], [0.0, 0.0]])
                ref.set_state(qpos, qvel)
                np.testing.assert_allclose(obs, ref._get_obs(), rtol=0, atol=1e-9)
            action = rng.uniform(-1, 1, size=2).astype(np.float32)
            obs, reward, terminated, truncated, info = ours.step(action)
            ref_obs, ref_reward, ref_term, _, ref_info = ref.step(action)
            np.testing.assert_allclose(obs, ref_obs, rtol=0, atol=1e-9)
            assert reward == pytest.approx(ref_reward, rel=0, abs=1e-9)
            assert info["reward_dist"] == pytest.approx(ref_info["reward_dist"], abs=1e-9)
            assert info["reward_ctrl"] == pytest.approx(ref_info["reward_ctrl"], abs=1e-9)
            assert terminated is False and ref_term is False
    finally:
        ref.close()


def test_reacher_truncates_after_50_steps(make):
    env = make("remoteenv/Reacher-v0")
    env.reset(seed=0)
    for t in range(50):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        assert not terminated
        assert truncated == (t == 49)


def test_cartpole_controller_survives_500_steps(make):
    env = make("remoteenv/CartPole-v0", continuous=True)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        total, steps = 0.0, 0
        while True:
            obs, reward, terminated, truncated, _ = env.step(controllers.cartpole_continuous(obs))
            total += reward
            steps += 1
            if terminated or truncated:
                break
        assert not terminated and truncated and steps == 500 and total == 500.0


def test_cartpole_random_actions_terminate_by_cartpole_v1_rules(make):
    env = make("remoteenv/CartPole-v0")
    env.action_space.seed(0)
    lengths = []
    for seed in range(10):
        obs, _ = env.reset(seed=seed)
        assert np.all(np.abs(obs) <= 0.05)
        steps = 0
        while True:
            obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            steps += 1
            assert reward == 1.0
            out = abs(obs[0]) > 2.4 or abs(obs[2]) > 12 * 2 * np.pi / 360
            assert terminated == out
            if terminated or truncated:
                break
        assert terminated
        lengths.append(steps)
    assert 8 <= np.mean(lengths) <= 60  # CartPole-v1 random episodes last ~20 steps


def test_scene_exception_comes_back_and_sim_keeps_serving(make):
    env = remoteenv.OpenAIRemoteEnv(os.path.join(HERE, "scenes", "raising_scene.py"))
    try:
        env.reset(seed=0)
        env.step(np.array([0.1], dtype=np.float32))
        with pytest.raises(remoteenv.RemoteEnvError) as info:
            env.step(np.array([0.5], dtype=np.float32))
        err = info.value
        assert err.kind == "scene" and err.instance == 0
        assert "scene refuses the action 0.5" in str(err)
        assert "Traceback" in err.remote_traceback and "post_step" in err.remote_traceback
        obs, _ = env.reset(seed=1)  # the sim is still serving
        obs, reward, *_ = env.step(np.array([0.1], dtype=np.float32))
        assert reward == 1.0
    finally:
        env.close()


def test_step_before_reset_is_a_state_error(make):
    env = make("remoteenv/CartPole-v0", disable_env_checker=True)
    with pytest.raises(remoteenv.RemoteEnvError) as info:
        env.unwrapped.step(0)
    assert info.value.kind == "state"


@pytest.mark.parametrize("transport", ["pipe", "ipc", "tcp"])
def test_close_leaves_no_process_and_no_socket_file(make, transport, pid_alive, wait_gone):
    env = gym.make("remoteenv/CartPole-v0", transport=transport)
    env.reset(seed=0)
    env.step(0)
    pid = env.unwrapped.pid
    workdir = env.unwrapped.launcher.workdir
    endpoint = env.unwrapped.launcher.endpoints[0]
    assert endpoint.startswith("tcp://127.0.0.1:" if transport == "tcp" else "ipc://")
    if transport != "tcp":
        assert os.path.exists(endpoint[len("ipc://") :])
    assert pid_alive(pid)
    env.close()
    assert wait_gone(pid, timeout=5.0)
    assert not os.path.exists(workdir)
    env.close()  # closing twice is allowed
    with pytest.raises(remoteenv.RemoteEnvError):
        env.unwrapped.step(0)


def test_garbage_collected_env_stops_its_sim(wait_gone):
    import gc

    env = gym.make("remoteenv/CartPole-v0")
    pid, workdir = env.unwrapped.pid, env.unwrapped.launcher.workdir
    del env
    gc.collect()
    assert wait_gone(pid, timeout=5.0)
    assert not os.path.exists(workdir)


def test_rgb_array_rendering(make):
    env = make("remoteenv/CartPole-v0", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == (400, 600, 3)
    assert frame.std() > 5  # an image of something, not a blank buffer
    env2 = make("remoteenv/Reacher-v0", render_mode="rgb_array")
    env2.reset(seed=0)
    assert env2.render().shape == (480, 480, 3)
    no_render = make("remoteenv/Reacher-v0")
    no_render.reset(seed=0)
    assert no_render.render() is None


def test_record_video_writes_an_mp4(make, tmp_path):
    pytest.importorskip("moviepy")
    from gymnasium.wrappers import RecordVideo

    env = RecordVideo(
        make("remoteenv/Reacher-v0", render_mode="rgb_array"),
        str(tmp_path),
        episode_trigger=lambda e: True,
        disable_logger=True,
    )
    env.reset(seed=0)
    for _ in range(50):
        env.step(env.action_space.sample())
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert videos and videos[0].stat().st_size > 1000


def test_bad_scene_kwargs_fail_at_launch_with_stderr():
    with pytest.raises(remoteenv.RemoteEnvError) as info:
        gym.make("remoteenv/CartPole-v0", no_such_option=1)
    assert info.value.kind == "launch"
    assert "no_such_option" in str(info.value)


def test_package_imported_from_the_checkout_finds_its_scenes():
    """``python -m remoteenv`` in the repository root imports the checkout, whose
    scenes live in the top-level scenes/ folder rather than under remoteenv/."""
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(HERE))
    code = (
        "import gymnasium, remoteenv, remoteenv.scenes; "
        "print(remoteenv.__file__); print(remoteenv.scenes.__file__); "
        "print(sorted(remoteenv.SHIPPED_SCENES.values())); "
        "print(all(i in gymnasium.registry for i in remoteenv.SHIPPED_SCENES.values()))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    module_file, scenes_file, ids, registered = out.stdout.split("\n")[:4]
    assert module_file == os.path.join(root, "remoteenv", "__init__.py")
    assert scenes_file == os.path.join(root, "scenes", "__init__.py")
    assert ids == "['remoteenv/CartPole-v0', 'remoteenv/Hexapod-v0', 'remoteenv/Reacher-v0']" and registered == "True"


def test_a_scene_that_raises_in_init_fails_to_launch_with_its_own_exception_first():
    """Issue 28, item 6: the scene's exception was the last line of a 1,500-character message."""
    with pytest.raises(remoteenv.LaunchError) as caught:
        remoteenv.OpenAIRemoteEnv(os.path.join(HERE, "scenes", "raising_scene.py"), fail_init=True)
    first, _, rest = str(caught.value).partition("\n")
    assert first.endswith("failed to start: ValueError: the pole length must be positive, got -1"), first
    assert "Traceback (most recent call last)" in rest and "exited with code 1" in rest
