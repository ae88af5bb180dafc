"""What a zygote imports before it forks, and what keeps a fork from being a fresh start.

Runs in the zygote process. :data:`BASE_MODULES` is what every sim imports
before its handshake; :func:`scene_imports` reads a scene script's top-level
imports from its source (without running it), of which the zygote imports
only those :func:`installed` says come from the standard library or an
installed distribution: a module of the user's own (on ``PYTHONPATH``, in
the scene's folder, an editable install) may read ``sys.argv``, the working
directory or the clock when it is imported, and must be imported by the sim
itself. :func:`shadowing` names the imported modules that a file in a
scene's folder would replace in a fresh interpreter (which puts that folder
first on ``sys.path``).
"""

from __future__ import annotations

import ast
import importlib
import importlib.machinery
import importlib.util
import os
import site
import sys
import sysconfig

from remoteenv.wire.files.file_reads import read_text

#: Largest scene script whose imports are read.
MAX_SCRIPT_BYTES = 4 << 20

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
    "remoteenv.sim.scene.batch_result",
    "remoteenv.wire.messages.handshake",
)


def scene_imports(path: str) -> list[str]:
    """The absolute imports at the top level of the script at ``path``, in
    order: ``import a.b`` gives ``a.b``; ``from a import b`` gives ``a`` and
    ``a.b`` (``b`` may be a submodule). Empty if the file cannot be read or parsed."""
    try:
        tree = ast.parse(read_text(path, MAX_SCRIPT_BYTES, what="scene script"), filename=path)
    except (OSError, SyntaxError, ValueError):  # UnreadableFile is a ValueError
        return []
    names: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and node.module != "__future__":
            names.append(node.module)
            names += [f"{node.module}.{alias.name}" for alias in node.names if alias.name != "*"]
    return list(dict.fromkeys(names))


def _installed_roots() -> tuple[str, ...]:
    paths = sysconfig.get_paths()
    roots = [paths[key] for key in ("stdlib", "platstdlib", "purelib", "platlib") if key in paths]
    roots += site.getsitepackages() if hasattr(site, "getsitepackages") else []
    roots.append(site.getusersitepackages())
    return tuple(os.path.join(os.path.realpath(root), "") for root in roots)


def installed(name: str) -> bool:
    """Whether module ``name`` is safe to import ahead of a scene: its top-level
    package is imported already, built in, or found (without importing it) in
    the standard library or an installed distribution's site-packages."""
    top = name.partition(".")[0]
    if top in sys.modules or top in sys.builtin_module_names:
        return True
    try:
        spec = importlib.util.find_spec(top)
    except (ImportError, ValueError):
        return False
    if spec is None:
        return False
    where = spec.origin if spec.has_location and spec.origin else None
    if where is None and spec.submodule_search_locations:
        where = next(iter(spec.submodule_search_locations), None)
    return where is not None and os.path.realpath(where).startswith(_installed_roots())


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
