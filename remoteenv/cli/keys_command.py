"""``python -m remoteenv keys DIR``: generate CURVE key pairs for remote binding. Runs in the agent process (the command's own)."""

from __future__ import annotations

import argparse
import os
from typing import Any

from remoteenv.wire.files import keys


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "keys",
        help="generate a CURVE key pair (for binding sims beyond loopback)",
        description="Generate a ZeroMQ CURVE key pair and save it as NAME.key (public, "
        "Z85 text) and NAME.key_secret (mode 0600) in DIR. A sim bound beyond "
        "loopback needs a server pair; each agent allowed to drive it needs a "
        "client pair whose public key the sim lists. Existing files are never "
        "overwritten.",
    )
    p.add_argument("directory", help="where to write the key files (created if missing)")
    p.add_argument(
        "--name",
        action="append",
        default=None,
        help="base name of a key pair; repeat for several (default: server and client)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    names = args.name or ["server", "client"]
    for name in names:
        try:
            public_path, secret_path = keys.save_keypair(args.directory, name)
        except FileExistsError as exc:
            raise SystemExit(f"not overwriting {exc.filename}; choose another --name or directory") from None
        print(
            f"{name}: public key {public_path}  secret key {secret_path} (mode "
            f"{oct(os.stat(secret_path).st_mode & 0o777)})"
        )
    return 0
