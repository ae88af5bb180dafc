"""What a zygote imports before it forks, and what keeps a fork from being a fresh start.

Runs in the zygote process. :data:`BASE_MODULES` is what every sim imports
before its handshake; :func:`scene_imports` reads a scene script's top-level
imports from its source (without running it). :func:`shadowing` names the
imported modules that a file in a scene's folder would replace in a fresh
interpreter (which puts that folder first on ``sys.path``).
"""

from __future__ import annotations

import ast
import importlib
import importlib.machinery
import os
import sys

#: Modules every sim imports before its handshake (a scene's own come on top).
BASE_MODULES = (
    "numpy",
    "numpy.random",
    "mujoco",
    "gymnasium",
    "gymnasium.spaces",
    "gymnasium.utils.seeding",
    "zmq",
    "msgpack",
    "remoteenv.sim",
    "remoteenv.sim.batch_result",
    "remoteenv.wire.handshake",
)


def scene_imports(path: str) -> list[str]:
    """The absolute imports at the top level of the script at ``path``, in
    order: ``import a.b`` gives ``a.b``; ``from a import b`` gives ``a`` and
    ``a.b`` (``b`` may be a submodule). Empty if the file cannot be read or parsed."""
    try:
        with open(path, encoding="utf-8") as f:
            tree = ast.parse(f.read(), filename=path)
    except (OSError, SyntaxError, ValueError):
        return []
    names: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and node.module != "__future__":
            names.append(node.module)
            names += [f"{node.module}.{alias.name}" for alias in node.names if alias.name != "*"]
    return list(dict.fromkeys(names))


def preload(modules: list[str] | tuple[str, ...]) -> list[str]:
    """Import each of ``modules``; return those that failed. A ``from a import
    b`` where ``b`` is no module is not a failure (it is an attribute)."""
    failed = []
    for name in modules:
        if name in sys.modules:
            continue
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as exc:
            parent = name.rpartition(".")[0]
            if not (parent and exc.name == name and parent in sys.modules):
                failed.append(name)
        except Exception:  # a scene's import may fail here and work in the sim (or fail there, reported)
            failed.append(name)
    return failed


def shadowing(folder: str) -> list[str]:
    """The imported top-level modules that a file or package in ``folder``
    would be imported as instead, were ``folder`` first on ``sys.path``."""
    try:
        entries = os.listdir(folder)
    except OSError:
        return []
    suffixes = sorted(importlib.machinery.all_suffixes(), key=len, reverse=True)
    names = set()
    for entry in entries:
        if os.path.isfile(os.path.join(folder, entry, "__init__.py")):
            names.add(entry)
            continue
        for suffix in suffixes:
            if entry.endswith(suffix):
                names.add(entry[: -len(suffix)])
                break
    loaded = {name.partition(".")[0] for name in sys.modules}
    return sorted(names & loaded)


__all__ = ["BASE_MODULES", "preload", "scene_imports", "shadowing"]
