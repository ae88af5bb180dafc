"""``python -m remoteenv new-scene NAME --dir D``: write a standalone env package.

The package is what the env-package guide (``docs/env-package.md``) describes,
ready to install and test, in a src layout: ``D/pyproject.toml`` (the MJCF
model as package data), ``D/src/NAME/NAME.xml``, ``D/src/NAME/NAME_scene.py``
(the sim side: a BaseEnv subclass, ``run_scene`` and a ``demo_policy``),
``D/src/NAME/__init__.py`` (the agent side: registers ``NAME/<Name>-v0`` on
import, ``<Name>`` being NAME in CamelCase, e.g. ``ball_plate/BallPlate-v0``),
``D/tests/test_NAME.py`` and a README. It passes Gymnasium's env checker as
generated. With ``--pixels`` the id observes through the scene's camera (the
registration's ``obs_mode="pixels"``: uint8 images rendered in the sim). NAME must not be the name of an importable module (``numpy``,
``os``, ``remoteenv``, ...), which the package would hide.

Why a src layout: with the package directly in ``D`` (``D/NAME/``), running
Python in the folder above ``D`` (where ``new-scene`` was run, when ``D`` is
``./NAME``) imports the project folder ``./NAME`` as an empty namespace
package, which hides the installed one. Under ``src/`` no folder on the
import path is named like the package. The templates are in
``remoteenv/cli/scene_template/``.
"""

from __future__ import annotations

import argparse
import importlib.machinery
import importlib.metadata
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
    "init.py.tmpl": "src/$name/__init__.py",
    "scene.py.tmpl": "src/$name/${name}_scene.py",
    "model.xml.tmpl": "src/$name/$name.xml",
    "test.py.tmpl": "tests/test_$name.py",
}


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "new-scene",
        help="write a standalone, installable env package for a new scene",
        description=__doc__.split("\n\n")[1].replace("``", "") if __doc__ else None,
    )
    p.add_argument("name", help="package name: lower case letters, digits and _ (e.g. pointmass)")
    p.add_argument(
        "--dir", default=None, help="where to write the package (default: ./NAME); must not exist or be empty"
    )
    p.add_argument(
        "--pixels",
        action="store_true",
        help="a camera scene: the id's observation is the overhead camera's 64x64 image "
        "(obs_mode='pixels'; 'state_pixels' and 'state' stay available as kwargs)",
    )
    p.set_defaults(run=run)


def camel(name: str) -> str:
    """``point_mass`` -> ``PointMass``."""
    return "".join(part[:1].upper() + part[1:] for part in name.split("_") if part)


def existing_module(name: str) -> str | None:
    """Where an importable top-level module ``name`` comes from (the standard
    library, a file or a folder), or None if there is none. The working
    directory is left out: a folder there is what ``--dir`` may create."""
    if name in sys.builtin_module_names or name in getattr(sys, "stdlib_module_names", ()):
        return "the standard library"
    loaded = getattr(sys.modules.get(name), "__file__", None)
    if loaded:
        return str(loaded)
    cwd = os.getcwd()
    path = [p for p in sys.path if p and os.path.abspath(p) != cwd]
    for finder in sys.meta_path:
        try:
            if finder is importlib.machinery.PathFinder:
                spec = importlib.machinery.PathFinder.find_spec(name, path)
            else:
                find_spec = getattr(finder, "find_spec", None)
                spec = find_spec(name, None) if find_spec is not None else None
        except (ImportError, ValueError):
            continue
        if spec is not None:
            if spec.origin not in (None, "namespace"):
                return str(spec.origin)
            locations = list(spec.submodule_search_locations or [])
            return f"a namespace package at {', '.join(locations) or 'an unknown place'}"
    return None


def check_name(name: str) -> str:
    """``name`` if it can be the new package's name; else ValueError saying why."""
    if not re.fullmatch(r"[a-z][a-z0-9_]*", name) or keyword.iskeyword(name) or len(name) > 64:
        raise ValueError(
            f"package name {name[:80]!r} is not usable: use lower case letters, digits and _ , starting with a letter"
        )
    where = existing_module(name)
    if where is not None:
        raise ValueError(
            f"package name {name!r} is taken: an importable module {name!r} exists ({where}), and a "
            f"package of that name would hide it or be hidden by it; pick another name, e.g. {name}_scene"
        )
    return name


def write_package(name: str, directory: str | os.PathLike[str] | None = None, *, pixels: bool = False) -> list[str]:
    """Write the package for ``name`` into ``directory`` (default ``./name``);
    returns the paths written. Refuses a non-empty directory; never overwrites.
    ``pixels``: the id observes through the camera (``obs_mode="pixels"``)."""
    check_name(name)
    root = os.path.abspath(os.fspath(directory) if directory is not None else name)
    if os.path.exists(root) and (not os.path.isdir(root) or os.listdir(root)):
        raise FileExistsError(f"{root} exists and is not an empty directory; pick another --dir")
    values = {"name": name, "Camel": camel(name), "obs_mode": "pixels" if pixels else "state"}
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
        written = write_package(args.name, args.dir, pixels=args.pixels)
    except (ValueError, FileExistsError) as exc:
        print(f"new-scene: {exc}", file=sys.stderr)
        return 2
    root = os.path.dirname(written[0])
    env_id = f"{args.name}/{camel(args.name)}-v0"
    print(f"wrote the env package {args.name} ({env_id}) to {root}:")
    for path in written:
        print(f"  {os.path.relpath(path, root)}")
    print("next:")
    clone = remoteenv_source_tree()
    if clone is not None:
        print(f"  pip install {clone}    # remoteenv itself: it is not installed here, only imported from there")
    # The recipe of the package's README and docs/env-package.md: the test extra
    # brings pytest into this environment, and `python -m pytest` runs that one.
    print(f'  pip install -e "{root}[test]"    # this package, editable, and pytest')
    print(f"  cd {root} && python -m pytest")
    print(f"  python -m remoteenv demo {args.name}:{env_id}")
    return 0


def remoteenv_source_tree() -> str | None:
    """The root of the remoteenv clone this process imports remoteenv from, when
    remoteenv is not installed as a distribution (e.g. run through PYTHONPATH);
    None when it is installed (the new package's requirement is then met)."""
    try:
        importlib.metadata.distribution("remoteenv")
        return None
    except importlib.metadata.PackageNotFoundError:
        pass
    import remoteenv

    root = os.path.dirname(os.path.dirname(os.path.abspath(remoteenv.__file__)))
    return root if os.path.isfile(os.path.join(root, "pyproject.toml")) else None
