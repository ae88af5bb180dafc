"""Pickling and copying an env means building a fresh one from its constructor arguments.

Runs in the agent process. An env holds sockets, a launcher and live sim
processes, none of which can be pickled; what can be is how it was made. So,
as Gymnasium's own envs do (``gymnasium.utils.EzPickle``), the pickled state
of :class:`remoteenv.OpenAIRemoteEnv` and :class:`remoteenv.RemoteVectorEnv`
is their constructor arguments, and unpickling (or ``copy.deepcopy``) calls
the constructor again: the copy launches its own, fresh sims (reset it
before stepping). The original keeps its own sims.

An env built around an object (``launcher=`` a group, ``attach=`` an
:class:`~remoteenv.agent.launch.attach.AttachedSims`) cannot be rebuilt that way;
pickling it raises a ``TypeError`` that says to pass a factory instead.

Neither can an env attached to running sims (``attach=`` a launch-info path,
``gymnasium.make(id, attach=path)``, ``OpenAIRemoteEnv.attach``): rebuilding
it would attach the copy to the *same* sims, so the copy's ``reset`` would
move the original's worlds. Copying or pickling it raises a ``TypeError``
saying so; a process that should drive those sims attaches itself (and the
original then stops driving them).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from typing import Any, TypeVar

_Init = TypeVar("_Init", bound=Callable[..., None])

#: Constructor arguments that may hold objects which cannot be rebuilt in another process.
_OBJECT_ARGUMENTS = ("launcher", "attach")


def remember_init_args(init: _Init) -> _Init:
    """Decorate ``__init__`` so the instance keeps the arguments it was built with."""

    @functools.wraps(init)
    def wrapper(self: Any, *args: Any, **kwargs: Any) -> None:
        self.__dict__["_init_args"] = (args, dict(kwargs))
        init(self, *args, **kwargs)

    return wrapper  # type: ignore[return-value]


class RebuildOnUnpickle:
    """Mixin: the pickled state is the constructor arguments (see the module docstring)."""

    def __getstate__(self) -> dict[str, Any]:
        args, kwargs = self.__dict__.get("_init_args", ((), {}))
        attached = kwargs.get("attach")
        if isinstance(attached, (str, os.PathLike)):
            raise TypeError(
                f"cannot pickle or copy a {type(self).__name__} attached to running sims "
                f"(attach={os.fspath(attached)!r}): a copy would drive the same sims as this env, and its "
                "reset would move this env's worlds. Attach in the process that should drive them "
                "(gymnasium.make(id, attach=path) or OpenAIRemoteEnv.attach(path)), and let one env drive "
                "a sim at a time; for fresh sims of their own, build copies from a launching env instead"
            )
        for key in _OBJECT_ARGUMENTS:
            value = kwargs.get(key)
            if value is not None and not isinstance(value, (str, os.PathLike)):
                raise TypeError(
                    f"cannot pickle or copy a {type(self).__name__} built with {key}={type(value).__name__}(...): "
                    "only its constructor arguments can travel, and that object cannot be rebuilt elsewhere. "
                    "Pass a factory instead (a function that builds the env, e.g. functools.partial or "
                    "lambda: gymnasium.make(...)) and call it in the worker"
                )
        return {"init_args": args, "init_kwargs": kwargs, "spec": getattr(self, "spec", None)}

    def __setstate__(self, state: dict[str, Any]) -> None:
        type(self).__init__(self, *state["init_args"], **state["init_kwargs"])
        if state.get("spec") is not None:
            setattr(self, "spec", state["spec"])  # noqa: B010  (set by gymnasium.make on the original)


__all__ = ["RebuildOnUnpickle", "remember_init_args"]
