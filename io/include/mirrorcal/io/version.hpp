// Which mirrorcal wrote a file: the program's version and the commit it was built from (the
// build writes them, cmake/Version.cmake). `mirrorcal --version` prints them, and every YAML file
// and report the program writes names them in its header.
#pragma once

#include <string>

namespace mirrorcal::io {

const char* version();  // the project's, e.g. "0.1.0"
const char* commit();   // git describe of the source, e.g. "8de380c1a2b3" (-dirty: uncommitted)

// "mirrorcal 0.1.0 (commit 8de380c1a2b3)", as the files' headers give it.
inline std::string written_by() {
  return std::string("mirrorcal ") + version() + " (commit " + commit() + ")";
}

}  // namespace mirrorcal::io
