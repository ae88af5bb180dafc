"""render_mode="human": the sim process opens MuJoCo's viewer, or explains why it cannot."""

from __future__ import annotations

import gymnasium as gym
import pytest

from remoteenv import RemoteEnvError
from remoteenv.sim.scene import viewer


def test_human_is_a_declared_render_mode():
    env = gym.make("remoteenv/CartPole-v0", render_mode="rgb_array")
    try:
        assert "human" in env.metadata["render_modes"]
        assert "rgb_array" in env.metadata["render_modes"]
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ["remoteenv/CartPole-v0", "remoteenv/Reacher-v0"])
def test_headless_human_render_fails_naming_rgb_array(monkeypatch, env_id):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(RemoteEnvError) as err:
        gym.make(env_id, render_mode="human")
    text = str(err.value)
    assert err.value.kind == "launch"
    assert 'render_mode="human" cannot open the MuJoCo viewer' in text
    assert "no display" in text
    assert 'render_mode="rgb_array"' in text


def test_headless_check_env_with_the_render_check_says_what_to_do(monkeypatch):
    from gymnasium.utils.env_checker import check_env

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    env = gym.make("remoteenv/CartPole-v0")
    try:
        with pytest.raises(RemoteEnvError) as err:
            check_env(env.unwrapped)  # builds a "human" env: no display here
    finally:
        env.close()
    assert "check_env(env, skip_render_check=True)" in str(err.value)
    assert 'render_mode="rgb_array"' in str(err.value)


def test_headless_gl_backend_is_reported(monkeypatch):
    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setenv("MUJOCO_GL", "egl")
    assert "MUJOCO_GL=egl" in (viewer.display_problem() or "")


def test_unreachable_display_is_reported(monkeypatch):
    monkeypatch.setenv("DISPLAY", ":97")  # no X server listens there
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    problem = viewer.display_problem()
    assert problem is not None and ":97" in problem
    with pytest.raises(viewer.HumanRenderUnavailable, match="rgb_array"):
        import mujoco

        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
        viewer.HumanViewer(model, mujoco.MjData(model), instance=3)


class _FakeHandle:
    """Stands in for mujoco.viewer.Handle where no display exists."""

    def __init__(self):
        self.syncs = 0
        self.closed = False

    def is_running(self):
        return not self.closed

    def sync(self):
        self.syncs += 1

    def close(self):
        self.closed = True


def test_human_mode_routes_steps_and_render_to_the_viewer(monkeypatch):
    import mujoco.viewer

    from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv

    handles = []

    def fake_launch_passive(model, data, **kwargs):
        handles.append(_FakeHandle())
        return handles[-1]

    monkeypatch.setattr(viewer, "display_problem", lambda: None)
    monkeypatch.setattr(mujoco.viewer, "launch_passive", fake_launch_passive)
    env = CartPoleEnv(render_mode="human")
    (handle,) = handles
    env.reset(seed=0)
    for _ in range(3):
        env.step(1)
    assert handle.syncs == 3  # one redraw per control tick
    assert env.render() is None and handle.syncs == 4
    for _ in range(50):  # real-time mode calls substep() at physics rate: redraws are throttled
        env.substep()
    assert handle.syncs < 4 + 25
    env.close()
    assert handle.closed
    env.step(0)  # the sim keeps working after the window is gone
