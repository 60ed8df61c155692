// mirrorcal record's two halves: the board's devices (cmd_record.cpp) and the simulated rig
// (record_simulated.cpp, only in the host's build; board_tools.cpp refers the board's to it).
#pragma once

#include <string>

#include "cli.hpp"
#include "mirrorcal/io/files.hpp"

namespace mirrorcal::app {

// A recording's folder is written whole or not at all, into the temporary folder of a
// io::StagedFolder that replaces it when committed. An error returned before then leaves
// nothing: the StagedFolder removes its temporary folder as it goes out of scope, after the writer
// declared after it has closed its files. refuse_recording refuses err, about a file in folder,
// naming the file as the user will find it (exit code 1).
inline int refuse_recording(const io::StagedFolder& folder, const std::string& err) {
  return refuse(folder.as_target(err), 1);
}

// The simulated rig's recording into dir, as `record` without --imu asks for it.
int record_simulated(const Options& o, const std::string& dir);

}  // namespace mirrorcal::app
