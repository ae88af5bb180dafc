"""Issue 35, item 1: removing remoteenv's private dirs acts only on the dir
remoteenv made, through descriptors, never through a symlink, and never opens
anything that could block (``remoteenv.wire.files.owned_dirs``)."""

from __future__ import annotations

import os
from pathlib import Path

from remoteenv.sim.process.orphan_guard import remove_instance_files
from remoteenv.wire.files.owned_dirs import format_id, identity, parse_id, remove_dir


def _victim(tmp_path: Path) -> Path:
    victim = tmp_path / "victim"
    victim.mkdir()
    for name in ("sim-0.keep", "sim-0.log", "other.txt"):
        (victim / name).write_text("mine\n")
    return victim


def _private(tmp_path: Path) -> Path:
    private = tmp_path / "remoteenv-x"
    private.mkdir()
    (private / "sim-0.log").write_text("log\n")
    (private / "sim-0.ready.json").write_text("{}\n")
    return private


def test_a_private_dir_swapped_for_a_symlink_is_refused(tmp_path):
    victim = _victim(tmp_path)
    private = _private(tmp_path)
    dir_id = identity(str(private))
    assert dir_id is not None
    os.rename(private, tmp_path / "moved")
    os.symlink(victim, private)
    remove_instance_files(str(private), dir_id, 0)
    assert remove_dir(str(private), dir_id) is False
    remove_dir(str(private), None)  # even without an identity: a symlink is never followed
    assert sorted(os.listdir(victim)) == ["other.txt", "sim-0.keep", "sim-0.log"]
    assert private.is_symlink()


def test_a_private_dir_swapped_for_another_dir_is_refused(tmp_path):
    private = _private(tmp_path)
    dir_id = identity(str(private))
    os.rename(private, tmp_path / "moved")
    private.mkdir()
    (private / "sim-0.keep").write_text("not remoteenv's\n")
    remove_instance_files(str(private), dir_id, 0)
    assert not remove_dir(str(private), dir_id)
    assert (private / "sim-0.keep").exists()


def test_nothing_is_tidied_in_a_dir_whose_identity_was_not_taken(tmp_path):
    private = _private(tmp_path)
    remove_instance_files(str(private), None, 0)
    assert sorted(os.listdir(private)) == ["sim-0.log", "sim-0.ready.json"]


def test_an_instances_files_go_and_the_dir_with_the_last_sims(tmp_path):
    private = _private(tmp_path)
    (private / "sim-1.log").write_text("log\n")
    (private / "launcher.json").write_text("{}\n")
    dir_id = identity(str(private))
    remove_instance_files(str(private), dir_id, 0)
    assert sorted(os.listdir(private)) == ["launcher.json", "sim-1.log"]
    remove_instance_files(str(private), dir_id, 1)
    assert not private.exists()


def test_symlinks_and_fifos_inside_are_removed_not_followed_or_opened(tmp_path):
    victim = _victim(tmp_path)
    private = _private(tmp_path)
    os.symlink(victim, private / "link-to-dir")
    os.symlink(victim / "sim-0.keep", private / "sim-0.link")
    os.mkfifo(private / "sim-0.fifo")
    sub = private / "nested" / "deeper"
    sub.mkdir(parents=True)
    os.mkfifo(sub / "pipe")
    os.symlink(victim, sub / "up")
    assert remove_dir(str(private), identity(str(private)))
    assert not private.exists()
    assert sorted(os.listdir(victim)) == ["other.txt", "sim-0.keep", "sim-0.log"]


def test_a_fifo_or_file_at_the_dirs_path_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "remoteenv-fifo"
    os.mkfifo(fifo)
    assert identity(str(fifo)) is None
    assert remove_dir(str(fifo), None) is False  # would block forever if it opened the FIFO
    assert fifo.is_fifo()
    plain = tmp_path / "remoteenv-file"
    plain.write_text("x")
    assert remove_dir(str(plain), None) is False and plain.exists()


def test_identities_round_trip_and_malformed_ones_are_none():
    assert parse_id(format_id((12, 34))) == (12, 34)
    assert format_id(None) == "" and parse_id("") is None
    for bad in ("12", "a:b", "1:2:3", "-1:2", ":"):
        assert parse_id(bad) is None
