# Kernel-in-the-loop tests: a statically linked test program boots with Debian's kernel under
# qemu (toolchain/kernel/run-in-qemu) and exercises a real kernel driver (vcan, i2c-stub, vivid,
# the PL061 GPIO of the arm64 virt machine). The kernel packages are fetched at test time into
# MIRRORCAL_KERNEL_CACHE (build tree, never committed) by fixture tests, one per architecture.
#
#   mirrorcal_guest_program(NAME SOURCES src... [ARCH amd64|arm64] [LIBRARIES lib...]
#                           [ARM64_PACKAGES deb...] [ARM64_LIBS -lfoo...])
#     amd64 (default): a normal executable target NAME, linked statically with LIBRARIES (targets).
#     arm64: cross-compiled with aarch64-linux-gnu-g++ at test time (a fixture test builds it, so
#     the build itself never downloads); SOURCES are compiled together, with the include
#     directories of estimator/, hal/ and drivers/ and Eigen; ARM64_PACKAGES (e.g. libgpiod-dev
#     libgpiod2) are unpacked into an arm64 sysroot in the cache for headers and static libraries.
#
#   mirrorcal_kernel_test(NAME (PROGRAM guest | SCRIPT file [ARCH amd64|arm64]) [ARGS arg...]
#                         [MODULES "name [param=value ...]"...] [SETUP "shell command"...]
#                         [HOST_TOOLS /usr/bin/cansend ...] [FILES file...] [MONITOR] [TIMEOUT s]
#                         [ICOUNT shift])
#     A CTest test labelled `kernel` running PROGRAM ARGS in the guest after loading MODULES (their
#     dependencies first) and running SETUP; its exit status is the test's. See run-in-qemu.
#     SCRIPT runs a busybox shell script instead (e.g. to start a peer beside a host tool such as
#     the mirrorcal program, which HOST_TOOLS copies in with its shared libraries; amd64 only).
#     ICOUNT gives the guest a clock of its own instructions (run-in-qemu --icount), for tests
#     that play sensors in real time: the host's load then cannot stall the guest's time.
#
# Not available in the sanitizer build (static linking and ASan do not mix): there the functions
# do nothing and MIRRORCAL_KERNEL_TESTS is OFF.
include_guard(GLOBAL)

set(MIRRORCAL_KERNEL_CACHE "${CMAKE_BINARY_DIR}/kernel-cache"
    CACHE PATH "Where kernel-in-the-loop tests keep Debian's kernel packages")
set(_mirrorcal_run_in_qemu "${PROJECT_SOURCE_DIR}/toolchain/kernel/run-in-qemu")
set(_mirrorcal_fetch "${PROJECT_SOURCE_DIR}/toolchain/kernel/fetch")

if(MIRRORCAL_SANITIZE)
  set(MIRRORCAL_KERNEL_TESTS OFF)
else()
  set(MIRRORCAL_KERNEL_TESTS ON)
endif()

# One fixture per architecture fetches the kernel, whichever directory's test asks first.
function(_mirrorcal_kernel_fixture arch)
  get_property(done GLOBAL PROPERTY MIRRORCAL_KERNEL_FIXTURE_${arch})
  if(done)
    return()
  endif()
  set_property(GLOBAL PROPERTY MIRRORCAL_KERNEL_FIXTURE_${arch} TRUE)
  add_test(NAME kernel_fetch_${arch} COMMAND ${_mirrorcal_fetch} ${arch} ${MIRRORCAL_KERNEL_CACHE})
  set_tests_properties(kernel_fetch_${arch} PROPERTIES LABELS kernel FIXTURES_SETUP
                       kernel_${arch} TIMEOUT 900)
endfunction()

function(mirrorcal_guest_program name)
  if(NOT MIRRORCAL_KERNEL_TESTS)
    return()
  endif()
  cmake_parse_arguments(PARSE_ARGV 1 G "" "ARCH" "SOURCES;LIBRARIES;ARM64_PACKAGES;ARM64_LIBS")
  if(NOT G_ARCH)
    set(G_ARCH amd64)
  endif()
  if(G_ARCH STREQUAL "amd64")
    add_executable(${name} ${G_SOURCES})
    target_link_libraries(${name} PRIVATE ${G_LIBRARIES} mirrorcal_warnings)
    target_link_options(${name} PRIVATE -static)
    set_target_properties(${name} PROPERTIES MIRRORCAL_GUEST_FILE "$<TARGET_FILE:${name}>"
                                             MIRRORCAL_GUEST_ARCH amd64)
  elseif(G_ARCH STREQUAL "arm64")
    find_program(MIRRORCAL_AARCH64_CXX aarch64-linux-gnu-g++)
    if(NOT MIRRORCAL_AARCH64_CXX)
      set(MIRRORCAL_AARCH64_CXX aarch64-linux-gnu-g++)  # the test reports it missing
    endif()
    set(sysroot "${MIRRORCAL_KERNEL_CACHE}/arm64/root")
    # In a folder of its own: the custom target of the same name is a path of its own to Ninja.
    set(out "${CMAKE_CURRENT_BINARY_DIR}/arm64/${name}")
    set(sources "")
    foreach(s IN LISTS G_SOURCES)
      get_filename_component(abs "${s}" ABSOLUTE)
      list(APPEND sources "${abs}")
    endforeach()
    get_target_property(eigen_dirs Eigen3::Eigen INTERFACE_INCLUDE_DIRECTORIES)
    set(includes "")
    foreach(d ${PROJECT_SOURCE_DIR}/estimator/include ${PROJECT_SOURCE_DIR}/hal/include
            ${PROJECT_SOURCE_DIR}/drivers/include ${CMAKE_CURRENT_SOURCE_DIR})
      list(APPEND includes "-I${d}")
    endforeach()
    foreach(d ${eigen_dirs} ${sysroot}/usr/include)
      list(APPEND includes "-isystem" "${d}")
    endforeach()
    add_custom_command(
      OUTPUT ${out}
      COMMAND ${_mirrorcal_fetch} arm64 ${MIRRORCAL_KERNEL_CACHE} ${G_ARM64_PACKAGES}
      COMMAND ${MIRRORCAL_AARCH64_CXX} -std=c++17 -O2 -Wall -Wextra -Wpedantic -Werror -static
              ${includes} ${sources} -L${sysroot}/usr/lib/aarch64-linux-gnu ${G_ARM64_LIBS} -o ${out}
      DEPENDS ${sources}
      COMMENT "Cross-compiling the arm64 guest program ${name}"
      VERBATIM)
    add_custom_target(${name} DEPENDS ${out})
    set_target_properties(${name} PROPERTIES EXCLUDE_FROM_ALL TRUE MIRRORCAL_GUEST_FILE "${out}"
                                             MIRRORCAL_GUEST_ARCH arm64)
    # Built at test time: its first command fetches the sysroot (nothing to fetch once cached).
    add_test(NAME kernel_build_${name}
             COMMAND ${CMAKE_COMMAND} --build ${CMAKE_BINARY_DIR} --target ${name})
    set_tests_properties(kernel_build_${name} PROPERTIES LABELS kernel FIXTURES_SETUP
                         guest_${name} TIMEOUT 900)
  else()
    message(FATAL_ERROR "mirrorcal_guest_program(${name}): ARCH must be amd64 or arm64")
  endif()
endfunction()

function(mirrorcal_kernel_test)
  if(NOT MIRRORCAL_KERNEL_TESTS)
    return()
  endif()
  cmake_parse_arguments(PARSE_ARGV 0 K "MONITOR" "NAME;PROGRAM;SCRIPT;ARCH;TIMEOUT;ICOUNT"
                        "ARGS;MODULES;SETUP;HOST_TOOLS;FILES")
  if(NOT K_NAME OR (NOT K_PROGRAM AND NOT K_SCRIPT))
    message(FATAL_ERROR "mirrorcal_kernel_test: NAME and PROGRAM or SCRIPT are required")
  endif()
  if(K_SCRIPT)
    get_filename_component(file "${K_SCRIPT}" ABSOLUTE)
    set(arch amd64)
    if(K_ARCH)
      set(arch ${K_ARCH})
    endif()
  else()
    get_target_property(file ${K_PROGRAM} MIRRORCAL_GUEST_FILE)
    get_target_property(arch ${K_PROGRAM} MIRRORCAL_GUEST_ARCH)
    if(NOT file)
      message(FATAL_ERROR "mirrorcal_kernel_test(${K_NAME}): ${K_PROGRAM} is no mirrorcal_guest_program")
    endif()
  endif()
  # A wall-clock guard against a hung guest only: no test may depend on the host's speed. A guest
  # on its instruction clock (ICOUNT) runs at the host's pace, two to three times slower on a
  # loaded CI machine than on an idle one, so its guard is wide.
  if(NOT K_TIMEOUT)
    if(DEFINED K_ICOUNT)
      set(K_TIMEOUT 600)
    else()
      set(K_TIMEOUT 90)
    endif()
  endif()
  set(cmd ${_mirrorcal_run_in_qemu} --arch ${arch} --cache ${MIRRORCAL_KERNEL_CACHE}
          --timeout ${K_TIMEOUT})
  foreach(m IN LISTS K_MODULES)
    list(APPEND cmd --module "${m}")
  endforeach()
  foreach(s IN LISTS K_SETUP)
    list(APPEND cmd --setup "${s}")
  endforeach()
  foreach(t IN LISTS K_HOST_TOOLS)
    list(APPEND cmd --host-tool "${t}")
  endforeach()
  foreach(f IN LISTS K_FILES)
    list(APPEND cmd --file "${f}")
  endforeach()
  if(K_MONITOR)
    list(APPEND cmd --monitor)
  endif()
  if(DEFINED K_ICOUNT)
    list(APPEND cmd --icount ${K_ICOUNT})
  endif()
  add_test(NAME ${K_NAME} COMMAND ${cmd} -- ${file} ${K_ARGS})
  _mirrorcal_kernel_fixture(${arch})
  set(fixtures kernel_${arch})
  if(arch STREQUAL "arm64" AND K_PROGRAM)
    list(APPEND fixtures guest_${K_PROGRAM})
  endif()
  math(EXPR ctest_timeout "${K_TIMEOUT} + 30")
  set_tests_properties(${K_NAME} PROPERTIES LABELS kernel FIXTURES_REQUIRED "${fixtures}"
                       TIMEOUT ${ctest_timeout})
endfunction()
