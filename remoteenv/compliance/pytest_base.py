"""The compliance suite as a pytest base class, one test per check.

A server author subclasses :class:`ComplianceTests` in a test module::

    from remoteenv.compliance import ComplianceTests

    class TestMyBridge(ComplianceTests):
        launch_info = "/path/to/launch.json"      # a launch-info file naming the server

or, to start the server for the class, overrides the
``compliance_launch_info`` fixture (any scope) to yield the path::

    class TestMyBridge(ComplianceTests):
        @pytest.fixture(scope="class")
        @classmethod
        def compliance_launch_info(cls, tmp_path_factory):
            ...start the server, which writes the file...
            yield path
            ...stop it...

Each check is a test named ``test_protocol[<check name>]``; a failing check
fails with its reason, a check that does not apply is skipped with why.

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

import os
from typing import ClassVar

import pytest

from remoteenv.compliance.check_results import FAIL, SKIP, Check
from remoteenv.compliance.probe import targets_from_launch_info
from remoteenv.compliance.suite import CHECKS, run_check


class ComplianceTests:
    """Subclass (as ``Test...``) to run every compliance check on one server.

    Class attributes:
        launch_info: path of the launch-info file (or override the
            ``compliance_launch_info`` fixture).
        instance: which instance of the file to check.
        allow_close: run the ``close`` check, which stops the server
            (run last; leave False if the server must outlive the class).
        timeout: seconds to wait for each reply.
    """

    launch_info: ClassVar[str | os.PathLike[str] | None] = None
    instance: ClassVar[int] = 0
    allow_close: ClassVar[bool] = False
    timeout: ClassVar[float] = 10.0

    @pytest.fixture
    def compliance_launch_info(self) -> str | os.PathLike[str]:
        """The launch-info file of the server under test (default: ``launch_info``)."""
        if self.launch_info is None:
            pytest.fail(
                f"{type(self).__name__}: set launch_info or override the compliance_launch_info fixture", pytrace=False
            )
        return self.launch_info

    @pytest.mark.parametrize("check", CHECKS, ids=[c.name for c in CHECKS])
    def test_protocol(self, check: Check, compliance_launch_info: str | os.PathLike[str]) -> None:
        (target,) = targets_from_launch_info(
            compliance_launch_info, self.instance, timeout=self.timeout, allow_close=self.allow_close
        )
        result = run_check(check, target)
        if result.status == SKIP:
            pytest.skip(f"{check.name}: {result.reason}")
        if result.status == FAIL:
            pytest.fail(f"{check.name} ({check.description}): {result.reason}", pytrace=False)


__all__ = ["ComplianceTests"]
