"""Sim-side diagnostics go through logging (the remoteenv.sim logger), so users can route them."""

from __future__ import annotations

import logging

from remoteenv.sim.process import pacing_levers
from remoteenv.sim.process.log import LOGGER


def test_a_refused_priority_is_a_logged_warning(monkeypatch, caplog, capsys) -> None:
    def refuse(*args):
        raise PermissionError("no")

    monkeypatch.setattr(pacing_levers.os, "sched_setscheduler", refuse, raising=False)
    monkeypatch.setattr(pacing_levers.os, "SCHED_FIFO", 1, raising=False)
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        assert pacing_levers.set_realtime_priority(10) is False
    [record] = caplog.records
    assert record.name == "remoteenv.sim.process.pacing_levers" and record.levelno == logging.WARNING
    assert "SCHED_FIFO priority 10 refused" in record.getMessage()
    assert capsys.readouterr().err == ""  # nothing printed behind logging's back
