# Installs the build into a staging directory (DESTDIR, as a package build does) and checks the
# layout docs/board.md ("Deploying") promises: the program, the run settings and sensor descriptions, the systemd
# unit pointing at the installed program and settings. Run by CTest (label deploy) with
# -DBUILD_DIR, -DSTAGE, -DPREFIX, -DSYSCONFDIR (absolute), -DUNIT_DIR (relative to the prefix).
file(REMOVE_RECURSE ${STAGE})
set(ENV{DESTDIR} ${STAGE})
execute_process(COMMAND ${CMAKE_COMMAND} --install ${BUILD_DIR} RESULT_VARIABLE rc OUTPUT_QUIET)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "cmake --install failed: ${rc}")
endif()
set(root ${STAGE}${PREFIX})
set(conf ${STAGE}${SYSCONFDIR}/mirrorcal)
foreach(f ${root}/bin/mirrorcal ${conf}/run.conf ${conf}/imu.yaml ${conf}/camchain.yaml
          ${conf}/mirrorcal.yaml ${root}/${UNIT_DIR}/mirrorcal.service)
  if(NOT EXISTS ${f})
    message(FATAL_ERROR "not installed: ${f}")
  endif()
endforeach()
file(READ ${root}/${UNIT_DIR}/mirrorcal.service unit)
string(FIND "${unit}" "ExecStart=${PREFIX}/bin/mirrorcal run --config ${SYSCONFDIR}/mirrorcal/run.conf"
       at)
if(at EQUAL -1)
  message(FATAL_ERROR "the unit does not start the installed program with the installed settings:\n${unit}")
endif()
file(READ ${conf}/run.conf settings)
string(FIND "${settings}" "sensors: ${SYSCONFDIR}/mirrorcal" at)
if(at EQUAL -1)
  message(FATAL_ERROR "run.conf does not name the installed sensor descriptions:\n${settings}")
endif()
execute_process(COMMAND ${root}/bin/mirrorcal --help RESULT_VARIABLE rc OUTPUT_VARIABLE out)
if(NOT rc EQUAL 0 OR NOT out MATCHES "sim")
  message(FATAL_ERROR "the installed program does not run: ${rc}\n${out}")
endif()
file(REMOVE_RECURSE ${STAGE})
