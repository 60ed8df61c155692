# Script mode, run at every build: writes OUT, the source of mirrorcal::io::version(), with the
# project's VERSION and the commit SRC is at (git describe; "unknown" outside a git checkout). The
# file is rewritten only when either changes, so that a new commit recompiles one small unit.
execute_process(COMMAND git -C ${SRC} describe --always --dirty --abbrev=12
                OUTPUT_VARIABLE commit OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET
                RESULT_VARIABLE status)
if(NOT status EQUAL 0 OR commit STREQUAL "")
  set(commit "unknown")
endif()
set(text "// Written by cmake/Version.cmake at build time.
#include \"mirrorcal/io/version.hpp\"

namespace mirrorcal::io {

const char* version() {
  return \"${VERSION}\";
}

const char* commit() {
  return \"${commit}\";
}

}  // namespace mirrorcal::io
")
set(old "")
if(EXISTS ${OUT})
  file(READ ${OUT} old)
endif()
if(NOT old STREQUAL text)
  file(WRITE ${OUT} "${text}")
endif()
