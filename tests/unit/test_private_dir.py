"""Where a launch's private dir is made: in TMPDIR when its sockets' paths fit the OS limit, else in a shorter base."""

from __future__ import annotations

import os
import shutil
import stat
import tempfile

import pytest

from remoteenv.agent.errors import LaunchError
from remoteenv.agent.launch import private_dir
from remoteenv.agent.launch.private_dir import MAX_SOCKET_PATH, make_private_dir, socket_path_length


@pytest.fixture
def short_base():
    """A short directory standing in for $XDG_RUNTIME_DIR."""
    base = tempfile.mkdtemp(prefix="rs-", dir="/tmp")
    yield base
    shutil.rmtree(base, ignore_errors=True)


def _long_dir(parent: str) -> str:
    path = os.path.join(parent, "d" * max(1, MAX_SOCKET_PATH - len(parent) - 10))
    os.makedirs(path)
    return path


def test_a_short_tmpdir_takes_the_dir(monkeypatch, short_base):
    monkeypatch.setattr(tempfile, "tempdir", short_base)
    made = make_private_dir(16)
    assert os.path.dirname(made) == short_base
    assert os.path.basename(made).startswith("remoteenv-")
    assert stat.S_IMODE(os.stat(made).st_mode) == 0o700
    assert len(os.fsencode(os.path.join(made, "sim-15.sock"))) <= socket_path_length(short_base, 16)


def test_a_long_tmpdir_moves_the_dir_where_every_socket_fits(monkeypatch, short_base):
    long = _long_dir(short_base)
    assert socket_path_length(long, 16) > MAX_SOCKET_PATH
    runtime = tempfile.mkdtemp(prefix="rt-", dir="/tmp")
    try:
        monkeypatch.setattr(tempfile, "tempdir", long)
        monkeypatch.setenv("XDG_RUNTIME_DIR", runtime)
        made = make_private_dir(16)
        assert os.path.dirname(made) == runtime
        assert stat.S_IMODE(os.stat(made).st_mode) == 0o700
        for i in range(16):
            assert len(os.fsencode(os.path.join(made, f"sim-{i}.sock"))) <= MAX_SOCKET_PATH
        assert os.listdir(long) == []
    finally:
        shutil.rmtree(runtime, ignore_errors=True)


def test_without_xdg_runtime_dir_it_falls_back_to_tmp(monkeypatch, short_base):
    long = _long_dir(short_base)
    monkeypatch.setattr(tempfile, "tempdir", long)
    monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
    made = make_private_dir(4)
    try:
        assert os.path.dirname(made) == "/tmp"
    finally:
        os.rmdir(made)


def test_without_sockets_the_long_tmpdir_is_kept(monkeypatch, short_base):
    long = _long_dir(short_base)
    monkeypatch.setattr(tempfile, "tempdir", long)
    made = make_private_dir(16, sockets=False)
    assert os.path.dirname(made) == long


def test_no_room_anywhere_is_refused_saying_what_to_set(monkeypatch, short_base):
    monkeypatch.setattr(tempfile, "tempdir", short_base)
    monkeypatch.setattr(private_dir, "MAX_SOCKET_PATH", 4)
    with pytest.raises(LaunchError, match="set TMPDIR to a shorter directory, or pass transport='tcp'"):
        make_private_dir(2)
    assert os.listdir(short_base) == []


def test_the_longest_socket_is_the_last_instances(short_base):
    assert socket_path_length(short_base, 10) == len(
        os.fsencode(os.path.join(short_base, "remoteenv-xxxxxxxx/sim-9.sock"))
    )
    assert socket_path_length(short_base, 11) == socket_path_length(short_base, 10) + 1
