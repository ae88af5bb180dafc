"""The zygote's script: ``python start.py --agent-pid P --control-fd F [--scene S ...]``.

Run by path (not ``-m``), so that no working directory is put on
``sys.path``; the folder of this file is taken off it at once: the zygote
finds modules as a scene script does, without the scene's folder (which a
forked sim puts first, see :mod:`remoteenv.sim.process.zygote.child`).
"""

import sys

if __name__ == "__main__":
    del sys.path[0]
    from remoteenv.sim.process.zygote.server import main

    sys.exit(main(sys.argv[1:]))
