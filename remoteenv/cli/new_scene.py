"""``python -m remoteenv new-scene NAME --dir D``: write a standalone env package.

The package is what the env-package guide (``docs/env-package.md``) describes,
ready to install and test: ``D/pyproject.toml`` (the MJCF model as package
data), ``D/NAME/NAME.xml``, ``D/NAME/NAME_scene.py`` (the sim side: a
:class:`~remoteenv.sim.BaseEnv` subclass, ``run_scene`` and a
``demo_policy``), ``D/NAME/__init__.py`` (the agent side: registers
``NAME/Camel-v0`` on import), ``D/tests/test_NAME.py`` and a README. It
passes Gymnasium's env checker as generated; the templates are in
``remoteenv/cli/scene_template/``.
"""

from __future__ import annotations

import argparse
import keyword
import os
import re
import sys
from importlib import resources
from string import Template
from typing import Any

#: Template file -> where it goes, relative to the package dir (``$name`` substituted).
FILES = {
    "pyproject.toml.tmpl": "pyproject.toml",
    "README.md.tmpl": "README.md",
    "init.py.tmpl": "$name/__init__.py",
    "scene.py.tmpl": "$name/${name}_scene.py",
    "model.xml.tmpl": "$name/$name.xml",
    "test.py.tmpl": "tests/test_$name.py",
}


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "new-scene",
        help="write a standalone, installable env package for a new scene",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    p.add_argument("name", help="package name: lower case letters, digits and _ (e.g. pointmass)")
    p.add_argument(
        "--dir", default=None, help="where to write the package (default: ./NAME); must not exist or be empty"
    )
    p.set_defaults(run=run)


def camel(name: str) -> str:
    """``point_mass`` -> ``PointMass``."""
    return "".join(part[:1].upper() + part[1:] for part in name.split("_") if part)


def check_name(name: str) -> str:
    if not re.fullmatch(r"[a-z][a-z0-9_]*", name) or keyword.iskeyword(name) or len(name) > 64:
        raise ValueError(
            f"package name {name[:80]!r} is not usable: use lower case letters, digits and _ , starting with a letter"
        )
    return name


def write_package(name: str, directory: str | os.PathLike[str] | None = None) -> list[str]:
    """Write the package for ``name`` into ``directory`` (default ``./name``);
    returns the paths written. Refuses a non-empty directory; never overwrites."""
    check_name(name)
    root = os.path.abspath(os.fspath(directory) if directory is not None else name)
    if os.path.exists(root) and (not os.path.isdir(root) or os.listdir(root)):
        raise FileExistsError(f"{root} exists and is not an empty directory; pick another --dir")
    values = {"name": name, "Camel": camel(name)}
    templates = resources.files("remoteenv.cli").joinpath("scene_template")
    written = []
    for template, target in FILES.items():
        text = Template(templates.joinpath(template).read_text(encoding="utf-8")).substitute(values)
        path = os.path.join(root, Template(target).substitute(values))
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "x", encoding="utf-8") as f:  # "x": never follow or replace an existing file
            f.write(text)
        written.append(path)
    return written


def run(args: argparse.Namespace) -> int:
    try:
        written = write_package(args.name, args.dir)
    except (ValueError, FileExistsError) as exc:
        print(f"new-scene: {exc}", file=sys.stderr)
        return 2
    root = os.path.dirname(written[0])
    print(f"wrote the env package {args.name} ({camel(args.name)}-v0) to {root}:")
    for path in written:
        print(f"  {os.path.relpath(path, root)}")
    print(
        "next:\n"
        f"  pip install -e {root}\n"
        f"  pytest {os.path.join(root, 'tests')}\n"
        f"  python -m remoteenv demo {args.name}:{args.name}/{camel(args.name)}-v0"
    )
    return 0
