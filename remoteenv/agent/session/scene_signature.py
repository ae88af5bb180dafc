"""What a scene script says of itself, read before any sim process starts:
the keyword arguments its env takes, and whether it steps its worlds as one batch.

Runs in the agent process, which never imports scene code (a scene script
belongs to the sim side and may need what the agent lacks). Instead it reads
the script's source: the env factory that ``run_scene`` is given (a class
or a function defined in the script) and the parameters of its
``__init__`` (or of the function). A keyword the factory does not take is
refused with :class:`~remoteenv.agent.errors.SceneArgumentError`, a
``TypeError`` worded as Python words it (``... got an unexpected keyword
argument 'x'``), which libraries that retry without an argument (TorchRL
drops ``frameskip``) recognise.

When the source does not say (a factory imported from elsewhere, a class
without its own ``__init__``, a ``**kwargs`` parameter), nothing is refused
here; the sim process then reports a rejected keyword itself, as the same
error (see :func:`remoteenv.sim.scene_main.run_scene`).

:func:`declares_stacked_hooks` tells whether a class of the script sets
``stacked_hooks = True``: a hint for the default layout's first launch,
which the first sim's handshake then confirms or corrects.
"""

from __future__ import annotations

import ast
import functools
import os
from collections.abc import Iterable

from remoteenv.agent.errors import SceneArgumentError
from remoteenv.wire.files.file_reads import read_text

#: Largest scene script whose source is read for its keywords.
MAX_SCRIPT_BYTES = 4 << 20


@functools.lru_cache(maxsize=16)
def _tree(path: str, mtime_ns: int) -> ast.Module | None:
    """The script's syntax tree (None: unreadable, too large or not Python)."""
    try:
        return ast.parse(read_text(path, MAX_SCRIPT_BYTES, what="scene script"), filename=path)
    except (OSError, SyntaxError, ValueError):  # UnreadableFile is a ValueError
        return None


def _mtime_ns(path: str) -> int | None:
    """The script's modification time, the key of what is read of it (None: no such file)."""
    try:
        return os.stat(path).st_mtime_ns
    except OSError:
        return None


@functools.lru_cache(maxsize=64)
def _accepted(path: str, mtime_ns: int) -> tuple[str, frozenset[str]] | None:
    """``(callable's name, keyword names it takes)`` from the script's source, or
    None when the source does not tell (or takes any keyword)."""
    tree = _tree(path, mtime_ns)
    if tree is None:
        return None
    factory = None
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and node.args:
            fn = node.func
            called = fn.id if isinstance(fn, ast.Name) else fn.attr if isinstance(fn, ast.Attribute) else None
            if called == "run_scene" and isinstance(node.args[0], ast.Name):
                factory = node.args[0].id
                break
    if factory is None:
        return None
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == factory:
            inits = [
                n for n in node.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.name == "__init__"
            ]
            if not inits:
                return None
            return _params(f"{factory}.__init__", inits[0].args, skip_first=True)
        if isinstance(node, ast.FunctionDef) and node.name == factory:
            return _params(factory, node.args, skip_first=False)
    return None


def _params(name: str, args: ast.arguments, *, skip_first: bool) -> tuple[str, frozenset[str]] | None:
    if args.kwarg is not None:
        return None
    keywords = [a.arg for a in args.args[len(args.posonlyargs) :]]
    if skip_first and not args.posonlyargs:
        keywords = keywords[1:]
    return name, frozenset(keywords) | frozenset(a.arg for a in args.kwonlyargs)


def check_scene_kwargs(scene: str | os.PathLike[str], names: Iterable[str]) -> None:
    """Raise :class:`SceneArgumentError` if the scene script's env factory
    certainly does not take one of the keyword arguments ``names``."""
    path = os.fspath(scene)
    mtime = _mtime_ns(path)
    if mtime is None:
        return  # the launcher reports a missing script
    accepted = _accepted(path, mtime)
    if accepted is None:
        return
    factory, keywords = accepted
    for name in names:
        if name not in keywords:
            raise SceneArgumentError(
                f"{factory}() got an unexpected keyword argument {name!r} "
                f"(scene {os.path.basename(path)} takes {sorted(keywords)}; no sim was launched)"
            )


def declares_stacked_hooks(scene: str | os.PathLike[str]) -> bool:
    """Whether a class in the scene script's source sets ``stacked_hooks = True``
    (a class that inherits it from a scene elsewhere is not seen: False)."""
    path = os.fspath(scene)
    mtime = _mtime_ns(path)
    tree = None if mtime is None else _tree(path, mtime)
    if tree is None:
        return False
    for node in ast.walk(tree):
        if not isinstance(node, ast.ClassDef):
            continue
        for statement in node.body:
            value: ast.expr | None
            if isinstance(statement, ast.Assign):
                targets, value = statement.targets, statement.value
            elif isinstance(statement, ast.AnnAssign):
                targets, value = [statement.target], statement.value
            else:
                continue
            named = any(isinstance(target, ast.Name) and target.id == "stacked_hooks" for target in targets)
            if named and isinstance(value, ast.Constant) and value.value is True:
                return True
    return False


__all__ = ["check_scene_kwargs", "declares_stacked_hooks"]
