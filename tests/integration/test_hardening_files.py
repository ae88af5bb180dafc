"""Issue 10, items 7 and 10: files at user paths are never written through a
planted symlink, and a killed ``launch`` leaves no client secret behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from remoteenv.agent.launch.attach import LaunchInfo, read_launch_info, write_launch_info
from remoteenv.wire.files import keys, safe_writes


def test_a_planted_symlink_at_the_launch_info_path_is_replaced_not_followed(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    out = tmp_path / "launch.json"
    out.symlink_to(victim)
    # Every temporary name the old code used is predictable; plant them too.
    for pid in range(os.getpid() - 5, os.getpid() + 5):
        (tmp_path / f"launch.json.tmp-{pid}").symlink_to(victim)
    write_launch_info(out, LaunchInfo(scene="s.py", instances=[]))
    assert victim.read_text() == "precious\n"
    assert not out.is_symlink() and '"format": "remoteenv-launch/1"' in out.read_text()


def test_files_are_created_exclusively_without_following_symlinks(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("x")
    link = tmp_path / "link"
    link.symlink_to(victim)
    with pytest.raises(FileExistsError):
        safe_writes.create_new(link, "y")
    with pytest.raises(FileExistsError):
        keys.write_secret_key(link, keys.generate_keypair().secret)
    assert victim.read_text() == "x"
    secret = tmp_path / "k.key_secret"
    old = os.umask(0)
    try:
        keys.write_secret_key(secret, keys.generate_keypair().secret)
    finally:
        os.umask(old)
    assert (secret.stat().st_mode & 0o777) == 0o600
    safe_writes.write_atomic(tmp_path / "plain.json", "{}", 0o644)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_killed_launch_leaves_no_client_secret_behind(tmp_path, wait_gone):
    out = tmp_path / "launch.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "remoteenv", "launch", "cartpole", "--transport", "tcp", "--curve", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "MUJOCO_GL": "egl"},
    )
    pids: list[int] = []
    try:
        deadline = time.monotonic() + 120
        while not out.exists():
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "launch did not write its file"
            time.sleep(0.05)
        info = read_launch_info(out)
        pids = [s.pid for s in info.instances if s.pid is not None]
        key = info.curve_client_secret_key_file
        assert key is not None and os.path.isabs(key) and os.path.exists(key)
        assert (os.stat(key).st_mode & 0o077) == 0
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        assert all(wait_gone(p, 5.0) for p in pids)
        deadline = time.monotonic() + 5.0
        while os.path.exists(key) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not os.path.exists(key), "the killed launch left its client secret key behind"
        assert not os.path.exists(os.path.dirname(key))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for p in pids:
            try:
                os.kill(p, signal.SIGKILL)
            except ProcessLookupError:
                pass
