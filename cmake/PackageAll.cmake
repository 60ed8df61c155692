# The `package` preset (MIRRORCAL_PACKAGE_ALL): instead of the project, two builds of the board's
# program, statically linked so that one package serves Debian 12, Ubuntu, Raspberry Pi OS and
# Jetson Linux alike (MIRRORCAL_HOST_TOOLS off, as on the board: record, calibrate, run, export),
# each packaged by deploy/Package.cmake into this build's folder (build/package):
#   mirrorcal_<version>_amd64.deb  (the host's clang)
#   mirrorcal_<version>_arm64.deb  (Debian's aarch64 cross GCC and toolchain/setup-cross's sysroot)
# One after the other: each fills both cores. The marker counts and IMU models are the project's
# defaults unless given (-DMIRRORCAL_MARKERS=..., -DMIRRORCAL_IMU_MODELS=...).
include(ExternalProject)
set(common -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX=/usr
    -DMIRRORCAL_STATIC_PROGRAM=ON -DMIRRORCAL_HOST_TOOLS=OFF -DMIRRORCAL_BUILD_TESTS=OFF
    -DMIRRORCAL_PACKAGE_DIR=${PROJECT_BINARY_DIR})
foreach(var MIRRORCAL_MARKERS MIRRORCAL_IMU_MODELS)
  if(DEFINED ${var})
    list(APPEND common "-D${var}:STRING=${${var}}")
  endif()
endforeach()
execute_process(COMMAND ${PROJECT_SOURCE_DIR}/toolchain/setup-cross aarch64
                        ${PROJECT_SOURCE_DIR}/build/sysroot/aarch64
                OUTPUT_VARIABLE arm64_sysroot OUTPUT_STRIP_TRAILING_WHITESPACE
                RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "toolchain/setup-cross aarch64 failed (${rc}): the arm64 package needs it")
endif()

set(previous "")
foreach(arch amd64 arm64)
  set(args ${common})
  if(arch STREQUAL "arm64")
    list(APPEND args --toolchain ${PROJECT_SOURCE_DIR}/toolchain/aarch64.cmake
         -DMIRRORCAL_SYSROOT=${arm64_sysroot})
  else()
    list(APPEND args -DCMAKE_CXX_COMPILER=${CMAKE_CXX_COMPILER})
  endif()
  set(build ${PROJECT_BINARY_DIR}/${arch})
  ExternalProject_Add(mirrorcal_${arch}
    SOURCE_DIR ${PROJECT_SOURCE_DIR}
    BINARY_DIR ${build}
    CONFIGURE_COMMAND ${CMAKE_COMMAND} -S ${PROJECT_SOURCE_DIR} -B ${build} ${args}
    BUILD_COMMAND ${CMAKE_COMMAND} --build ${build} -j2 --target mirrorcal
    INSTALL_COMMAND ${CMAKE_CPACK_COMMAND} --config ${build}/CPackConfig.cmake
    BUILD_ALWAYS ON
    USES_TERMINAL_CONFIGURE ON USES_TERMINAL_BUILD ON USES_TERMINAL_INSTALL ON
    DEPENDS ${previous})
  set(previous mirrorcal_${arch})
endforeach()
