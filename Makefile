# Two commands do everything on a fresh machine: `make demo` and `make test`.
# Each creates .venv/ and installs what is missing (PyPI wheels, incl. ROS 2 Jazzy), registers
# the package in the venv's ament prefix and writes .venv/setup.bash; with ../shared/tools/
# ros2cli/install beside the checkout it also installs the ROS 2 command line (`ros2`).
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
IFACE_STAMP := $(VENV)/.interfaces
KERNELS_STAMP := $(VENV)/.kernels
KERNELS := grasp_safety_ros/core/kernels
IFACE_SRC := $(shell find msg_defs -type f 2>/dev/null) scripts/build_interfaces.sh
AMENT_STAMP := $(VENV)/.ament
ROS2CLI_INSTALL := $(wildcard ../shared/tools/ros2cli/install)
ROS2CLI_STAMP := $(if $(ROS2CLI_INSTALL),$(VENV)/.ros2cli)
# some machines' pip.conf names local indexes that do not exist: drop pip's warning about them
PIP_QUIET := sed -e '/is ignored: it is neither a file nor a directory/d'

.PHONY: all setup demo test bench lint clean

all: setup

setup: $(IFACE_STAMP) $(AMENT_STAMP) $(ROS2CLI_STAMP) $(KERNELS_STAMP)

$(STAMP): requirements.txt setup.py
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	set -o pipefail; $(PY) -m pip install -q -r requirements.txt 2>&1 | $(PIP_QUIET)
	set -o pipefail; $(PY) -m pip install -q --no-deps -e . 2>&1 | $(PIP_QUIET)
	touch $@

# numba's cache goes stale across kernel files (see core/kernels/__init__.py): recompile here.
$(KERNELS_STAMP): $(STAMP) $(wildcard $(KERNELS)/*.py)
	rm -f $(KERNELS)/__pycache__/*.nbi $(KERNELS)/__pycache__/*.nbc
	$(PY) -c "from grasp_safety_ros.core.method.warm_up import warm_up; print(f'compiled kernels ready ({warm_up():.1f} s)')"
	touch $@

$(IFACE_STAMP): $(STAMP) $(IFACE_SRC)
	bash scripts/build_interfaces.sh
	touch $@

$(AMENT_STAMP): $(STAMP) package.xml resource/grasp_safety_ros scripts/register_ament.sh
	bash scripts/register_ament.sh
	touch $@

$(VENV)/.ros2cli: $(STAMP) $(ROS2CLI_INSTALL)
	set -o pipefail; bash $(ROS2CLI_INSTALL) $(VENV) 2>&1 | $(PIP_QUIET)
	touch $@

demo: setup
	$(VENV)/bin/grasp-safety demo --out demo_output

test: setup
	$(PY) -m pytest -q test

bench: setup
	$(PY) bench/run.py --json bench/results.json

lint: $(STAMP)
	$(VENV)/bin/ruff check grasp_safety_ros test bench examples launch

clean:
	rm -rf $(VENV) build install log

# README.md and docs/: re-render the generated blocks (parameters, benchmark tables) and
# re-capture the outputs shown (scripts/render_docs.py; the tests fail while they are stale).
.PHONY: docs
docs: setup
	$(PY) scripts/render_docs.py --capture
