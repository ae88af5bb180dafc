"""``python -m remoteenv``: see :mod:`remoteenv.cli`. Runs in the agent process (the command's own)."""

import sys

from remoteenv.cli import main

if __name__ == "__main__":
    sys.exit(main())
