"""Checking an env's scene keyword arguments before any sim process starts.

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


@functools.lru_cache(maxsize=64)
def _accepted(path: str, mtime_ns: int) -> tuple[str, frozenset[str]] | None:
    """``(callable's name, keyword names it takes)`` from the script's source, or
    None when the source does not tell (or takes any keyword)."""
    try:
        tree = ast.parse(read_text(path, MAX_SCRIPT_BYTES, what="scene script"), filename=path)
    except (OSError, SyntaxError, ValueError):  # UnreadableFile is a ValueError
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
    try:
        mtime = os.stat(path).st_mtime_ns
    except OSError:
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


__all__ = ["check_scene_kwargs"]
