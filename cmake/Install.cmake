# What another project builds against (find_package(mirrorcal) or pkg-config mirrorcal): the
# estimator, the HAL's interfaces, the deterministic loop and marker detection, their headers and
# static libraries. The program and the board's files install from firmware/app and deploy/.
include(CMakePackageConfigHelpers)

set(MIRRORCAL_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/mirrorcal)
set_target_properties(mirrorcal_estimator PROPERTIES EXPORT_NAME estimator)
set_target_properties(mirrorcal_hal PROPERTIES EXPORT_NAME hal)
set_target_properties(mirrorcal_loop PROPERTIES EXPORT_NAME loop)
set_target_properties(mirrorcal_detection PROPERTIES EXPORT_NAME detection)

install(TARGETS mirrorcal_estimator mirrorcal_hal mirrorcal_loop mirrorcal_detection
        EXPORT mirrorcalTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT development
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/estimator/include/ ${PROJECT_SOURCE_DIR}/hal/include/
                  ${PROJECT_SOURCE_DIR}/firmware/loop/include/
                  ${PROJECT_SOURCE_DIR}/firmware/detection/include/
        DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} COMPONENT development)
install(FILES ${MIRRORCAL_GENERATED_INCLUDE}/mirrorcal/estimator/marker_counts.hpp
        DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/mirrorcal/estimator COMPONENT development)
install(EXPORT mirrorcalTargets NAMESPACE mirrorcal:: DESTINATION ${MIRRORCAL_CMAKE_DIR}
        COMPONENT development)

configure_package_config_file(${CMAKE_CURRENT_LIST_DIR}/mirrorcalConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/mirrorcalConfig.cmake
                              INSTALL_DESTINATION ${MIRRORCAL_CMAKE_DIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/mirrorcalConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
configure_file(${CMAKE_CURRENT_LIST_DIR}/mirrorcal.pc.in ${PROJECT_BINARY_DIR}/mirrorcal.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/mirrorcalConfig.cmake
              ${PROJECT_BINARY_DIR}/mirrorcalConfigVersion.cmake
        DESTINATION ${MIRRORCAL_CMAKE_DIR})
install(FILES ${PROJECT_BINARY_DIR}/mirrorcal.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig
        COMPONENT development)
