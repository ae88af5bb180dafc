"""Issue 19, files the agent reads (launch-info files, key files, delay
traces): opened without blocking, regular files only, read with a size bound,
JSON nesting bounded, and a launch-info file's content checked before
anything connects. A FIFO and /dev/zero stand for hostile files; no process
is started."""

from __future__ import annotations

import json
import os
import threading

import pytest

from remoteenv.agent.errors import LaunchError
from remoteenv.agent.launch.attach import LaunchInfo, read_launch_info
from remoteenv.wire.delays.delay_specs import Trace
from remoteenv.wire.files.keys import load_keypair


def _unblock_fifo_later(path: str) -> threading.Thread:
    """Open ``path`` (a FIFO) for writing once, which ends a reader stuck in open()."""

    def writer() -> None:
        try:
            os.close(os.open(path, os.O_WRONLY))
        except OSError:
            pass

    return threading.Thread(target=writer, daemon=True)


def _in_time(fn, path: str, seconds: float = 10.0) -> BaseException | None:
    """Run ``fn()`` in a thread; what it raised, or a failure if it blocked for ``seconds``."""
    outcome: list[BaseException | None] = []

    def run() -> None:
        try:
            fn()
            outcome.append(None)
        except BaseException as exc:
            outcome.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():
        unblock = _unblock_fifo_later(path)
        unblock.start()
        thread.join(5.0)
        pytest.fail(f"reading {path} blocked for {seconds:g} s")
    return outcome[0]


def test_a_fifo_launch_info_file_is_refused_without_blocking(tmp_path):
    fifo = str(tmp_path / "launch.json")
    os.mkfifo(fifo)
    err = _in_time(lambda: read_launch_info(fifo), fifo)
    assert isinstance(err, LaunchError) and "not a regular file" in str(err)


def test_a_fifo_or_dev_zero_as_key_file_is_refused(tmp_path):
    fifo = str(tmp_path / "client.key_secret")
    os.mkfifo(fifo)
    err = _in_time(lambda: load_keypair(fifo), fifo)
    assert isinstance(err, ValueError) and "not a regular file" in str(err)
    with pytest.raises(ValueError, match="not a regular file"):
        load_keypair("/dev/zero")
    info = LaunchInfo(scene="s.py", instances=[], curve_client_secret_key_file="/dev/zero", path="x.json")
    with pytest.raises(LaunchError, match="cannot be read"):
        info.client_keypair()


@pytest.mark.parametrize("suffix", [".json", ".txt", ".npy"])
def test_a_fifo_trace_file_is_refused_without_blocking(tmp_path, suffix):
    fifo = str(tmp_path / f"trace{suffix}")
    os.mkfifo(fifo)
    err = _in_time(lambda: Trace(fifo), fifo)
    assert isinstance(err, ValueError) and "not a regular file" in str(err)


def test_deeply_nested_json_is_a_clear_error(tmp_path):
    deep = "[" * 100_000 + "]" * 100_000
    launch = tmp_path / "launch.json"
    launch.write_text('{"format": "remoteenv-launch/1", "instances": ' + deep + "}")
    with pytest.raises(LaunchError, match="deeper than 32"):
        read_launch_info(launch)
    trace = tmp_path / "trace.json"
    trace.write_text(deep)
    with pytest.raises(ValueError, match="deeper than 32"):
        Trace(str(trace))


def test_a_key_file_above_its_bound_is_refused(tmp_path):
    big = tmp_path / "client.key_secret"
    big.write_bytes(b"# a comment line\n" * 100_000)  # 1.7 MB of nothing
    with pytest.raises(ValueError, match="more than the 1048576"):
        load_keypair(big)


def _launch_doc(**instance: object) -> dict:
    sim = {"instance": 0, "endpoint": "tcp://127.0.0.1:5555", "pid": None, "curve_server_key": None, **instance}
    return {"format": "remoteenv-launch/1", "scene": "s.py", "worlds_per_instance": 1, "instances": [sim]}


@pytest.mark.parametrize(
    "doc, message",
    [
        (_launch_doc(endpoint="garbage"), "not a tcp:// or ipc:// address"),
        (_launch_doc(endpoint=5), "not a tcp:// or ipc:// address"),
        (_launch_doc(curve_server_key="~" * 40), "Z85"),
        (_launch_doc(curve_server_key="short"), "40 characters"),
        ({**_launch_doc(), "worlds_per_instance": 10**9}, "worlds_per_instance"),
        ({**_launch_doc(), "instances": [_launch_doc()["instances"][0]] * 2000}, "at most 1024"),
        ({**_launch_doc(), "render_mode": ["rgb_array"]}, "render_mode"),
        ({**_launch_doc(), "stepping": ["real_time"]}, "malformed"),
    ],
)
def test_launch_info_content_is_checked_before_anything_connects(tmp_path, doc, message):
    path = tmp_path / "launch.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(LaunchError, match=message):
        read_launch_info(path)


def test_a_trace_npy_whose_header_claims_10_to_the_12_values_is_refused_before_allocating(tmp_path):
    """Issue 28, item 4: ``np.load`` allocated what the header claimed (a raw MemoryError)."""
    import io

    import numpy as np

    from remoteenv.delays import Trace

    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(buffer, {"descr": "<i8", "fortran_order": False, "shape": (10**12,)})
    path = tmp_path / "trace.npy"
    path.write_bytes(buffer.getvalue() + b"\0" * 64)
    with pytest.raises(ValueError, match="header says shape"):
        Trace(str(path))
    np.save(tmp_path / "short.npy", np.arange(10))
    data = (tmp_path / "short.npy").read_bytes()
    (tmp_path / "short.npy").write_bytes(data[:-16])  # the header says 10 values, 8 are there
    with pytest.raises(ValueError, match="holds fewer"):
        Trace(str(tmp_path / "short.npy"))
    np.save(tmp_path / "fine.npy", np.arange(5))
    assert Trace(str(tmp_path / "fine.npy")).values == (0, 1, 2, 3, 4)


def test_a_sim_log_replaced_by_a_fifo_is_not_waited_on(tmp_path):
    """A sim's log is read for its tail without blocking (a FIFO gives nothing)."""
    from remoteenv.agent.launch.sim_process import SimProcess

    os.mkfifo(tmp_path / "sim-0.log")

    class Exited:
        pid, returncode = 12345, 1

        def poll(self):
            return 1

        def wait(self, timeout=None):
            return 1

    sim = SimProcess(instance=0, proc=Exited(), log_path=str(tmp_path / "sim-0.log"), ready_file="")
    outcome = []
    reader = threading.Thread(target=lambda: outcome.append(sim.stderr_tail()), daemon=True)
    reader.start()
    reader.join(10.0)
    if reader.is_alive():
        os.close(os.open(tmp_path / "sim-0.log", os.O_WRONLY | os.O_NONBLOCK))
        reader.join(5.0)
        pytest.fail("reading a FIFO as the sim's log blocked")
    assert outcome == [""]
    (tmp_path / "real.log").write_bytes(b"x" * 20000 + b"\nlast line\n")
    sim.log_path = str(tmp_path / "real.log")
    assert sim.stderr_tail(1) == "last line"
