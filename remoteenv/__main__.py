"""``python -m remoteenv``: see :mod:`remoteenv.cli`."""

import sys

from remoteenv.cli import main

if __name__ == "__main__":
    sys.exit(main())
