# Installs the build under a prefix of its own and builds a small outside project against it twice:
# with find_package(mirrorcal) (tests/deploy/outside) and with pkg-config's flags; each program
# runs the installed filter. Run by CTest (label deploy) with -DBUILD_DIR, -DWORK, -DSOURCE_DIR.
file(REMOVE_RECURSE ${WORK})
set(prefix ${WORK}/prefix)
execute_process(COMMAND ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix}
                RESULT_VARIABLE rc OUTPUT_QUIET)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "cmake --install failed: ${rc}")
endif()
foreach(f lib/cmake/mirrorcal/mirrorcalConfig.cmake lib/pkgconfig/mirrorcal.pc
          include/mirrorcal/estimator/calibration_filter.hpp include/mirrorcal/hal/sources.hpp
          include/mirrorcal/loop/loop.hpp include/mirrorcal/detection/blob_detector.hpp
          lib/libmirrorcal_estimator.a)
  if(NOT EXISTS ${prefix}/${f})
    message(FATAL_ERROR "not installed: ${f}")
  endif()
endforeach()

include(${CMAKE_CURRENT_LIST_DIR}/run_step.cmake)

# find_package(mirrorcal), from the installed prefix only.
run("configure the outside project" ${CMAKE_COMMAND} -S ${SOURCE_DIR}/outside -B ${WORK}/outside
    -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_BUILD_TYPE=Release)
run("build the outside project" ${CMAKE_COMMAND} --build ${WORK}/outside)
run("run the outside project" ${WORK}/outside/outside)

# pkg-config mirrorcal.
set(ENV{PKG_CONFIG_PATH} ${prefix}/lib/pkgconfig)
execute_process(COMMAND pkg-config --cflags --libs mirrorcal RESULT_VARIABLE rc
                OUTPUT_VARIABLE flags OUTPUT_STRIP_TRAILING_WHITESPACE)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "pkg-config cannot read mirrorcal.pc")
endif()
separate_arguments(flags UNIX_COMMAND "${flags}")
run("compile with pkg-config's flags" c++ -std=c++17 -O1 ${SOURCE_DIR}/outside/main.cpp ${flags}
    -o ${WORK}/outside-pc)
run("run the pkg-config build" ${WORK}/outside-pc)
