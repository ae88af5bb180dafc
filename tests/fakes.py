"""Stand-ins the unit tests share: a torch module that only counts threads, and
a shipped scene's env class loaded from its script."""

from __future__ import annotations

import importlib.util
import types
from typing import Any

import remoteenv


class FakeTorch(types.ModuleType):
    """``torch`` as far as thread counts go: ``set_num_threads`` calls are kept in ``calls``."""

    def __init__(self, threads: int) -> None:
        super().__init__("torch")
        self.threads = threads
        self.calls: list[int] = []

    def get_num_threads(self) -> int:
        return self.threads

    def set_num_threads(self, n: int) -> None:
        self.calls.append(n)
        self.threads = n


def scene_class(name: str, cls: str, module_name: str) -> Any:
    """Class ``cls`` of the shipped scene ``name``'s script, loaded as module ``module_name``."""
    spec = importlib.util.spec_from_file_location(module_name, remoteenv.scene_path(name))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return getattr(module, cls)
