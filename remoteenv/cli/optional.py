"""The optional dependencies of the commands, and one clear message when one is missing.

A command imports an optional package through :func:`require` before it
starts any work; :func:`remoteenv.cli.main` turns a missing optional package
found later (deep in a benchmark, say) into the same message.

Runs in the agent process (the command's own).
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: Top-level module -> the extra of remoteenv that installs it.
EXTRAS = {
    "tqdm": "torch",
    "matplotlib": "torch",
    "torch": "torch",
    "torchrl": "torchrl",
    "moviepy": "video",
    "stable_baselines3": "sb3",
    "envpool": "bench",
    "ray": "ray",
}


def missing_message(module: str, purpose: str) -> str:
    """What to tell a user whose ``purpose`` needs ``module``, which is not installed."""
    top = module.split(".")[0]
    extra = EXTRAS.get(top)
    how = f"pip install 'remoteenv[{extra}]'" if extra else f"pip install {top}"
    return f"{purpose} needs {top}, which is not installed: {how}"


def is_optional(exc: ModuleNotFoundError) -> bool:
    """Whether ``exc`` is about one of the optional packages of :data:`EXTRAS`."""
    return (exc.name or "").split(".")[0] in EXTRAS


def require(module: str, purpose: str) -> ModuleType:
    """Import ``module``; if it is not installed, exit with :func:`missing_message`.

    A module that is installed but fails to import itself raises as usual.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if (exc.name or "").split(".")[0] != module.split(".")[0]:
            raise
        raise SystemExit(missing_message(module, purpose)) from None


__all__ = ["EXTRAS", "is_optional", "missing_message", "require"]
