# The board's Debian package (deploy/Package.cmake) made from this build by cpack, then read back
# with Debian's own dpkg-deb: its name and architecture, its files (the program, settings as
# conffiles, the unit, sysusers.d, udev rules, CAN bring-up, maintainer scripts), a unit that runs
# as a user of its own; then unpacked and its program run: `--version`, and a recording of a
# simulated rig calibrated. Run by CTest (label deploy) with -DBUILD_DIR, -DWORK, -DARCH (dpkg's).
cmake_policy(VERSION 3.25)
file(REMOVE_RECURSE ${WORK})
file(MAKE_DIRECTORY ${WORK})

include(${CMAKE_CURRENT_LIST_DIR}/run_step.cmake)

run("cpack" ${CMAKE_CPACK_COMMAND} --config ${BUILD_DIR}/CPackConfig.cmake -B ${WORK})
file(GLOB debs ${WORK}/mirrorcal_*_${ARCH}.deb)
list(LENGTH debs n)
if(NOT n EQUAL 1)
  file(GLOB all ${WORK}/*)
  message(FATAL_ERROR "cpack wrote no one mirrorcal_*_${ARCH}.deb: ${all}")
endif()

run("dpkg-deb --field" dpkg-deb --field ${debs} Package Architecture Version)
if(NOT out MATCHES "Package: mirrorcal\n" OR NOT out MATCHES "Architecture: ${ARCH}\n")
  message(FATAL_ERROR "the package's control fields:\n${out}")
endif()
run("dpkg-deb --contents" dpkg-deb --contents ${debs})
set(contents "${out}")
foreach(f ./usr/bin/mirrorcal ./etc/mirrorcal/run.conf ./etc/mirrorcal/imu.yaml
          ./usr/lib/systemd/system/mirrorcal.service ./usr/lib/sysusers.d/mirrorcal.conf
          ./usr/lib/udev/rules.d/60-mirrorcal.rules ./usr/libexec/mirrorcal/can-up
          ./usr/share/doc/mirrorcal/board.md)
  string(FIND "${contents}" " ${f}\n" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "the package lacks ${f}:\n${contents}")
  endif()
endforeach()
if(contents MATCHES " ./usr/(include|lib/cmake|lib/pkgconfig)/")
  message(FATAL_ERROR "the board's package holds the development files:\n${contents}")
endif()
# Maintainer scripts and conffiles, as dpkg will read them.
run("dpkg-deb --control" dpkg-deb --control ${debs} ${WORK}/DEBIAN)
foreach(f postinst prerm postrm conffiles)
  if(NOT EXISTS ${WORK}/DEBIAN/${f})
    message(FATAL_ERROR "the package has no ${f}")
  endif()
endforeach()
file(STRINGS ${WORK}/DEBIAN/conffiles conffiles)
foreach(f IN LISTS conffiles)
  string(FIND "${contents}" " .${f}\n" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "conffile ${f} is not in the package")
  endif()
endforeach()

run("dpkg-deb --extract" dpkg-deb --extract ${debs} ${WORK}/root)
file(READ ${WORK}/root/usr/lib/systemd/system/mirrorcal.service unit)
if(NOT unit MATCHES "\nUser=([a-z_][a-z0-9_-]*)\n" OR CMAKE_MATCH_1 STREQUAL "root")
  message(FATAL_ERROR "the packaged unit does not run as a user of its own:\n${unit}")
endif()
set(line "ExecStart=/usr/bin/mirrorcal run --config /etc/mirrorcal/run.conf")
string(FIND "${unit}" "${line}" at)
if(at EQUAL -1)
  message(FATAL_ERROR "the packaged unit lacks '${line}':\n${unit}")
endif()

set(program ${WORK}/root/usr/bin/mirrorcal)
run("mirrorcal --version" ${program} --version)
if(NOT out MATCHES "^mirrorcal [0-9]")
  message(FATAL_ERROR "the packaged program's --version: ${out}")
endif()
run("mirrorcal record" ${program} record --scenario paper --seed 2 --duration 4 --out ${WORK}/rec)
# 0 (consistent) or 3 (its self-check's doubt on 4 s of data): both are a calibration written.
execute_process(COMMAND ${program} calibrate ${WORK}/rec --out ${WORK}/cal RESULT_VARIABLE rc
                OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT (rc EQUAL 0 OR rc EQUAL 3) OR NOT EXISTS ${WORK}/cal/camchain-imucam.yaml)
  message(FATAL_ERROR "the packaged program did not calibrate (${rc}):\n${out}\n${err}")
endif()
file(REMOVE_RECURSE ${WORK})
