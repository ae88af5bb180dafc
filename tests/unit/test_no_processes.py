"""The unit layer's guard: a unit test cannot start a process."""

import subprocess
import sys

import pytest


def test_starting_a_process_fails_in_a_unit_test() -> None:
    with pytest.raises(AssertionError, match="tests/integration"):
        subprocess.run([sys.executable, "-c", "pass"], check=False)
