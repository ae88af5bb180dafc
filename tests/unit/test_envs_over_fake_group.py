"""Both env classes driven over a fake SimGroup whose sims answer in-process.

No process, no socket: the fake group's connections are SimConnections whose
transport hands each request frame to a tiny server in this file (a toy
"walker" world speaking the wire protocol, batch commands included) and
queues its reply frame. Everything above the transport is the real code:
session, handshake parsing, fan-out/fan-in, autoreset, assembly, restarts.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from equality import assert_same
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from remoteenv import OpenAIRemoteEnv, RemoteVectorEnv
from remoteenv.agent.connection.sim_connection import SimConnection
from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout, SimDiedError, StateError
from remoteenv.agent.launch.restart import INFO_RESTARTED, INFO_RESTARTS
from remoteenv.agent.launch.sim_group import LaunchSpec, SimGroup, SimHandle, SimLayout
from remoteenv.wire import protocol
from remoteenv.wire.codec.spaces import space_to_wire
from remoteenv.wire.messages.batch_encoding import columnar_infos, stack

SCENE = "/nonexistent/walker_scene.py"  # the fake group never runs it
OBS_SPACE = gym.spaces.Box(-10.0, 10.0, (2,), np.float32)
ACT_SPACE = gym.spaces.Discrete(2)
WALL = 3  # an episode terminates when |pos| reaches it


# ------------------------------------------------------------ a toy sim, in-process


class Walker:
    """One world: a walker on a line; action 1 steps right, 0 left."""

    def __init__(self) -> None:
        self.pos = 0
        self.steps = 0
        self.has_reset = False

    def obs(self) -> np.ndarray:
        return np.array([self.pos, self.steps], dtype=np.float32)

    def reset(self, seed: int | None) -> tuple[np.ndarray, dict[str, Any]]:
        self.pos = 0 if seed is None else seed % 3 - 1
        self.steps = 0
        self.has_reset = True
        return self.obs(), {"seeded": seed is not None, "tag": "reset"}

    def step(self, action: int, timed: bool) -> tuple[np.ndarray, float, bool, dict[str, Any]]:
        self.pos += 1 if action == 1 else -1
        self.steps += 1
        info: dict[str, Any] = {"pos": self.pos}
        if timed:
            info.update(latency_s=0.02, latency_ticks=1, late=self.steps % 2 == 0, pacing_overruns=self.steps)
        return self.obs(), 1.0, abs(self.pos) >= WALL, info


class FakeSim:
    """A sim "process": its worlds, the protocol, and a fake pid and death."""

    next_pid = 1000

    def __init__(self, instance: int, worlds: int, real_time: bool, action_delay: int) -> None:
        FakeSim.next_pid += 1
        self.instance = instance
        self.pid = FakeSim.next_pid
        self.endpoint = f"inproc://walker-{instance}"
        self.curve_server_key = None
        self.pipe = None
        self.node = None
        self.worlds = [Walker() for _ in range(worlds)]
        self.real_time = real_time
        self.action_delay = action_delay
        self.killed = False
        self.stuck = False
        #: The handshake's "commands" list (None: the field is left out).
        self.offered: list[str] | None = None
        self.commands: list[str] = []

    def death(self) -> str | None:
        return f"pid {self.pid} killed by signal SIGKILL" if self.killed else None

    def handle(self, frame: bytes) -> bytes:
        msg = protocol.decode_request(frame)
        cmd = msg["cmd"]
        self.commands.append(cmd)
        try:
            result = getattr(self, f"_{cmd}")(msg)
        except LookupError as exc:
            return protocol.pack(protocol.error_reply(msg["seq"], "state", str(exc)))
        return protocol.pack({"seq": msg["seq"], "ok": True, **result}, big_ints=True)  # as a sim's replies

    def _handshake(self, msg: dict[str, Any]) -> dict[str, Any]:
        stepping = (
            {"mode": "real_time", "real_time_factor": 1.0, "action_delay": 0}
            if self.real_time
            else {"mode": "lock_step", "action_delay": self.action_delay}
        )
        return {
            "protocol": protocol.PROTOCOL_VERSION,
            "env_id": "fake/Walker-v0",
            "instance": self.instance,
            "pid": self.pid,
            "num_worlds": len(self.worlds),
            "observation_space": space_to_wire(OBS_SPACE),
            "action_space": space_to_wire(ACT_SPACE),
            "metadata": {
                "render_modes": ["rgb_array"],
                "render_fps": 50,
                "dt": 0.02,
                "timestep": 0.01,
                "frame_skip": 2,
            },
            "stepping": stepping,
            **({} if self.offered is None else {"commands": self.offered}),
        }

    def _world(self, msg: dict[str, Any]) -> Walker:
        return self.worlds[msg.get("world", 0)]

    def _reset(self, msg: dict[str, Any]) -> dict[str, Any]:
        obs, info = self._world(msg).reset(msg.get("seed"))
        return {"obs": obs, "info": info}

    def _step(self, msg: dict[str, Any]) -> dict[str, Any]:
        walker = self._world(msg)
        if not walker.has_reset:
            raise LookupError("step before reset")
        obs, reward, terminated, info = walker.step(msg["action"], self.real_time or self.action_delay > 0)
        return {"obs": obs, "reward": reward, "terminated": terminated, "truncated": False, "info": info}

    def _render(self, msg: dict[str, Any]) -> dict[str, Any]:
        return {"frame": np.full((2, 3, 3), self._world(msg).pos % 256, dtype=np.uint8)}

    def _close(self, msg: dict[str, Any]) -> dict[str, Any]:
        return {}

    def _reset_batch(self, msg: dict[str, Any]) -> dict[str, Any]:
        seeds = msg["seeds"] or [None] * len(msg["worlds"])
        out = [self.worlds[w].reset(s) for w, s in zip(msg["worlds"], seeds)]
        return {"obs": stack([o for o, _ in out]), "info": columnar_infos([i for _, i in out])}

    def _step_batch(self, msg: dict[str, Any]) -> dict[str, Any]:
        obs, rewards, terms, infos, final = [], [], [], [], []
        for w, op in enumerate(msg["ops"]):
            walker = self.worlds[w]
            if op == protocol.OP_RESET:
                o, i = walker.reset(None)
                obs.append(o), rewards.append(0.0), terms.append(False), infos.append(i)
                continue
            o, r, t, i = walker.step(int(msg["actions"][w]), self.action_delay > 0)
            if op == protocol.OP_STEP_RESET or (op == protocol.OP_STEP_AUTORESET and t):
                final.append([w, o, i])
                o, i = walker.reset(None)
            obs.append(o), rewards.append(r), terms.append(t), infos.append(i)
        return {
            "obs": stack(obs),
            "reward": rewards,
            "terminated": terms,
            "truncated": [False] * len(obs),
            "info": columnar_infos(infos),
            "final": final,
        }


class InProcessConnection(SimConnection):
    """A SimConnection whose transport is a function call: request frames go to
    the fake sim, its reply frames wait in a queue. A killed or stuck sim answers nothing."""

    def __init__(self, sim: FakeSim, timeout: float | None) -> None:
        super().__init__(sim.endpoint, instance=sim.instance, timeout=timeout, death_check=sim.death)
        self.sim = sim
        self.inbox: deque[bytes] = deque()

    def _send_frame(self, payload: bytes) -> None:
        if not (self.sim.killed or self.sim.stuck):
            self.inbox.append(self.sim.handle(payload))

    def _recv_frame(self) -> bytes | None:
        return self.inbox.popleft() if self.inbox else None

    _recv_frame_nowait = _recv_frame

    def reconnect(self) -> None:
        self.inbox.clear()


class FakeGroup:
    """A SimGroup of FakeSims."""

    curve_client_keypair = None

    def __init__(self, layout: SimLayout | None = None, owns_sims: bool = True) -> None:
        self.owns_sims = owns_sims
        self._fixed = layout
        self.spec: LaunchSpec | None = None
        self.sims: list[FakeSim] = []
        self.closed = False
        self.restarted: list[int] = []
        self.retired: list[FakeSim] = []
        if layout is not None:
            self.sims = [
                FakeSim(i, layout.worlds_per_instance, layout.real_time, 0) for i in range(layout.num_instances)
            ]

    @property
    def layout(self) -> SimLayout | None:
        if self._fixed is not None or self.spec is None:
            return self._fixed
        return SimLayout(self.spec.num_instances, self.spec.worlds_per_instance, self.spec.run.real_time, "fake")

    def start(self, spec: LaunchSpec) -> None:
        self.spec = spec
        self.sims = [
            FakeSim(i, spec.worlds_per_instance, spec.run.real_time, spec.run.action_delay)
            for i in range(spec.num_instances)
        ]

    def connect(self, index: int, timeout: float | None) -> SimConnection:
        return InProcessConnection(self.sims[index], timeout)

    def restart(self, index: int) -> FakeSim:
        old = self.sims[index]
        self.retired.append(old)
        self.sims[index] = FakeSim(index, len(old.worlds), old.real_time, old.action_delay)
        self.restarted.append(index)
        return self.sims[index]

    def close(self) -> None:
        self.closed = True


def all_commands(group: FakeGroup) -> list[str]:
    return [c for sim in [*group.retired, *group.sims] for c in sim.commands]


# ------------------------------------------------------------ the seam itself


def test_the_fakes_and_the_shipped_groups_have_the_declared_shapes():
    from remoteenv import Launcher
    from remoteenv import SimGroup as Exported
    from remoteenv.agent.launch.attach import AttachedSim

    assert Exported is SimGroup
    assert isinstance(FakeGroup(), SimGroup)
    assert isinstance(FakeSim(0, 1, False, 0), SimHandle)
    assert isinstance(AttachedSim(0, "ipc:///x", None), SimHandle)
    launcher = Launcher(transport="tcp")  # unconfigured: starts nothing
    try:
        assert isinstance(launcher, SimGroup)
        assert launcher.layout is None and launcher.sims == [] and not launcher.closed
    finally:
        launcher.close()
    assert launcher.closed


# ------------------------------------------------------------ single env


def make_single(group: FakeGroup | None = None, **kwargs: Any) -> OpenAIRemoteEnv:
    return OpenAIRemoteEnv(SCENE, launcher=group or FakeGroup(), **kwargs)


def test_single_env_takes_spaces_and_metadata_from_the_handshake():
    group = FakeGroup()
    env = make_single(group, seed=4, render_mode="rgb_array", flavour="mint")
    assert group.spec == LaunchSpec(SCENE, 1, 1, seed=4, env_kwargs={"flavour": "mint"}, render_mode="rgb_array")
    assert env.observation_space == OBS_SPACE and env.action_space == ACT_SPACE
    assert env.metadata == {"render_modes": ["rgb_array"], "render_fps": 50} and env.dt == 0.02
    assert env.handshake.env_id == "fake/Walker-v0" and env.handshake["metadata"]["frame_skip"] == 2
    assert env.pid == group.sims[0].pid and env.launcher is group
    env.close()


def test_single_env_reset_step_render_close():
    group = FakeGroup()
    env = make_single(group, render_mode="rgb_array")
    obs, info = env.reset(seed=5)
    assert obs.tolist() == [1.0, 0.0] and info == {"seeded": True, "tag": "reset"}
    obs, reward, terminated, truncated, info = env.step(1)
    assert obs.tolist() == [2.0, 1.0] and reward == 1.0 and not terminated and not truncated
    assert info == {"pos": 2} and "wall_round_trip_s" not in info
    assert env.step(1)[2] is True  # reached the wall
    assert env.render().shape == (2, 3, 3)
    with pytest.raises(ValueError, match="Discrete"):
        env.step(7)  # refused before anything is sent
    assert group.sims[0].commands.count("step") == 2
    env.close()
    assert group.sims[0].commands[-1] == "close" and group.closed
    assert env.pid is None and env.launcher is None
    with pytest.raises(StateError, match="closed OpenAIRemoteEnv"):
        env.step(0)
    env.close()  # idempotent


def test_single_env_records_latency_of_timed_steps():
    env = make_single(action_delay=1)
    env.reset(seed=0)
    for _ in range(2):
        info = env.step(1)[4]
    assert info["wall_round_trip_s"] >= 0.0
    stats = env.latency_stats
    assert stats.steps == 2 and stats.latency_s.count == 2 and stats.late_actions == 1
    env.close()


def test_single_env_restarts_on_a_fake_death():
    group = FakeGroup()
    env = make_single(group, restart_on_failure=True, max_restarts=1)
    env.reset(seed=5)
    last, *_ = env.step(0)
    first = group.sims[0]
    first.killed = True
    obs, reward, terminated, truncated, info = env.step(1)
    assert truncated and not terminated and reward == 0.0 and (obs == last).all()
    assert info[INFO_RESTARTED] is True and info[INFO_RESTARTS] == 1 and "SIGKILL" in info["remoteenv_error"]
    assert group.restarted == [0] and env.pid == group.sims[0].pid != first.pid
    assert group.sims[0].commands[0] == "handshake"  # the new sim was greeted
    env.reset(seed=0)
    group.sims[0].killed = True
    with pytest.raises(SimDiedError, match="max_restarts=1"):
        env.step(0)
    env.close()


def test_single_env_without_restarts_raises_the_death():
    group = FakeGroup()
    env = make_single(group)
    env.reset()
    group.sims[0].killed = True
    with pytest.raises(SimDiedError, match="sim instance 0 died") as err:
        env.step(0)
    assert err.value.instance == 0 and group.restarted == []
    env.close()


def test_single_env_call_timeouts_and_a_restart_on_timeout():
    group = FakeGroup()
    env = make_single(group, call_timeouts={"step": 0.0}, restart_on_failure=True)
    env.reset(seed=1)
    group.sims[0].stuck = True
    *_, truncated, info = env.step(1)
    assert truncated and "did not answer 'step' within 0 s" in info["remoteenv_error"]
    assert group.restarted == [0]
    env.close()


def test_attached_groups_are_not_asked_to_close_nor_restarted():
    group = FakeGroup(SimLayout(1, 1, False, "fake launch-info file"), owns_sims=False)
    with pytest.raises(ValueError, match="restart_on_failure needs sims this env launched"):
        make_single(group, restart_on_failure=True)
    env = make_single(group)
    assert group.spec is None  # a fixed layout is driven as it is, not started
    env.reset(seed=0)
    env.close()
    assert "close" not in group.sims[0].commands and group.closed


def test_single_env_refuses_a_group_of_several_sims():
    with pytest.raises(ValueError, match="drives one sim; fake file has 2"):
        make_single(FakeGroup(SimLayout(2, 1, False, "fake file")))


def test_launcher_and_attach_are_exclusive():
    with pytest.raises(ValueError, match="launcher= or attach="):
        make_single(attach="launch.json")


# ------------------------------------------------------------ vector env


def make_vector(num_envs: int, group: FakeGroup | None = None, **kwargs: Any) -> RemoteVectorEnv:
    return RemoteVectorEnv(SCENE, num_envs, launcher=group or FakeGroup(), **kwargs)


def reference(num_envs: int, limit: int | None, mode: AutoresetMode) -> SyncVectorEnv:
    """Gymnasium's SyncVectorEnv over single fake envs: the semantics to match."""

    def one() -> gym.Env:
        env: gym.Env = make_single()
        return gym.wrappers.TimeLimit(env, limit) if limit else env

    return SyncVectorEnv([one] * num_envs, autoreset_mode=mode)


@pytest.mark.parametrize("mode", list(AutoresetMode))
@pytest.mark.parametrize("k", [1, 2, 3])
def test_vector_env_matches_sync_vector_env_of_single_envs(mode, k):
    n, limit = 3, 4
    group = FakeGroup()
    remote = make_vector(n, group, envs_per_process=k, autoreset_mode=mode, max_episode_steps=limit)
    ref = reference(n, limit, mode)
    assert len(group.sims) == len(remote.slices) == -(-n // k)
    ro, ri = remote.reset(seed=7)
    fo, fi = ref.reset(seed=7)
    assert_same(ro, fo, "reset obs")
    assert_same(ri, fi, "reset info")
    rng = np.random.default_rng(k)
    ends = 0
    for t in range(25):
        actions = rng.integers(0, 2, size=n)
        r, f = remote.step(actions), ref.step(actions)
        for name, x, y in zip(("obs", "reward", "terminated", "truncated", "info"), r, f):
            assert_same(x, y, f"step {t} {name}")
        ended = r[2] | r[3]
        ends += int(ended.sum())
        if mode == AutoresetMode.DISABLED and ended.any():
            assert_same(
                remote.reset(options={"reset_mask": ended})[0],
                ref.reset(options={"reset_mask": ended.copy()})[0],
                f"step {t} masked reset",
            )
    assert ends >= 3
    assert any("step_batch" in s.commands for s in group.sims) == (k > 1)
    remote.close()
    ref.close()


def test_vector_env_restarts_only_the_dead_process():
    group = FakeGroup()
    venv = make_vector(4, group, envs_per_process=2, restart_on_failure=True, max_restarts=1)
    venv.reset(seed=0)
    before, *_ = venv.step(np.zeros(4, dtype=np.int64))
    group.sims[1].killed = True
    obs, rewards, terminated, truncated, info = venv.step(np.ones(4, dtype=np.int64))
    assert truncated.tolist() == [False, False, True, True] and not terminated.any()
    assert rewards.tolist() == [1.0, 1.0, 0.0, 0.0]
    np.testing.assert_array_equal(obs[2:], before[2:])
    assert info["_remoteenv_restarted"].tolist() == [False, False, True, True]
    assert group.restarted == [1] and venv.restarts.count == 1
    _, rewards, _, truncated, _ = venv.step(np.ones(4, dtype=np.int64))  # next-step autoreset
    assert rewards.tolist() == [1.0, 1.0, 0.0, 0.0] and not truncated.any()
    group.sims[0].killed = True
    with pytest.raises(SimDiedError, match="max_restarts=1"):
        venv.step(np.zeros(4, dtype=np.int64))
    venv.close()


def test_vector_reset_is_sent_again_to_a_relaunched_process():
    group = FakeGroup()
    venv = make_vector(4, group, envs_per_process=2, restart_on_failure=True)
    venv.reset(seed=0)
    group.sims[0].killed = True
    obs, info = venv.reset(seed=1)
    assert obs.shape == (4, 2) and info["_remoteenv_restarted"].tolist() == [True, True, False, False]
    assert group.sims[0].commands == ["handshake", "reset_batch"]
    venv.close()


def test_vector_same_step_restart_starts_new_episodes_at_once():
    group = FakeGroup()
    venv = make_vector(2, group, envs_per_process=1, restart_on_failure=True, autoreset_mode=AutoresetMode.SAME_STEP)
    venv.reset(seed=3)
    before, *_ = venv.step(np.array([1, 1]))
    group.sims[0].killed = True
    obs, _, _, truncated, info = venv.step(np.array([1, 1]))
    assert truncated.tolist() == [True, False]
    np.testing.assert_array_equal(info["final_obs"][0], before[0])
    assert obs[0].tolist() == [0.0, 0.0]  # the relaunched world's fresh episode
    venv.close()


def test_vector_call_timeouts_bound_a_stuck_process():
    group = FakeGroup()
    venv = make_vector(2, group, envs_per_process=1, call_timeouts={"step": 0.0})
    assert venv.call_timeouts == {"step": 0.0}
    venv.reset(seed=0)
    group.sims[1].stuck = True
    with pytest.raises(RemoteEnvTimeout, match="did not answer 'step' within 0 s") as err:
        venv.step(np.array([0, 0]))
    assert err.value.instance == 1
    venv.close()


def test_vector_env_records_latency_stats():
    venv = make_vector(2, real_time=True)
    venv.reset(seed=0)
    for _ in range(3):
        venv.step(np.array([1, 0]))
    stats = venv.latency_stats
    assert stats.steps == 3 and stats.round_trip_s.count == 3
    assert stats.latency_s.count == 6 and stats.latency_ticks.mean == 1.0
    assert stats.late_actions == 2 and stats.pacing_overruns == 3
    venv.close()


def test_vector_env_over_a_fixed_layout_takes_it():
    layout = SimLayout(2, 2, False, "fake launch-info file")
    with pytest.raises(ValueError, match="fake launch-info file serves 4 worlds; pass num_envs=4"):
        make_vector(3, FakeGroup(layout, owns_sims=False))
    group = FakeGroup(layout, owns_sims=False)
    venv = make_vector(4, group, envs_per_process=1)
    assert venv.envs_per_process == 2 and group.spec is None
    venv.reset(seed=0)
    venv.close()
    assert group.closed and not any("close" in s.commands for s in group.sims)


def test_vector_env_render_and_close():
    group = FakeGroup()
    venv = make_vector(3, group, envs_per_process=2, render_mode="rgb_array")
    venv.reset(seed=0)
    frames = venv.render()
    assert len(frames) == 3 and all(f.shape == (2, 3, 3) for f in frames)
    pids = venv.pids
    assert pids == [s.pid for s in group.sims]
    venv.close()
    assert venv.closed and venv.pids == [] and venv.launcher is None and group.closed
    assert [s.commands[-1] for s in group.sims] == ["close", "close"]
    venv.close()  # idempotent


def test_vector_env_step_before_reset_and_bad_actions():
    venv = make_vector(2)
    with pytest.raises(RuntimeError, match="before reset"):
        venv.step(np.array([0, 1]))
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="world 1"):
        venv.step(np.array([0, 5]))
    venv.close()


def test_vector_env_refuses_sims_that_cannot_host_its_worlds():
    group = FakeGroup(SimLayout(1, 2, False, "fake file"), owns_sims=False)
    group.sims[0].offered = ["handshake", "reset", "step", "render", "close"]
    with pytest.raises(RemoteEnvError, match="does not answer step_batch"):
        make_vector(2, group)
    assert group.closed
    group = FakeGroup(SimLayout(1, 3, False, "fake file"), owns_sims=False)
    group.sims[0].worlds = group.sims[0].worlds[:2]
    with pytest.raises(RemoteEnvError, match=r"hosts 2 world\(s\), not 3"):
        make_vector(3, group)


# ------------------------------------------------------------ big integers in infos (issue 35, item 6)


@pytest.mark.parametrize("autoreset_mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_big_integers_in_a_vector_envs_infos_reach_the_user_as_python_ints(monkeypatch, autoreset_mode):
    # Before: Gymnasium's merge typed a new int key int64, and 2**70 raised OverflowError.
    plain_step = Walker.step

    def step(self: Walker, action: int, timed: bool) -> tuple[np.ndarray, float, bool, dict[str, Any]]:
        obs, reward, terminated, info = plain_step(self, action, timed)
        big = {"big": 2**70 + self.pos, "huge": -(2**510), "u64": 2**64 - 1, "nested": {"deep": 2**100}}
        info.update({k: v for k, v in big.items() if self.steps % 2 == 1 or k != "big"})
        info["mixed"] = 2**70 if self.pos > 0 else 5  # a small int first, then a big one, or the reverse
        return obs, reward, terminated, info

    monkeypatch.setattr(Walker, "step", step)
    env = RemoteVectorEnv(SCENE, 3, launcher=FakeGroup(), envs_per_process=3, autoreset_mode=autoreset_mode)
    try:
        env.reset(seed=0)
        seen_big = 0
        for _ in range(4):
            _, _, _, _, infos = env.step(np.array([1, 0, 1]))
            seen_big += "big" in infos
            for key in [k for k in ("big", "huge", "u64", "mixed") if k in infos]:
                assert infos[key].dtype == object, key
                assert all(type(v) is int for v in present(infos, key)), key
            assert set(present(infos, "huge")) == {-(2**510)} and set(present(infos, "u64")) == {2**64 - 1}
            assert set(present(infos["nested"], "deep")) == {2**100}
            assert set(present(infos, "mixed")) <= {2**70, 5}
        assert seen_big
    finally:
        env.close()


def present(infos: dict[str, Any], key: str) -> list[Any]:
    """The values of ``key`` of the worlds whose info has it (Gymnasium's ``_key`` mask)."""
    return [v for v, there in zip(infos[key], infos[f"_{key}"]) if there]
