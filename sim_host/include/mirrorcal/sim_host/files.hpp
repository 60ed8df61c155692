// Files read safely: only regular files are read, so a FIFO or a device (/dev/zero) in a
// recording's place is refused, never waited on or read without end.
#pragma once

#include <string>

namespace mirrorcal::files {

// The whole of the regular file path into text; false with a message naming path otherwise
// ("PATH: cannot open: reason", "PATH: not a regular file").
bool read_file(const std::string& path, std::string& text, std::string& error);

}  // namespace mirrorcal::files
