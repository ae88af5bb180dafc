"""Make ``remoteenv.scenes`` importable from a source checkout.

An installed remoteenv carries the repository's top-level ``scenes/`` folder
as the package ``remoteenv.scenes`` (see ``pyproject.toml``). When Python
imports remoteenv straight from a checkout instead (``python -m remoteenv``
run in the repository root puts the checkout first on ``sys.path``), that
package is not under ``remoteenv/``; this module loads it from ``scenes/``.

Runs in every process that imports ``remoteenv``: the agent's, and a sim's (``remoteenv.sim`` is inside the package).
"""

from __future__ import annotations

import importlib.util
import os
import sys


def ensure_scenes_package() -> None:
    """Import ``remoteenv.scenes``, from ``<checkout>/scenes`` if it is not installed."""
    try:
        import remoteenv.scenes  # noqa: F401

        return
    except ModuleNotFoundError as exc:
        if exc.name != "remoteenv.scenes":
            raise
    folder = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes")
    init = os.path.join(folder, "__init__.py")
    if not os.path.isfile(init):
        raise ModuleNotFoundError(
            "remoteenv.scenes is missing: reinstall remoteenv (pip install .) or run from a "
            "checkout that has the scenes/ folder",
            name="remoteenv.scenes",
        )
    spec = importlib.util.spec_from_file_location("remoteenv.scenes", init, submodule_search_locations=[folder])
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["remoteenv.scenes"] = module
    spec.loader.exec_module(module)
    sys.modules["remoteenv"].scenes = module  # type: ignore[attr-defined]  # as a normal import would bind it
