# Included before the project when the package is built against the ROS 2 wheels from PyPI
# (-DCMAKE_PROJECT_INCLUDE=..., see build_in_venv.sh); a sourced ROS 2 or colcon never uses it.
#
# The message wheels' CMake targets <pkg>::<pkg>__rosidl_generator_py name the Python and NumPy
# include folders of the machine that built the wheels (/opt/python/cpXY-cpXY/...). CMake
# refuses an imported target whose include folder does not exist when it generates the build.
# At the end of the configure step, every such folder that does not exist here is replaced by
# this interpreter's (FindPython3's Python3_INCLUDE_DIRS and Python3_NumPy_INCLUDE_DIRS).
cmake_minimum_required(VERSION 3.21)  # cmake_language(DEFER), IMPORTED_TARGETS

function(aero_rig_fix_wheel_include_dirs)
  find_package(Python3 REQUIRED COMPONENTS Interpreter Development NumPy)
  get_directory_property(targets DIRECTORY "${CMAKE_SOURCE_DIR}" IMPORTED_TARGETS)
  set(fixed 0)
  foreach(target IN LISTS targets)
    get_target_property(dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT dirs)
      continue()
    endif()
    set(new_dirs "")
    set(changed FALSE)
    foreach(dir IN LISTS dirs)
      if(NOT dir MATCHES "^\\$<" AND NOT EXISTS "${dir}")
        if(dir MATCHES "numpy/_?core/include$")
          set(dir "${Python3_NumPy_INCLUDE_DIRS}")
          set(changed TRUE)
        elseif(dir MATCHES "/include/python3\\.[0-9]+$")
          set(dir "${Python3_INCLUDE_DIRS}")
          set(changed TRUE)
        endif()
      endif()
      list(APPEND new_dirs "${dir}")
    endforeach()
    if(changed)
      set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${new_dirs}")
      math(EXPR fixed "${fixed} + 1")
    endif()
  endforeach()
  message(STATUS "aero_rig_interfaces: ${fixed} wheel target(s) pointed at this Python's include folders")
endfunction()

cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL aero_rig_fix_wheel_include_dirs)
