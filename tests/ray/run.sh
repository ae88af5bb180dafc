#!/usr/bin/env bash
# Ray and RLlib tests: tests/ray in a virtualenv of their own, inside a private
# network namespace.
#
# - The venv (default .venv-ray, or $RAY_VENV) is made on first use: ray[rllib]
#   2.60 pins Gymnasium 1.2.2, so it cannot share the main test venv. torch is
#   installed first and pinned (anything looser pulls GBs of CUDA packages),
#   then Ray, then remoteenv's own dependencies (read from pyproject.toml);
#   remoteenv itself comes from this tree through PYTHONPATH, which the Ray
#   nodes and the sims inherit.
# - The namespace (`unshare -n`, needs root) has only loopback up, so the head,
#   the worker nodes and the driver all advertise 127.0.0.1 and no test traffic
#   leaves the machine. Packages are installed before entering it.
#
# Usage: tests/ray/run.sh [pytest arguments]      e.g. tests/ray/run.sh -k spread
#        tests/ray/run.sh --setup                  make the venv (if needed) and stop
#                                                  (make test runs it beside the main venv's build)
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/../.." && pwd)
VENV=${RAY_VENV:-$ROOT/.venv-ray}
STAMP=$VENV/.deps

if [ ! -f "$STAMP" ] || [ "$ROOT/pyproject.toml" -nt "$STAMP" ] || [ "$0" -nt "$STAMP" ]; then
    echo "tests/ray: setting up $VENV" >&2
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -qq torch==2.13.0
    "$VENV/bin/pip" install -qq "ray[default,rllib]>=2.60.0,<3"
    # remoteenv's runtime and test dependencies, as pyproject.toml lists them.
    mapfile -t DEPS < <(python3 - "$ROOT/pyproject.toml" <<'EOF'
import sys, tomllib
project = tomllib.load(open(sys.argv[1], "rb"))["project"]
extras = project["optional-dependencies"]
for req in project["dependencies"] + extras["test"]:
    print(req)
EOF
)
    "$VENV/bin/pip" install -qq "${DEPS[@]}"
    touch "$STAMP"
fi
if [ "${1:-}" = "--setup" ]; then
    exit 0
fi

if ! unshare -n true 2>/dev/null; then
    echo "tests/ray: cannot create a network namespace (unshare -n needs root); the Ray tests" \
         "must not run on the machine's real interfaces" >&2
    exit 1
fi

cd "$ROOT"
export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}"
export MUJOCO_GL=${MUJOCO_GL:-egl}
export RAY_USAGE_STATS_ENABLED=0
# Without Ray in this venv the suite fails (tests/ray/conftest.py) instead of collecting nothing.
export REMOTEENV_RAY_SUITE=1
# Ray's cluster utility leaves a multiprocessing listener socket in the temp
# dir when its nodes stop; the tests get a temp dir of their own, removed at the end.
TEST_TMP=$(mktemp -d "${TMPDIR:-/tmp}/rt-XXXXXX")
trap 'rm -rf "$TEST_TMP"' EXIT
export TMPDIR=$TEST_TMP
unshare -n bash -c 'ip link set lo up && exec "$0" -m pytest tests/ray "$@"' "$VENV/bin/python" "$@"
