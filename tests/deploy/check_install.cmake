# Installs the build into a staging directory (DESTDIR, as a package build does), once with the
# build's prefix and once with `--prefix /usr`, and checks the layout docs/board.md ("Deploying")
# promises: the program, the run settings and sensor descriptions (in /etc for the prefix /usr),
# the systemd unit pointing at the installed program and settings and running as its own user,
# its user and groups (sysusers.d), the device rules and the CAN bring-up. Run by CTest (label
# deploy) with -DBUILD_DIR, -DSTAGE, -DPREFIX (the build's).
cmake_policy(VERSION 3.25)
function(expect_match text regex failure)
  if(NOT text MATCHES "${regex}")
    message(FATAL_ERROR "${failure}")
  endif()
endfunction()

function(check_install prefix sysconfdir)
  file(REMOVE_RECURSE ${STAGE})
  set(ENV{DESTDIR} ${STAGE})
  execute_process(COMMAND ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix}
                  RESULT_VARIABLE rc OUTPUT_QUIET)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "cmake --install --prefix ${prefix} failed: ${rc}")
  endif()
  set(root ${STAGE}${prefix})
  set(conf ${STAGE}${sysconfdir}/mirrorcal)
  set(unit_file ${root}/lib/systemd/system/mirrorcal.service)
  foreach(f ${root}/bin/mirrorcal ${conf}/run.conf ${conf}/imu.yaml ${conf}/camchain.yaml
            ${conf}/mirrorcal.yaml ${unit_file} ${root}/libexec/mirrorcal/can-up
            ${root}/lib/udev/rules.d/60-mirrorcal.rules ${root}/lib/sysusers.d/mirrorcal.conf
            ${root}/share/doc/mirrorcal/board.md)
    if(NOT EXISTS ${f})
      message(FATAL_ERROR "--prefix ${prefix}: not installed: ${f}")
    endif()
  endforeach()
  file(READ ${unit_file} unit)
  foreach(line "ExecStart=${prefix}/bin/mirrorcal run --config ${sysconfdir}/mirrorcal/run.conf"
               "ExecStartPre=+${prefix}/libexec/mirrorcal/can-up ${sysconfdir}/mirrorcal/run.conf")
    string(FIND "${unit}" "${line}" at)
    if(at EQUAL -1)
      message(FATAL_ERROR "--prefix ${prefix}: the unit lacks '${line}':\n${unit}")
    endif()
  endforeach()
  # Its own user, and one the sysusers.d file creates.
  if(NOT unit MATCHES "\nUser=([a-z_][a-z0-9_-]*)\n" OR CMAKE_MATCH_1 STREQUAL "root")
    message(FATAL_ERROR "--prefix ${prefix}: the unit does not run as a user of its own:\n${unit}")
  endif()
  set(user ${CMAKE_MATCH_1})
  file(READ ${root}/lib/sysusers.d/mirrorcal.conf sysusers)
  expect_match("${sysusers}" "\nu ${user} " "sysusers.d/mirrorcal.conf does not create ${user}")
  if(NOT unit MATCHES "\nSupplementaryGroups=([^\n]*)\n")
    message(FATAL_ERROR "--prefix ${prefix}: the unit names no device groups:\n${unit}")
  endif()
  separate_arguments(groups UNIX_COMMAND "${CMAKE_MATCH_1}")
  file(READ ${root}/lib/udev/rules.d/60-mirrorcal.rules rules)
  foreach(g IN LISTS groups)
    expect_match("${sysusers}" "\nm ${user} ${g}\n"
                 "sysusers.d/mirrorcal.conf does not put ${user} in the group ${g}")
    expect_match("${rules}" "GROUP=\"${g}\"" "60-mirrorcal.rules gives no device to the group ${g}")
  endforeach()
  file(READ ${conf}/run.conf settings)
  string(FIND "${settings}" "sensors: ${sysconfdir}/mirrorcal" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "--prefix ${prefix}: run.conf does not name the installed sensor descriptions:\n${settings}")
  endif()
  execute_process(COMMAND ${root}/bin/mirrorcal --help RESULT_VARIABLE rc OUTPUT_VARIABLE out)
  if(NOT rc EQUAL 0 OR NOT out MATCHES "calibrate")
    message(FATAL_ERROR "--prefix ${prefix}: the installed program does not run: ${rc}\n${out}")
  endif()
  file(REMOVE_RECURSE ${STAGE})
endfunction()

# The build's prefix, and the packages' /usr (settings in /etc, not /usr/etc).
if(PREFIX STREQUAL "/usr")
  check_install(/usr /etc)
else()
  check_install(${PREFIX} ${PREFIX}/etc)
  check_install(/usr /etc)
endif()
