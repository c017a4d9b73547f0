# Two commands do everything on a fresh machine: `make demo` and `make test`.
# Each creates .venv/ and installs what is missing (PyPI wheels, incl. ROS 2 Jazzy).
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
IFACE_STAMP := $(VENV)/.interfaces
KERNELS_STAMP := $(VENV)/.kernels
KERNELS := grasp_safety_ros/core/kernels
IFACE_SRC := $(shell find msg_defs -type f 2>/dev/null) scripts/build_interfaces.sh

.PHONY: all setup demo test bench lint clean

all: setup

setup: $(IFACE_STAMP) $(KERNELS_STAMP)

$(STAMP): requirements.txt setup.py
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q -r requirements.txt
	$(PY) -m pip install -q --no-deps -e .
	touch $@

# numba's cache goes stale across kernel files (see core/kernels/__init__.py): recompile here.
$(KERNELS_STAMP): $(STAMP) $(wildcard $(KERNELS)/*.py)
	rm -f $(KERNELS)/__pycache__/*.nbi $(KERNELS)/__pycache__/*.nbc
	$(PY) -c "from grasp_safety_ros.core.method.warm_up import warm_up; print(f'compiled kernels ready ({warm_up():.1f} s)')"
	touch $@

$(IFACE_STAMP): $(STAMP) $(IFACE_SRC)
	bash scripts/build_interfaces.sh
	touch $@

demo: setup
	$(VENV)/bin/grasp-safety demo --out demo_output

test: setup
	$(PY) -m pytest -q test

bench: setup
	$(PY) bench/run.py --json bench/results.json

lint: $(STAMP)
	$(VENV)/bin/ruff check grasp_safety_ros test bench examples

clean:
	rm -rf $(VENV) build install log
