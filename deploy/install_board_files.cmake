# Install-time part of the board's files (deploy/CMakeLists.txt runs it as install(SCRIPT)): the
# systemd unit and run.conf name the installed program and settings, so they are written with the
# prefix the install uses (`cmake --install --prefix P`, or the Debian package's /usr), not the
# one the build was configured with. The settings go where GNUInstallDirs puts them: /etc for the
# prefix /usr, <prefix>/etc otherwise. file(INSTALL) honours DESTDIR (staging, packages).
#
# Set before this runs (install(CODE)): MIRRORCAL_DEPLOY_SOURCE (this folder),
# MIRRORCAL_DEPLOY_BINARY (a scratch folder of the build), MIRRORCAL_DOCS (the docs installed).
set(prefix ${CMAKE_INSTALL_PREFIX})
if(prefix STREQUAL "/usr")
  set(MIRRORCAL_CONFIG_DIR /etc/mirrorcal)
else()
  set(MIRRORCAL_CONFIG_DIR ${prefix}/etc/mirrorcal)
endif()
set(MIRRORCAL_BIN_DIR ${prefix}/bin)
set(MIRRORCAL_LIBEXEC_DIR ${prefix}/libexec/mirrorcal)
set(MIRRORCAL_DOC_DIR ${prefix}/share/doc/mirrorcal)

set(scratch ${MIRRORCAL_DEPLOY_BINARY}/install)
configure_file(${MIRRORCAL_DEPLOY_SOURCE}/mirrorcal.service.in ${scratch}/mirrorcal.service @ONLY)
configure_file(${MIRRORCAL_DEPLOY_SOURCE}/run.conf.in ${scratch}/run.conf @ONLY)

file(INSTALL ${scratch}/mirrorcal.service DESTINATION ${prefix}/lib/systemd/system)
file(INSTALL ${scratch}/run.conf ${MIRRORCAL_DEPLOY_SOURCE}/sensors/imu.yaml
             ${MIRRORCAL_DEPLOY_SOURCE}/sensors/camchain.yaml
             ${MIRRORCAL_DEPLOY_SOURCE}/sensors/mirrorcal.yaml
     DESTINATION ${MIRRORCAL_CONFIG_DIR})
file(INSTALL ${MIRRORCAL_DEPLOY_SOURCE}/can-up DESTINATION ${MIRRORCAL_LIBEXEC_DIR}
     FILE_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE WORLD_READ
                      WORLD_EXECUTE)
file(INSTALL ${MIRRORCAL_DEPLOY_SOURCE}/udev/60-mirrorcal.rules DESTINATION ${prefix}/lib/udev/rules.d)
file(INSTALL ${MIRRORCAL_DEPLOY_SOURCE}/sysusers/mirrorcal.conf DESTINATION ${prefix}/lib/sysusers.d)
file(INSTALL ${MIRRORCAL_DOCS} DESTINATION ${MIRRORCAL_DOC_DIR})
