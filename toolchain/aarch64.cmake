# Cross-building for a aarch64 board with Debian's aarch64-linux-gnu cross compiler. The board's
# libraries come from a sysroot in the build tree that toolchain/setup-cross aarch64 unpacks
# (never installed into the host); the C and C++ runtime are the cross compiler's own
# (/usr/aarch64-linux-gnu). Tests run under qemu-user: ctest works as on the host.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)

set(MIRRORCAL_SYSROOT "${CMAKE_CURRENT_LIST_DIR}/../build/sysroot/aarch64"
    CACHE PATH "The board's libraries, as toolchain/setup-cross aarch64 unpacks them")
set(CMAKE_FIND_ROOT_PATH "${MIRRORCAL_SYSROOT}" /usr/aarch64-linux-gnu)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
# Shared libraries of the sysroot are found at link time through it, and at run time under qemu.
set(CMAKE_EXE_LINKER_FLAGS_INIT "-Wl,-rpath-link,${MIRRORCAL_SYSROOT}/usr/lib/aarch64-linux-gnu")
set(CMAKE_CROSSCOMPILING_EMULATOR
    qemu-aarch64-static -L /usr/aarch64-linux-gnu -E LD_LIBRARY_PATH=${MIRRORCAL_SYSROOT}/usr/lib/aarch64-linux-gnu)
