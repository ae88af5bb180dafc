"""The vector env's torch_threads choice: "auto" lowers torch's intra-op threads
once, to the CPUs the local sims leave free, and says so; it never raises them,
never acts twice, and leaves torch alone when the user chose (OMP_NUM_THREADS,
None, an int)."""

from __future__ import annotations

import sys
import warnings

import pytest
from fakes import FakeTorch, fake_torch_on

from remoteenv.agent.vector import torch_threads
from remoteenv.agent.vector.torch_threads import TorchThreads, TorchThreadsNotice, check_torch_threads


@pytest.fixture
def fake_torch(monkeypatch):
    return fake_torch_on(monkeypatch, cpus=4)


def test_auto_leaves_the_sims_their_cpus_once_and_says_so(fake_torch):
    with pytest.warns(TorchThreadsNotice, match=r"torch's CPU threads to 1 \(was 4\).*on 4 of this machine.s 4 CPUs"):
        TorchThreads("auto", local_sims=4).apply()
    assert fake_torch.calls == [1]
    fake_torch.threads = 3  # the user raised it again after: remoteenv does not fight them
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        TorchThreads("auto", local_sims=4).apply()
    assert fake_torch.calls == [1]


def test_auto_keeps_what_the_sims_do_not_need_and_never_raises(fake_torch):
    with pytest.warns(TorchThreadsNotice):
        TorchThreads("auto", local_sims=2).apply()
    assert fake_torch.threads == 2
    torch_threads._Applied.done = False
    fake_torch.threads = 1
    TorchThreads("auto", local_sims=1).apply()  # 3 would be free: torch's 1 stays
    assert fake_torch.calls == [2]


def test_auto_leaves_torch_alone_when_the_user_chose(fake_torch, monkeypatch):
    TorchThreads(None, local_sims=4).apply()
    TorchThreads("auto", local_sims=0).apply()  # no sim on this machine (attached, a cluster)
    monkeypatch.setenv("OMP_NUM_THREADS", "4")
    TorchThreads("auto", local_sims=4).apply()
    assert fake_torch.calls == []
    TorchThreads(3, local_sims=4).apply()  # an explicit count is set as asked, quietly
    assert fake_torch.calls == [3]


def test_auto_waits_for_torch_to_be_loaded(monkeypatch):
    monkeypatch.delitem(sys.modules, "torch", raising=False)
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.setattr(torch_threads._Applied, "done", False)
    monkeypatch.setattr(torch_threads, "usable_cpus", lambda: 2)
    choice = TorchThreads("auto", local_sims=2)
    choice.apply()  # torch not loaded: nothing to do yet
    torch = FakeTorch(2)
    monkeypatch.setitem(sys.modules, "torch", torch)
    with pytest.warns(TorchThreadsNotice):
        choice.apply()  # the next reset finds it
    assert torch.calls == [1]


@pytest.mark.parametrize("bad", [0, -1, 1.5, "all", True])
def test_torch_threads_takes_auto_none_or_a_positive_int(bad):
    assert check_torch_threads("auto") == "auto" and check_torch_threads(None) is None
    assert check_torch_threads(2) == 2
    with pytest.raises(ValueError, match="torch_threads must be 'auto', None or an int >= 1"):
        check_torch_threads(bad)


def test_the_notice_names_the_users_line_not_remoteenvs_or_gymnasiums(fake_torch):
    import gymnasium.vector.utils as gym_utils  # any module of each package

    import remoteenv.agent.session.pickling as re_module

    def constructor() -> None:  # stands for the vector env's (wrapped) constructor
        TorchThreads("auto", local_sims=4).apply()

    def make_vec() -> None:  # stands for gym.make_vec
        constructor()

    constructor.__code__ = constructor.__code__.replace(co_filename=re_module.__file__)
    make_vec.__code__ = make_vec.__code__.replace(co_filename=gym_utils.__file__)
    with pytest.warns(TorchThreadsNotice) as caught:
        make_vec()
    assert caught[0].filename == __file__
