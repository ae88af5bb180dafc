"""Exceptions the agent side raises, one class per error kind.

:class:`RemoteEnvError` is the base; its ``kind`` names what went wrong, and
each kind has its own subclass so callers can ``except`` precisely::

    try:
        env.step(action)
    except remoteenv.SimDiedError: ...      # the sim process exited
    except remoteenv.RemoteEnvTimeout: ...  # alive but did not answer in time
    except remoteenv.SceneError as err:     # the scene's code raised
        print(err.remote_traceback)

``RemoteEnvError(message, kind=k)`` constructs the subclass registered for
``k`` (an unknown kind gives the base class), so every place that raises for
a kind, including error replies decoded from the wire, raises the right type.
"""

from __future__ import annotations

from typing import Any, ClassVar, cast

from remoteenv.wire import wire_errors


class RemoteEnvError(RuntimeError):
    """Something went wrong in, or on the way to, a sim process.

    Attributes:
        kind: ``"scene"`` (the env code raised), ``"protocol"``, ``"state"``,
            ``"invalid_action"``, ``"died"`` (the sim process exited),
            ``"timeout"`` or ``"launch"``; ``"remote"`` when unknown.
        instance: index of the sim instance, if known.
        remote_traceback: the traceback text from the sim process, if any.
    """

    #: The kind each subclass stands for (the base: any other kind).
    KIND: ClassVar[str] = "remote"
    _by_kind: ClassVar[dict[str, type[RemoteEnvError]]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "KIND" in cls.__dict__:
            RemoteEnvError._by_kind.setdefault(cls.KIND, cls)

    def __new__(cls, message: str = "", *, kind: str | None = None, **kwargs: Any) -> RemoteEnvError:
        if cls is RemoteEnvError and kind is not None:
            cls = RemoteEnvError._by_kind.get(kind, RemoteEnvError)
        # The builtin base with the widest instance layout must allocate
        # (OSError's, for the TimeoutError of RemoteEnvTimeout).
        builtin = max((b for b in cls.__mro__ if b.__module__ == "builtins"), key=lambda b: b.__basicsize__)
        return cast(RemoteEnvError, cast(Any, builtin).__new__(cls))

    def __init__(
        self,
        message: str = "",
        *,
        kind: str | None = None,
        instance: int | None = None,
        remote_traceback: str = "",
    ) -> None:
        self.kind = kind if kind is not None else type(self).KIND
        self.instance = instance
        self.remote_traceback = remote_traceback
        text = message
        if remote_traceback:
            text = f"{message}\n--- traceback in the sim process ---\n{remote_traceback.rstrip()}"
        super().__init__(text)

    def __reduce__(self) -> Any:
        # Rebuild from the keyword arguments (the default reduce passes only args).
        return (_rebuild, (type(self), str(self.args[0]) if self.args else "", self.kind, self.instance))


def _rebuild(cls: type[RemoteEnvError], text: str, kind: str, instance: int | None) -> RemoteEnvError:
    return cls(text, kind=kind, instance=instance)


class LaunchError(RemoteEnvError):
    """A sim process could not be started or attached to (kind ``"launch"``)."""

    KIND = "launch"


class SceneArgumentError(LaunchError, TypeError):
    """The scene's env class does not take a keyword argument it was given (a
    launch failure, kind ``"launch"``, and a ``TypeError`` as Python raises for
    an unexpected keyword); raised before launching when the scene script's
    source shows it, else when the sim process reports it."""


class LimitError(LaunchError, ValueError):
    """Something asked for is beyond a bound remoteenv keeps (memory a launch
    would take, the size of its arguments), refused before it is built
    (a launch failure, kind ``"launch"``, and a ``ValueError``); the message
    gives the figures and what to ask for instead."""


class SimDiedError(RemoteEnvError):
    """The sim process exited or was killed while the agent needed it (kind ``"died"``)."""

    KIND = "died"


class RemoteEnvTimeout(RemoteEnvError, TimeoutError):
    """A sim process is alive but did not answer in time (kind ``"timeout"``)."""

    KIND = "timeout"


class SceneError(RemoteEnvError):
    """The scene's env code raised in the sim process (kind ``"scene"``); see ``remote_traceback``."""

    KIND = wire_errors.SCENE


class RemoteProtocolError(RemoteEnvError):
    """A peer broke the wire protocol, or refused ours (kind ``"protocol"``)."""

    KIND = wire_errors.PROTOCOL


class BatchTooLargeError(RemoteProtocolError):
    """A sim hosts more worlds than one batch reply can carry the observations
    of (kind ``"protocol"``); :attr:`worlds_that_fit` says how many would."""

    worlds_that_fit: int = 0


class InvalidActionError(RemoteEnvError, ValueError):
    """The sim refused an action as outside its action space (kind ``"invalid_action"``)."""

    KIND = wire_errors.INVALID_ACTION


class StateError(RemoteEnvError):
    """A call that does not fit the env's state, e.g. step before reset or on a closed env
    (kind ``"state"``)."""

    KIND = wire_errors.STATE


class SceneAttributeError(RemoteEnvError, AttributeError):
    """``get_attr``/``set_attr``/``call`` named a scene attribute that does not
    exist or may not be reached (private, or one that drives the world)
    (kind ``"attribute"``)."""

    KIND = wire_errors.ATTRIBUTE


class UnsendableValueError(RemoteEnvError, TypeError):
    """A scene attribute's value (or a method's result) cannot cross the wire
    (kind ``"unsendable"``)."""

    KIND = wire_errors.UNSENDABLE


__all__ = [
    "BatchTooLargeError",
    "InvalidActionError",
    "LaunchError",
    "LimitError",
    "RemoteEnvError",
    "RemoteEnvTimeout",
    "RemoteProtocolError",
    "SceneArgumentError",
    "SceneAttributeError",
    "SceneError",
    "SimDiedError",
    "StateError",
    "UnsendableValueError",
]
