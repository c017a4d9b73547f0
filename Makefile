# Two commands do everything on a fresh machine: `make demo` and `make test`.
# Each creates .venv/ and installs what is missing (PyPI wheels, incl. ROS 2 Jazzy), registers
# the package in the venv's ament prefix and writes .venv/setup.bash; with ../shared/tools/
# ros2cli/install beside the checkout it also installs the ROS 2 command line (`ros2`), and with
# ../shared/tools/ros2launch/install too `ros2 launch`.
# Every pip install of the setup (the interface build's and ../shared/tools' too) takes the
# exact versions in requirements.lock (PIP_CONSTRAINT); requirements*.txt are the loose
# specification it is made from by `make lock` (see docs/development.md).
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
CORE_STAMP := $(VENV)/.core
LOCK := requirements.lock
LOCK_VENV := build/lock-venv
# LOCKED=0 installs what PyPI serves today within requirements*.txt (used by `make lock`)
export PIP_CONSTRAINT := $(if $(filter 0,$(LOCKED)),,$(abspath $(LOCK)))
IFACE_STAMP := $(VENV)/.interfaces
KERNELS_STAMP := $(VENV)/.kernels
KERNELS := grasp_safety_ros/core/kernels
# a class deriving from NamedTuple (core.kernels._jit selects the same files for the digest)
NAMED_TUPLE := ^class [A-Za-z0-9_]+\(.*NamedTuple
# interface packages: msg_defs/ and the used subsets of ../shared/interfaces/ (control_msgs,
# moveit_msgs; built once per machine and cached, see scripts/build_interfaces.sh)
IFACE_SRC := $(shell find msg_defs ../shared/interfaces -type f 2>/dev/null) \
  scripts/build_interfaces.sh scripts/stage_interfaces.py requirements-interfaces.txt
AMENT_STAMP := $(VENV)/.ament
ROS2CLI_INSTALL := $(wildcard ../shared/tools/ros2cli/install)
ROS2CLI_STAMP := $(if $(ROS2CLI_INSTALL),$(VENV)/.ros2cli)
ROS2LAUNCH_INSTALL := $(wildcard ../shared/tools/ros2launch/install)
ROS2LAUNCH_STAMP := $(if $(and $(ROS2CLI_INSTALL),$(ROS2LAUNCH_INSTALL)),$(VENV)/.ros2launch)
# some machines' pip.conf names local indexes that do not exist: drop pip's warning about them
PIP_QUIET := sed -u -e '/is ignored: it is neither a file nor a directory/d'

.PHONY: all setup demo test bench lint lock clean

all: setup

setup: $(IFACE_STAMP) $(AMENT_STAMP) $(ROS2CLI_STAMP) $(ROS2LAUNCH_STAMP) $(KERNELS_STAMP)

# The core's and the command line's packages (requirements-core.txt, all `make demo` needs)
# and the package; then the rest of requirements.txt. pip lists what it downloads and installs.
# No byte-compiling at install (--no-compile: a third of the install time on this machine;
# Python compiles what it imports, once).
$(CORE_STAMP): requirements-core.txt setup.py $(LOCK)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@echo "installing the core's packages: pip lists each download, then unpacks them all (1.4 GB, a minute or more)"
	set -o pipefail; $(PY) -m pip install --no-compile -r requirements-core.txt 2>&1 | $(PIP_QUIET)
	set -o pipefail; $(PY) -m pip install --no-deps -e . 2>&1 | $(PIP_QUIET)
	touch $@

$(STAMP): $(CORE_STAMP) requirements.txt $(LOCK)
	set -o pipefail; $(PY) -m pip install -r requirements.txt 2>&1 | $(PIP_QUIET)
	touch $@

# Compile the kernels, or load them from numba's cache of the same sources, shared by the
# checkouts of this machine (see core/kernels/_jit.py); a line per kernel compiled.
$(KERNELS_STAMP): $(STAMP) $(wildcard $(KERNELS)/*.py) \
  $(shell grep -rlE --include='*.py' '$(NAMED_TUPLE)' grasp_safety_ros/core)
	$(PY) -c "from grasp_safety_ros.core.method.warm_up import announce_compiles, warm_up; announce_compiles(); print(f'compiled kernels ready ({warm_up():.1f} s)')"
	touch $@

$(IFACE_STAMP): $(STAMP) $(IFACE_SRC)
	bash scripts/build_interfaces.sh
	touch $@

# launch/ and config/ are linked file by file: a new or removed file re-registers
$(AMENT_STAMP): $(STAMP) package.xml resource/grasp_safety_ros scripts/register_ament.sh \
  launch $(wildcard launch/*.py) config $(wildcard config/*)
	bash scripts/register_ament.sh
	touch $@

$(VENV)/.ros2cli: $(STAMP) $(ROS2CLI_INSTALL)
	set -o pipefail; bash $(ROS2CLI_INSTALL) $(VENV) 2>&1 | $(PIP_QUIET)
	touch $@

# ros2 launch (launch, launch_ros, ros2launch): a ros2 verb, so after the ros2 command line
$(VENV)/.ros2launch: $(VENV)/.ros2cli $(ROS2LAUNCH_INSTALL)
	set -o pipefail; bash $(ROS2LAUNCH_INSTALL) $(VENV) 2>&1 | $(PIP_QUIET)
	touch $@

# the demo needs the core's packages only (the rest and the ROS 2 parts install with `make test`)
# and no kernel: its three grasps run on the Pinocchio path (cli/main.py: DEMO_BACKEND)
demo: $(CORE_STAMP)
	$(VENV)/bin/grasp-safety demo --out demo_output

# The checks CI runs, cheapest first: lint (ruff), types (mypy, pyproject.toml), then pytest.
test: setup lint
	$(PY) -m pytest -q test

# Every section (about 3 minutes on 2 cores; bench/run.py's docstring), then the docs' tables
# rendered from bench/results.json (the generated blocks only; make docs also re-captures).
bench: setup
	$(PY) bench/run.py --json bench/results.json
	$(PY) scripts/render_docs.py

# ruff check, ruff format --check, then mypy (its configuration: pyproject.toml)
LINTED := grasp_safety_ros test bench examples launch scripts
lint: $(STAMP)
	$(VENV)/bin/ruff check $(LINTED)
	$(VENV)/bin/ruff format --check $(LINTED)
	$(VENV)/bin/mypy

# Re-resolve requirements*.txt (and the PyPI packages of ../shared/tools' installers) in a
# scratch venv and write every installed version to requirements.lock.
lock:
	rm -rf $(LOCK_VENV)
	$(PYTHON) -m venv $(LOCK_VENV)
	set -o pipefail; PIP_CONSTRAINT= $(LOCK_VENV)/bin/python -m pip install -q \
	  -r requirements.txt -r requirements-interfaces.txt cmake 2>&1 | $(PIP_QUIET)
	$(if $(ROS2CLI_INSTALL),set -o pipefail; PIP_CONSTRAINT= bash $(ROS2CLI_INSTALL) $(LOCK_VENV) 2>&1 | $(PIP_QUIET))
	$(if $(ROS2LAUNCH_INSTALL),set -o pipefail; PIP_CONSTRAINT= bash $(ROS2LAUNCH_INSTALL) $(LOCK_VENV) 2>&1 | $(PIP_QUIET))
	{ echo "# Exact versions of every PyPI package the venv gets; written by \`make lock\` from"; \
	  echo "# requirements*.txt on $$(date -u +%F) (Python $$($(LOCK_VENV)/bin/python -c 'import platform; print(platform.python_version())')). Do not edit by hand."; \
	  $(LOCK_VENV)/bin/python -m pip freeze --all --exclude-editable | grep -v ' @ ' | LC_ALL=C sort -f; \
	} > $(LOCK)
	rm -rf $(LOCK_VENV)

clean:
	rm -rf $(VENV) build install log

# README.md and docs/: re-render the generated blocks (parameters, benchmark tables) and
# re-capture the outputs shown (scripts/render_docs.py; the tests fail while they are stale).
.PHONY: docs
docs: setup
	$(PY) scripts/render_docs.py --capture
