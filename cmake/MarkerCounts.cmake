# MIRRORCAL_MARKERS checked, sorted, and written into the header every part of the program takes the
# list from (mirrorcal/estimator/marker_counts.hpp, in the build folder): the estimator instantiates
# its filters, the calibration its pipeline, and the program dispatches on it.
set(_counts "")
foreach(m IN LISTS MIRRORCAL_MARKERS)
  if(NOT m MATCHES "^[0-9]+$" OR m LESS 1 OR m GREATER 16)
    message(FATAL_ERROR "MIRRORCAL_MARKERS: '${m}' is not a marker count from 1 to 16 (a list: -DMIRRORCAL_MARKERS=\"3;4;6\")")
  endif()
  list(APPEND _counts ${m})
endforeach()
list(REMOVE_DUPLICATES _counts)
list(SORT _counts COMPARE NATURAL)
# The paper's scenario, the recordings of the tests and the board's examples have three markers.
if(NOT 3 IN_LIST _counts)
  message(FATAL_ERROR "MIRRORCAL_MARKERS must hold 3 (the paper's rig and the tests); got '${MIRRORCAL_MARKERS}'")
endif()
set(MIRRORCAL_MARKER_COUNTS ${_counts} CACHE INTERNAL "MIRRORCAL_MARKERS checked and sorted")

list(JOIN _counts ", " MIRRORCAL_MARKER_COUNTS_TEXT)
list(JOIN _counts ";" MIRRORCAL_MARKER_COUNTS_OPTION)
list(TRANSFORM _counts PREPEND "X(" OUTPUT_VARIABLE _x)
list(TRANSFORM _x APPEND ")")
list(JOIN _x " " MIRRORCAL_MARKER_COUNTS_X)
list(JOIN _counts ", " MIRRORCAL_MARKER_COUNTS_ARRAY)
list(LENGTH _counts MIRRORCAL_MARKER_COUNTS_N)
list(GET _counts -1 MIRRORCAL_MARKER_COUNTS_MAX)
set(MIRRORCAL_GENERATED_INCLUDE ${PROJECT_BINARY_DIR}/generated/include)
configure_file(${PROJECT_SOURCE_DIR}/estimator/marker_counts.hpp.in
               ${MIRRORCAL_GENERATED_INCLUDE}/mirrorcal/estimator/marker_counts.hpp @ONLY)
message(STATUS "mirrorcal: marker counts ${MIRRORCAL_MARKER_COUNTS_TEXT} (MIRRORCAL_MARKERS)")
