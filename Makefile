# The README's two commands: `make campaign` and `make test`.
# Everything lives in .venv, built from the system Python (>= 3.11); re-running is fast
# because installation is redone only when a package's setup.py/package.xml or the pins change.

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
export ROS_WHEELS_EXIST := import platform, sys; sys.exit(0 if platform.system() == "Linux" and platform.machine() == "x86_64" and (3, 10) <= sys.version_info[:2] <= (3, 13) else 1)
export PLATFORM := import platform, sys; print(platform.machine(), "Python", platform.python_version())
STAMP  := $(VENV)/.installed
INTERFACES := $(VENV)/.interfaces
IFACE_DIR := src/aero_rig_interfaces
IFACE_FILES := $(wildcard $(IFACE_DIR)/msg/*.msg $(IFACE_DIR)/srv/*.srv) $(IFACE_DIR)/CMakeLists.txt \
  $(IFACE_DIR)/package.xml $(IFACE_DIR)/build_in_venv.sh $(IFACE_DIR)/requirements-build.txt \
  $(IFACE_DIR)/cmake/wheel_include_dirs.cmake
PACKAGES := rig_runtime rig_testing multisine_gen pitch_actuator pressure_scanner wing_sim aero_identification aero_rig
PKG_FILES := $(foreach p,$(PACKAGES),src/$(p)/setup.py src/$(p)/package.xml)

.PHONY: test test-fast campaign lint format typecheck bench venv clean

venv: $(INTERFACES)

$(BIN)/python:
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' || \
	  { echo "error: $(PYTHON) is older than 3.11; set PYTHON=python3.11 (or newer)"; exit 1; }
	@$(PYTHON) -m venv $(VENV) || { rm -rf $(VENV); \
	  echo "error: '$(PYTHON) -m venv' failed. On Debian/Ubuntu install the venv module:"; \
	  echo "       sudo apt install python3-venv   (or python3.11-venv for that interpreter)"; exit 1; }
	@test -x $(BIN)/pip || { rm -rf $(VENV); \
	  echo "error: the venv has no pip (ensurepip missing): sudo apt install python3-venv"; exit 1; }

# rclpy: a sourced ROS 2 Jazzy's if there is one, else the PyPI wheels where they exist
# (CPython 3.10-3.13 on x86_64 Linux), else none: then only the offline verbs work (one line
# says so, and how to get rclpy).
$(STAMP): $(BIN)/python $(PKG_FILES) requirements-dev.txt requirements-ros.txt constraints.txt
	$(BIN)/pip install --quiet --upgrade pip setuptools wheel
	$(BIN)/pip install --quiet -c constraints.txt -r requirements-dev.txt \
	  $(foreach p,$(PACKAGES),-e src/$(p))
	@if [ -n "$$ROS_DISTRO" ] && $(BIN)/python -c 'import rclpy' 2>/dev/null; then \
	  echo "rclpy: using the sourced ROS 2 $$ROS_DISTRO"; \
	elif $(BIN)/python -c "$$ROS_WHEELS_EXIST"; then \
	  $(BIN)/pip install --quiet -c constraints.txt -r requirements-ros.txt && \
	  echo "rclpy: installed from PyPI (ros-jazzy-rclpy, Fast DDS)"; \
	else \
	  echo "rclpy: no PyPI wheels for this platform ($$($(BIN)/python -c "$$PLATFORM")) and no sourced ROS 2 Jazzy: source a ROS 2 Jazzy install or use RoboStack's conda packages for the node graph; aero-rig fit, view BAG and bag work without it"; \
	fi
	@touch $(STAMP)

# The rig's messages and control service (src/aero_rig_interfaces, ament_cmake + rosidl), built
# into the venv with the rosidl generators from PyPI when rclpy is there (a sourced ROS 2 Jazzy's
# or the wheels). Needs cmake and a C/C++ compiler; without them one line says what is missing.
# On a ROS machine, colcon builds the package like any interface package.
$(INTERFACES): $(STAMP) $(IFACE_FILES)
	@if $(BIN)/python -c 'import rclpy' 2>/dev/null; then \
	  PIP_CONSTRAINT=$(CURDIR)/constraints.txt $(IFACE_DIR)/build_in_venv.sh $(VENV) || exit 1; \
	else echo "aero_rig_interfaces: no rclpy, not built (the offline verbs read the .msg files)"; fi
	@touch $(INTERFACES)

# The real ros2 tools for the tests (ros2cli, launch_ros, ... from ../shared/ros2-python, with
# composition_interfaces built for launch_ros). Absent or failing: those tests skip, saying why.
ROS2_PYTHON ?= ../shared/ros2-python
ROS2_TOOLS := $(VENV)/.ros2-tools
$(ROS2_TOOLS): $(INTERFACES)
	@if [ -d "$(ROS2_PYTHON)" ] && $(BIN)/python -c 'import rclpy' 2>/dev/null; then \
	  $(ROS2_PYTHON)/install.sh $(VENV) && \
	  ($(BIN)/python -c "import composition_interfaces.srv" 2>/dev/null || \
	   PIP_CONSTRAINT=$(CURDIR)/constraints.txt $(IFACE_DIR)/build_in_venv.sh $(VENV) \
	     $(ROS2_PYTHON)/composition_interfaces || \
	   echo "ros2 launch: composition_interfaces did not build; the launch tests will skip"); \
	else echo "ros2 tools: $(ROS2_PYTHON) or rclpy missing; the ros2 CLI tests will skip"; fi
	@touch $(ROS2_TOOLS)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

typecheck: $(STAMP)
	$(BIN)/mypy

# The full suite: lint, types, every test (graph tests and campaigns included), on rclpy.
# CI (.ci/run) runs it once; it prints its slowest tests.
test: lint typecheck $(ROS2_TOOLS)
	$(BIN)/pytest --durations=25

# Unit tests only (no node graph, no campaign, no build): under a minute.
test-fast: $(INTERFACES)
	$(BIN)/pytest -m "not slow"

campaign: $(INTERFACES)
	$(BIN)/aero-rig campaign --plan default $(CAMPAIGN_ARGS)

bench: $(INTERFACES)
	@for b in bench/*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) build install log .pytest_cache .ruff_cache
