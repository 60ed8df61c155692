# Cross-building for a armhf board with Debian's arm-linux-gnueabihf cross compiler. The board's
# libraries come from a sysroot in the build tree that toolchain/setup-cross armhf unpacks
# (never installed into the host); the C and C++ runtime are the cross compiler's own
# (/usr/arm-linux-gnueabihf). Tests run under qemu-user: ctest works as on the host.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR arm)
set(CMAKE_C_COMPILER arm-linux-gnueabihf-gcc)
set(CMAKE_CXX_COMPILER arm-linux-gnueabihf-g++)

set(MIRRORCAL_SYSROOT "${CMAKE_CURRENT_LIST_DIR}/../build/sysroot/armhf"
    CACHE PATH "The board's libraries, as toolchain/setup-cross armhf unpacks them")
set(CMAKE_FIND_ROOT_PATH "${MIRRORCAL_SYSROOT}" /usr/arm-linux-gnueabihf)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
# Shared libraries of the sysroot are found at link time through it, and at run time under qemu.
set(CMAKE_EXE_LINKER_FLAGS_INIT "-Wl,-rpath-link,${MIRRORCAL_SYSROOT}/usr/lib/arm-linux-gnueabihf")
set(CMAKE_CROSSCOMPILING_EMULATOR
    qemu-arm-static -L /usr/arm-linux-gnueabihf -E LD_LIBRARY_PATH=${MIRRORCAL_SYSROOT}/usr/lib/arm-linux-gnueabihf)
