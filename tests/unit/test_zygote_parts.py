"""The zygote's parts that need no process: its control channel, what it
preloads, when it refuses to fork, the forked sim's handle, the switch."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import threading

import pytest

from remoteenv.agent.launch.sim_process import kill_group
from remoteenv.agent.launch.zygote import registry
from remoteenv.agent.launch.zygote.forked import LOST_STATUS, ForkedProcess
from remoteenv.agent.launch.zygote.process import pidfd_pid
from remoteenv.sim.process.zygote.fork_server import ZygoteServer, script_path, thread_count
from remoteenv.sim.process.zygote.preload import installed, preload, scene_imports, shadowing
from remoteenv.wire.messages.zygote_channel import (
    MAX_CONTROL_BYTES,
    ForkRequest,
    channel_pair,
    fork_request,
    receive_message,
    send_message,
)
from remoteenv.wire.wire_errors import ProtocolError


def _open(fd: int) -> bool:
    try:
        os.fstat(fd)
    except OSError:
        return False
    return True


@pytest.fixture
def pair():
    a, b = channel_pair()
    yield a, b
    a.close()
    b.close()


def test_a_message_and_its_descriptors_arrive_whole(pair):
    a, b = pair
    r, w = os.pipe()
    try:
        send_message(a, {"kind": "fork", "argv": ["s.py", "--x"], "cwd": "/", "pipe": False}, [r, w])
        message, fds = receive_message(b)
        assert message == {"kind": "fork", "argv": ["s.py", "--x"], "cwd": "/", "pipe": False}
        assert len(fds) == 2 and all(os.get_inheritable(fd) is False for fd in fds)
        assert fork_request(message, fds) == ForkRequest(["s.py", "--x"], "/", False)
        os.write(fds[1], b"!")
        assert os.read(r, 1) == b"!"  # the received descriptor is the pipe's write end
        for fd in fds:
            os.close(fd)
    finally:
        os.close(r)
        os.close(w)


def test_end_of_file_is_none_and_nothing_waiting_does_not_block(pair):
    a, b = pair
    with pytest.raises(BlockingIOError):
        receive_message(b, socket.MSG_DONTWAIT)
    a.close()
    assert receive_message(b) is None


def test_an_oversized_or_unknown_message_is_refused_and_its_descriptors_closed(pair):
    a, b = pair
    r, w = os.pipe()
    os.close(w)
    try:
        before = set(os.listdir("/proc/self/fd"))
        socket.send_fds(a, [b"\x81\xa4kind\xa4evil"], [r])  # {"kind": "evil"}
        with pytest.raises(ProtocolError, match="not a control message"):
            receive_message(b)
        assert set(os.listdir("/proc/self/fd")) == before  # the received copy of r is closed
        a.send(b"\x00" * (MAX_CONTROL_BYTES + 10))
        with pytest.raises(ProtocolError, match="truncated"):
            receive_message(b)
        with pytest.raises(ValueError, match="over the limits"):
            send_message(a, {"kind": "fork", "argv": ["x" * MAX_CONTROL_BYTES], "cwd": "/", "pipe": False})
    finally:
        os.close(r)


@pytest.mark.parametrize(
    ("message", "fds", "match"),
    [
        ({"kind": "fork", "argv": [], "cwd": "/", "pipe": False}, 2, "malformed"),
        ({"kind": "fork", "argv": ["s.py", 3], "cwd": "/", "pipe": False}, 2, "malformed"),
        ({"kind": "fork", "argv": ["s.py"], "cwd": "/", "pipe": 1}, 2, "malformed"),
        ({"kind": "fork", "argv": ["s.py"], "cwd": "/", "pipe": True}, 2, "expected 3"),
        ({"kind": "ready", "argv": ["s.py"], "cwd": "/", "pipe": False}, 2, "malformed"),
        ({"kind": "fork", "argv": ["s\0.py"], "cwd": "/", "pipe": False}, 2, "malformed"),
        ({"kind": "fork", "argv": ["s.py"], "cwd": "/tmp\0", "pipe": False}, 2, "malformed"),
        ({"kind": "fork", "argv": ["s.py"], "cwd": "tmp", "pipe": False}, 2, "malformed"),
    ],
)
def test_a_malformed_fork_request_is_refused(message, fds, match):
    with pytest.raises(ProtocolError, match=match):
        fork_request(message, list(range(fds)))


def test_scene_imports_are_read_from_the_source_without_running_it(tmp_path):
    script = tmp_path / "s.py"
    script.write_text(
        "from __future__ import annotations\nimport os, json as j\nfrom gymnasium import spaces\n"
        "from . import sibling\nraise SystemExit('never run')\ndef f():\n    import inside\n"
    )
    assert scene_imports(str(script)) == ["os", "json", "gymnasium", "gymnasium.spaces"]
    (tmp_path / "bad.py").write_text("import (")
    assert scene_imports(str(tmp_path / "bad.py")) == []
    assert scene_imports(str(tmp_path / "missing.py")) == []


def test_preload_counts_attributes_as_found_and_missing_modules_as_failed():
    assert preload(["os", "os.path", "os.getcwd", "remoteenv_no_such_module", "json.no_such"]) == [
        "remoteenv_no_such_module"
    ]


def test_only_modules_of_installed_packages_count_as_safe_to_preload(tmp_path, monkeypatch):
    (tmp_path / "remoteenv_user_module.py").write_text("raise SystemExit('never imported')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert installed("json") and installed("sys") and installed("pip")  # stdlib, built in, site-packages
    assert not installed("remoteenv_user_module")  # the user's own: the sim imports it itself
    assert not installed("remoteenv_no_such_module")


def test_shadowing_names_loaded_modules_a_folder_would_replace(tmp_path):
    (tmp_path / "json.py").write_text("")
    (tmp_path / "os").mkdir()
    (tmp_path / "os" / "__init__.py").write_text("")
    (tmp_path / "socket").mkdir()  # no __init__: a namespace portion shadows no regular module
    (tmp_path / "remoteenv_never_loaded.py").write_text("")
    (tmp_path / "scene.xml").write_text("")
    import json  # noqa: F401  (loaded, so shadowable)

    assert shadowing(str(tmp_path)) == ["json", "os"]
    assert shadowing(str(tmp_path / "missing")) == []


def _server(control: socket.socket) -> ZygoteServer:
    return ZygoteServer(control, os.getppid())  # our parent stands in for the agent


def test_the_zygote_refuses_to_fork_beside_another_thread(pair, tmp_path):
    server = _server(pair[0])
    script = tmp_path / "scene.py"
    script.write_text("")
    request = ForkRequest([str(script)], "/", False)
    alone = thread_count() == 1
    if alone:
        assert server._refusal(request) is None
    before = thread_count()
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    try:
        assert thread_count() == before + 1
        assert "Python threads (an imported module started them)" in (server._refusal(request) or "")
    finally:
        stop.set()
        thread.join()
    (tmp_path / "json.py").write_text("")
    if alone:
        assert "shadow modules the zygote imported: ['json']" in (server._refusal(request) or "")
    os.close(server.agent_pidfd)


def test_a_relative_script_is_found_from_the_sims_working_dir_not_the_zygotes(tmp_path, monkeypatch):
    (tmp_path / "scene").mkdir()
    (tmp_path / "scene" / "json.py").write_text("")
    monkeypatch.chdir("/")
    request = ForkRequest(["scene/s.py", "--x"], str(tmp_path), False)
    assert script_path(request) == os.path.realpath(tmp_path / "scene" / "s.py")
    import json  # noqa: F401  (loaded, so shadowable)

    assert shadowing(os.path.dirname(script_path(request))) == ["json"]


def test_a_fork_that_fails_is_refused_and_the_descriptors_closed(pair, tmp_path, monkeypatch):
    server = _server(pair[0])
    monkeypatch.setattr("remoteenv.sim.process.zygote.fork_server.thread_count", lambda: 1)

    def no_fork() -> int:
        raise BlockingIOError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", no_fork)
    r, w = os.pipe()
    try:
        request = ForkRequest([str(tmp_path / "s.py")], "/", False)
        assert server._fork(request.to_message(), [os.dup(r), os.dup(w)]) is None
        message, fds = receive_message(pair[1])
        assert message["kind"] == "refused" and "fork failed" in message["reason"] and fds == []
        os.close(w)
        assert os.read(r, 1) == b""  # the zygote's copy of the write end is closed too
        assert server.children == {}
    finally:
        os.close(r)
        os.close(server.agent_pidfd)


def test_the_zygote_will_not_serve_an_agent_that_is_not_its_parent(pair):
    with pytest.raises(RuntimeError, match="is gone"):
        ZygoteServer(pair[0], os.getpid())


def _forked(pair) -> ForkedProcess:
    return ForkedProcess(12345, pair[1], os.pidfd_open(os.getpid()), zygote_pid=999)


def test_a_forked_sims_status_comes_down_its_channel(pair):
    child = _forked(pair)
    assert child.poll() is None
    with pytest.raises(subprocess.TimeoutExpired):
        child.wait(0.01)
    send_message(pair[0], {"kind": "exit", "returncode": -9})
    assert child.wait(1.0) == -9 and child.poll() == -9 and child.returncode == -9
    assert child.exit_note is None
    assert pair[1].fileno() == -1  # closed once the exit is known


def test_a_forked_sim_whose_zygote_vanished_runs_until_its_pidfd_says_otherwise(pair):
    r, w = os.pipe()  # stands in for the sim's pidfd: readable = exited
    child = ForkedProcess(12345, pair[1], r, zygote_pid=999)
    pair[0].close()  # the zygote died without a word
    assert child.poll() is None
    os.write(w, b"x")
    assert child.wait(1.0) == LOST_STATUS
    assert "lost with its zygote (pid 999)" in (child.exit_note or "")
    assert not _open(r)
    os.close(w)


@pytest.mark.parametrize(("value", "on"), [(None, True), ("1", True), ("0", False), ("off", False), ("No", False)])
def test_the_switch_turns_zygotes_off(monkeypatch, value, on):
    if value is None:
        monkeypatch.delenv(registry.SWITCH, raising=False)
    else:
        monkeypatch.setenv(registry.SWITCH, value)
    assert registry.enabled() is on
    if not on:
        assert registry.zygote_for(dict(os.environ)) is None


def test_a_relative_pythonpath_makes_the_working_dir_part_of_a_zygotes_key(tmp_path, monkeypatch):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    keys = {}
    for name, pythonpath in (("absolute", "/opt"), ("empty entry", "/opt:"), ("relative", "lib")):
        for folder in ("a", "b"):
            monkeypatch.chdir(tmp_path / folder)
            keys[name, folder] = registry._key({"PYTHONPATH": pythonpath})
    assert keys["absolute", "a"] == keys["absolute", "b"]
    assert keys["empty entry", "a"] != keys["empty entry", "b"]  # an interpreter reads "" as its working dir
    assert keys["relative", "a"] != keys["relative", "b"]
    monkeypatch.chdir(tmp_path / "a")
    assert registry._key({}) == registry._key({})


def test_a_pidfd_names_its_process():
    fd = os.pidfd_open(os.getpid())
    r, w = os.pipe()
    try:
        assert pidfd_pid(fd) == os.getpid()
        assert pidfd_pid(r) is None  # not a pidfd
    finally:
        for each in (fd, r, w):
            os.close(each)


@pytest.mark.parametrize("pid", [1, 0, -1])
def test_no_sim_pid_below_2_is_ever_signalled(pair, monkeypatch, pid):
    # killpg(1) is kill(-1): every process this user may signal.
    sent = []
    monkeypatch.setattr(os, "killpg", lambda *args: sent.append(args))
    with pytest.raises(ValueError, match="refusing to signal process group"):
        kill_group(pid, signal.SIGKILL)
    with pytest.raises(ValueError, match="above 1"):
        ForkedProcess(pid, pair[1], -1, zygote_pid=999)
    assert sent == []
    kill_group(12345, signal.SIGTERM)
    assert sent == [(12345, signal.SIGTERM)]


def test_the_zygote_script_the_agent_starts_is_where_it_says():
    from remoteenv.agent.launch.zygote.process import START_SCRIPT

    assert os.path.isfile(START_SCRIPT) and START_SCRIPT.endswith(os.path.join("sim", "process", "zygote", "start.py"))
