# Set-up and run targets. Each creates $(VENV) on first use and installs
# remoteenv into it (non-editable, as a user would) before running.
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip
PYTHON3 ?= python3
export MUJOCO_GL ?= egl

.PHONY: demo test test-ray ray-venv lint bench install deps clean

$(VENV)/.deps: pyproject.toml Makefile
	$(PYTHON3) -m venv $(VENV)
	# torch first and pinned: a looser requirement pulls GBs of CUDA packages.
	$(PIP) install --quiet torch==2.13.0
	$(PIP) install --quiet ".[test,lint,torch,torchrl,sb3,video]"
	touch $@

deps: $(VENV)/.deps

install: deps
	# setuptools builds in the tree and copies all of build/lib into the wheel: a module
	# deleted from the tree would stay importable in the venv. Build from scratch.
	rm -rf build
	$(PIP) install --quiet --no-deps --force-reinstall .

demo: install
	$(PY) -m remoteenv demo cartpole --continuous --episodes 3
	$(PY) -m remoteenv demo reacher --episodes 3
	$(PY) -m remoteenv demo hexapod --episodes 1

# The unit, integration and Ray suites all run even when one fails; the target
# fails if any did, naming which. The unit and integration tests run TEST_WORKERS at a
# time (pytest-xdist), then the timing-sensitive ones (marked serial in
# tests/conftest.py) alone.
PYTEST ?= $(VENV)/bin/pytest
RAY_SUITE ?= tests/ray/run.sh
TEST_WORKERS ?= 2
# What make test sets up first, two at a time: the main venv, lint and install
# beside the Ray suite's venv (pip and the linters use one core each).
TEST_SETUP ?= install lint ray-venv

test:
	@$(if $(strip $(TEST_SETUP)),$(MAKE) --no-print-directory -j2 --output-sync=target $(TEST_SETUP))
	@failed=""; integration=""; \
	$(PYTEST) -n $(TEST_WORKERS) tests/unit || failed="$$failed unit"; \
	$(PYTEST) -n $(TEST_WORKERS) -m "not serial" tests/integration || integration=failed; \
	$(PYTEST) -m serial tests/integration || integration=failed; \
	if [ -n "$$integration" ]; then failed="$$failed integration"; fi; \
	$(RAY_SUITE) || failed="$$failed ray"; \
	if [ -n "$$failed" ]; then echo "make test: these suites failed:$$failed" >&2; exit 1; fi; \
	echo "make test: the unit, integration and ray suites passed"

# Ray and RLlib tests alone: a venv of their own (.venv-ray), a private network namespace.
test-ray:
	tests/ray/run.sh

# The Ray suite's venv alone (made on first use, kept while pyproject.toml is older).
ray-venv:
	$(RAY_SUITE) --setup

# Lint, format, types and the layer contracts of the source tree (no processes started).
lint: deps
	$(VENV)/bin/ruff check remoteenv scenes tests examples
	$(VENV)/bin/ruff format --check remoteenv scenes tests examples
	$(VENV)/bin/mypy
	PYTHONPATH=$(CURDIR) $(VENV)/bin/lint-imports

bench: install
	$(PY) -m remoteenv bench

clean:
	rm -rf $(VENV) .venv-ray build dist *.egg-info
