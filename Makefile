# rsart: `make demo` and `make test` each do the whole set-up on a fresh Debian machine
# (system libraries via apt where missing, .venv with the pinned stack), then run.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.rsart-installed
APT_PKGS := libusb-1.0-0 libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 libosmesa6
# Headless browser for the leaderboard site tests (Debian's; no browser is downloaded at run time).
TEST_APT_PKGS := chromium chromium-driver
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# Headless GL for pyrender and MuJoCo (same platform for both); rsart falls back to osmesa.
export PYOPENGL_PLATFORM ?= egl
export MUJOCO_GL ?= $(PYOPENGL_PLATFORM)
DEMO_OUT ?= demo_out
PYTEST_ARGS ?=
# test files spread over this many processes (pytest-xdist; a file's tests stay in one process, as they share
# module fixtures). Measured 2026-11-28 on 2 cores: 31 min in one process, before `pd2gs run` loaded cached
# kernels; 18 min in two, after
TEST_WORKERS ?= 2

.PHONY: setup sysdeps testdeps aptinstall demo test test-core bench clean

setup: sysdeps $(STAMP)

sysdeps:
	@$(MAKE) --no-print-directory aptinstall PKGS="$(APT_PKGS)"

testdeps:
	@$(MAKE) --no-print-directory aptinstall PKGS="$(TEST_APT_PKGS)"

aptinstall:
	@missing=""; for p in $(PKGS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then echo "installing system libraries:$$missing"; \
	  $(SUDO) apt-get update -q && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -q $$missing; fi

# The full environment, = pip install 'rsart[all]' pinned by requirements.lock (every extra). ray (the [ray]
# extra) is in it so the Ray runner tests (tests/pd2gs/test_object_runner.py) run; `make test` sets
# RSART_REQUIRE_RAY=1, which fails them instead of skipping when ray is missing.
$(STAMP): pyproject.toml requirements.lock
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check -r requirements.lock
	$(PY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $(STAMP)

demo: setup
	$(PY) -m pd2gs.demo --out $(DEMO_OUT)

test: setup testdeps
	RSART_REQUIRE_RAY=1 $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile $(PYTEST_ARGS)

# The core install alone (pip install rsart, no extras) in a fresh temporary venv, then the `core` tests.
test-core:
	PYTHON=$(PYTHON) .ci/core

bench: setup
	for b in benchmarks/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) $(DEMO_OUT) .pytest_cache
