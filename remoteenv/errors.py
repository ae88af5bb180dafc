"""Exceptions the agent side raises."""

from __future__ import annotations


class RemoteEnvError(RuntimeError):
    """Something went wrong in, or on the way to, a sim process.

    Attributes:
        kind: ``"scene"`` (the env code raised), ``"protocol"``, ``"state"``,
            ``"invalid_action"``, ``"died"`` (the sim process exited),
            ``"timeout"`` or ``"launch"``.
        instance: index of the sim instance, if known.
        remote_traceback: the traceback text from the sim process, if any.
    """

    def __init__(
        self,
        message: str,
        *,
        kind: str = "remote",
        instance: int | None = None,
        remote_traceback: str = "",
    ) -> None:
        self.kind = kind
        self.instance = instance
        self.remote_traceback = remote_traceback
        text = message
        if remote_traceback:
            text = f"{message}\n--- traceback in the sim process ---\n{remote_traceback.rstrip()}"
        super().__init__(text)


class RemoteEnvTimeout(RemoteEnvError, TimeoutError):
    """A sim process is alive but did not answer in time."""
