"""Restart policy: the budget, which instances a failure costs, gathering with relaunches."""

from __future__ import annotations

import pytest

from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout, SceneError, SimDiedError
from remoteenv.agent.launch.restart import RestartBudget, gather_restarting, instances_lost, restarted_info


def died(instance: int) -> RemoteEnvError:
    return RemoteEnvError(f"sim instance {instance} died", kind="died", instance=instance)


def test_budget_covers_deaths_and_timeouts_only_when_enabled():
    on, off = RestartBudget(True, 2), RestartBudget(False, 2)
    timeout = RemoteEnvError("slow", kind="timeout", instance=0)
    scene = RemoteEnvError("boom", kind="scene", instance=0)
    assert isinstance(timeout, RemoteEnvTimeout) and isinstance(scene, SceneError)
    assert on.covers(died(0)) and on.covers(timeout) and not on.covers(scene)
    assert not off.covers(died(0))


def test_budget_spends_up_to_the_cap_then_raises_the_same_kind():
    budget = RestartBudget(True, 2)
    assert budget.spend(died(1)) == 1 and budget.spend(died(1)) == 2
    with pytest.raises(SimDiedError, match=r"giving up after 2 restart\(s\) \(max_restarts=2\)") as err:
        budget.spend(died(1))
    assert err.value.instance == 1 and err.value.kind == "died" and budget.count == 2


def test_budget_refuses_a_negative_cap():
    with pytest.raises(ValueError, match="max_restarts"):
        RestartBudget(True, -1)


def test_restarted_info():
    info = restarted_info(died(3), 2)
    assert info == {"remoteenv_restarted": True, "remoteenv_restarts": 2, "remoteenv_error": "sim instance 3 died"}


def test_a_timeout_costs_every_pending_instance_a_death_only_its_own():
    timeout = RemoteEnvError("slow", kind="timeout", instance=1)
    assert instances_lost(timeout, [1, 2, 5]) == [1, 2, 5]
    assert instances_lost(died(2), [1, 2, 5]) == [2]


class Script:
    """A gather that fails as scripted, then answers everything pending."""

    def __init__(self, *failures: RemoteEnvError) -> None:
        self.failures = list(failures)
        self.relaunched: list[int] = []

    def gather(self, pending: dict[int, int], replies: dict) -> None:
        if self.failures:
            raise self.failures.pop(0)
        for p, seq in list(pending.items()):
            replies[p] = {"seq": seq}
            del pending[p]

    def relaunch(self, p: int, err: RemoteEnvError) -> None:
        self.relaunched.append(p)


def test_gather_restarting_relaunches_and_resends():
    script = Script(died(1))
    replies, failed = gather_restarting(
        script.gather, script.relaunch, RestartBudget(True, 3), {0: 10, 1: 11}, resend=lambda p: 100 + p
    )
    assert script.relaunched == [1] and list(failed) == [1]
    assert replies == {0: {"seq": 10}, 1: {"seq": 101}}


def test_gather_restarting_without_resend_leaves_the_lost_instance_without_reply():
    timeout = RemoteEnvError("slow", kind="timeout", instance=0)
    script = Script(timeout)
    replies, failed = gather_restarting(script.gather, script.relaunch, RestartBudget(True, 3), {0: 1, 1: 2})
    assert replies == {} and set(failed) == {0, 1} and script.relaunched == [0, 1]


def test_gather_restarting_raises_what_the_budget_does_not_cover():
    scene = RemoteEnvError("boom", kind="scene", instance=0)
    with pytest.raises(SceneError):
        gather_restarting(Script(scene).gather, Script().relaunch, RestartBudget(True, 3), {0: 1})
    with pytest.raises(SimDiedError):
        gather_restarting(Script(died(0)).gather, Script().relaunch, RestartBudget(False, 3), {0: 1})
    with pytest.raises(SimDiedError):  # an instance that was not pending
        gather_restarting(Script(died(7)).gather, Script().relaunch, RestartBudget(True, 3), {0: 1})
