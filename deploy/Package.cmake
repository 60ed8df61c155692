# The Debian package of the board's program: install component `board` only (the program and
# deploy/'s files, not the libraries and headers), laid out under /usr with its settings in
# /etc/mirrorcal. `cpack` in a build writes it into <build>/package; the `package` workflow
# (cmake/PackageAll.cmake) builds it statically for arm64 and amd64.
set(MIRRORCAL_PACKAGE_DIR ${PROJECT_BINARY_DIR}/package CACHE PATH "Where cpack writes the .deb")
if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64)$")
  set(deb_arch arm64)
elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "^arm")
  set(deb_arch armhf)
elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|AMD64)$")
  set(deb_arch amd64)
else()
  set(deb_arch ${CMAKE_SYSTEM_PROCESSOR})
endif()

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME mirrorcal)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_CONTACT "mirrorcal developers <mirrorcal@users.noreply.invalid>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "IMU-camera self-calibration in front of a plane mirror")
set(CPACK_PACKAGE_DESCRIPTION
    "mirrorcal runs on the sensor board: moved in front of a plane mirror, it calibrates the\
 camera's pose in the IMU's frame, the markers' positions and the camera's intrinsics from the\
 IMU (SPI, I2C or CAN) and the camera (V4L2), and writes Kalibr, OpenVINS and VINS-Fusion files.")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_INSTALL_CMAKE_PROJECTS "${PROJECT_BINARY_DIR};mirrorcal;board;/")
set(CPACK_PACKAGE_DIRECTORY ${MIRRORCAL_PACKAGE_DIR})
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE ${deb_arch})
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "systemd, udev")
if(MIRRORCAL_HOST_TOOLS)
  # The report's plots (a host build's program).
  string(APPEND CPACK_DEBIAN_PACKAGE_RECOMMENDS ", gnuplot-nox")
endif()
# A dynamically linked program depends on the libraries dpkg-shlibdeps finds (the host's build);
# the static one (MIRRORCAL_STATIC_PROGRAM, the package workflow's) on none.
if(NOT MIRRORCAL_STATIC_PROGRAM AND NOT CMAKE_CROSSCOMPILING)
  set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
endif()
# The settings are the user's to edit: conffiles, kept over upgrades.
set(conffiles "")
foreach(f run.conf imu.yaml camchain.yaml mirrorcal.yaml)
  string(APPEND conffiles "/etc/mirrorcal/${f}\n")
endforeach()
file(WRITE ${CMAKE_CURRENT_BINARY_DIR}/debian/conffiles "${conffiles}")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    ${CMAKE_CURRENT_SOURCE_DIR}/debian/postinst ${CMAKE_CURRENT_SOURCE_DIR}/debian/prerm
    ${CMAKE_CURRENT_SOURCE_DIR}/debian/postrm ${CMAKE_CURRENT_BINARY_DIR}/debian/conffiles)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
# Stripped, as Debian ships programs (CMAKE_STRIP: the cross toolchain's for a board's build).
set(CPACK_STRIP_FILES ON)
include(CPack)
