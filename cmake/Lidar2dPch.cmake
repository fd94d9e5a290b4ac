# Precompiled headers (option LIDAR2D_PCH): heavy third-party and standard headers that most
# sources of a target include, compiled once per target (or once for all tests, REUSE_FROM) and
# force-included (-include) into each of its sources. Only headers outside the project are listed:
# a change to a lidar2d header then rebuilds only the sources that include it, as without PCH.
#
# ccache: a compilation that uses a precompiled header is cached only with
# CCACHE_SLOPPINESS=pch_defines,time_macros (ccache cannot see __TIME__ or the #defines inside the
# .gch), so the targets given a PCH run their launcher through `cmake -E env` with that setting when
# the launcher is ccache. CMake's -include names the header by its path in the build tree, which
# CCACHE_BASEDIR makes relative: a warm cache still hits from another clone.

# Headers for every library module with a PCH (and the start of the CLI's and the tests' lists).
set(LIDAR2D_PCH_LIBRARY <Eigen/Core> <fmt/format.h>
  <algorithm> <array> <cmath> <cstddef> <cstdint> <cstring> <filesystem> <fstream> <functional>
  <limits> <memory> <numbers> <optional> <string> <utility> <vector>)

# lidar2d_precompile_headers(target header...): `target` precompiles and force-includes `header...`.
function(lidar2d_precompile_headers target)
  if(NOT LIDAR2D_PCH)
    return()
  endif()
  target_precompile_headers(${target} PRIVATE ${ARGN})
  lidar2d_pch_ccache(${target})
endfunction()

# lidar2d_reuse_precompiled_headers(target from): `target` force-includes the PCH of `from` (whose
# compile flags must be the same as `target`'s).
function(lidar2d_reuse_precompiled_headers target from)
  if(NOT LIDAR2D_PCH)
    return()
  endif()
  target_precompile_headers(${target} REUSE_FROM ${from})
  lidar2d_pch_ccache(${target})
endfunction()

function(lidar2d_pch_ccache target)
  if(CMAKE_CXX_COMPILER_LAUNCHER MATCHES "ccache")
    set_target_properties(${target} PROPERTIES CXX_COMPILER_LAUNCHER
      "${CMAKE_COMMAND};-E;env;CCACHE_SLOPPINESS=pch_defines,time_macros;${CMAKE_CXX_COMPILER_LAUNCHER}")
  endif()
endfunction()
