"""The python code blocks of the README and the guides run as written.

A block preceded by the line ``<!-- skip-test -->`` is not run (long
training, code that needs files of its own, fragments). Each block runs on
its own in a fresh interpreter with this checkout first on ``sys.path``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
#: The documents whose blocks must run (the guides written for issue 14).
DOCUMENTS = [
    "README.md",
    "docs/using.md",
    "docs/env-package.md",
    "docs/real-time.md",
    "docs/vector-envs.md",
    "docs/training.md",
    "docs/rendering.md",
    "docs/attach.md",
    "docs/failures-and-security.md",
    "docs/protocol.md",
    "docs/troubleshooting.md",
    "docs/latency-twin.md",
    "docs/latency.md",
    "docs/delays.md",
    "docs/startup.md",
    "docs/cameras.md",
]
SKIP = "<!-- skip-test -->"
_BLOCK = re.compile(r"^(?P<indent>[ \t]*)```python[ \t]*\n(?P<code>.*?)^(?P=indent)```[ \t]*$", re.M | re.S)


def python_blocks(path: str) -> list[tuple[int, str, bool]]:
    """``(line number, code, skipped)`` of every python block in ``path``."""
    with open(path, encoding="utf-8") as f:
        text = f.read()
    blocks = []
    for match in _BLOCK.finditer(text):
        before = text[: match.start()].rstrip("\n").splitlines()
        skipped = bool(before) and before[-1].strip() == SKIP
        line = text.count("\n", 0, match.start()) + 1
        blocks.append((line, textwrap.dedent(match.group("code")), skipped))
    return blocks


CASES = [
    pytest.param(doc, line, code, id=f"{doc}:{line}")
    for doc in DOCUMENTS
    for line, code, skipped in python_blocks(os.path.join(ROOT, doc))
    if not skipped
]


def test_every_document_exists_and_blocks_are_found():
    for doc in DOCUMENTS:
        assert os.path.isfile(os.path.join(ROOT, doc)), doc
    assert len(CASES) >= 8


@pytest.mark.parametrize(("doc", "line", "code"), CASES)
def test_code_block_runs(doc, line, code, tmp_path):
    script = tmp_path / "block.py"
    script.write_text(code)
    env = dict(os.environ, PYTHONPATH=ROOT, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    result = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, f"{doc} line {line} failed:\n{code}\n--- stderr ---\n{result.stderr[-3000:]}"
