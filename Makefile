# kinemaforge_opt — set-up, tests, demo, benchmarks.  Every target builds .venv from nothing
# (idempotent: re-runs only redo what changed).
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# No pip cache: the wheels (drake, open3d, mujoco: ~1 GB) would otherwise be kept twice on disk, and a
# CI machine once ran out of space installing them (`[Errno 28] No space left on device`).
export PIP_NO_CACHE_DIR := 1
STAMP := $(VENV)/.kinemaforge-installed
# Debian packages the project needs at run time (open3d: libGL/EGL/X11 and libusb; OpenMP: libgomp;
# MuJoCo headless rendering: EGL) and at build time (the native bridge: g++).
SYSTEM_PACKAGES := g++ libgl1 libegl1 libgomp1 libx11-6 libusb-1.0-0
NATIVE_SOURCES := $(wildcard kinemaforge_opt/native/*.cpp kinemaforge_opt/native/*.hpp)

.PHONY: demo test test-all bench sysdeps clean

demo: $(STAMP)
	$(VENV)/bin/kinemaforge demo -o out/demo

# The suite runs in parallel (pytest-xdist), one process per CPU this shell may use, at most 4
# (memory: each imports Drake, open3d and MuJoCo): 10 -> 7 minutes on a 2-core machine (docs/NOTES.md).
TEST_WORKERS ?= $(shell n=$$(nproc 2>/dev/null || echo 1); echo $$(( n < 4 ? n : 4 )))
TEST_ARGS := -q -n $(TEST_WORKERS)

test: $(STAMP)
	$(PY) -m pytest $(TEST_ARGS) -m "not slow"

test-all: $(STAMP)
	$(PY) -m pytest $(TEST_ARGS)

bench: $(STAMP)
	$(VENV)/bin/kinemaforge bench -o bench_results

# Installs missing Debian packages only (apt-get update runs only when something is missing);
# waits up to 10 min for another apt/dpkg (e.g. a second checkout's make) to release its lock.
sysdeps:
	@missing=$$(for p in $(SYSTEM_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "installing system packages: $$missing"; \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get -o DPkg::Lock::Timeout=600 update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get -o DPkg::Lock::Timeout=600 install -y -qq $$missing; \
	fi

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip "setuptools>=77" wheel

# The native bridge compiles against the exact casadi/libpinocchio installed in .venv
# (no build isolation), so build and runtime versions are the same files.
$(STAMP): $(VENV)/bin/python pyproject.toml setup.py $(NATIVE_SOURCES) | sysdeps
	$(PY) -m pip install -q "casadi==3.8.2" "libpinocchio==4.1.0"
	$(PY) -m pip install -q --no-build-isolation -e ".[dev]"
	touch $(STAMP)

clean:
	rm -rf $(VENV) build *.egg-info kinemaforge_opt/native/_kfbridge*.so out
