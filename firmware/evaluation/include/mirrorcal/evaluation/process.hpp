// Other programs (gnuplot) run without a shell: an argument vector, never a command line, so no
// file or folder name can become a command, whatever characters it holds.
#pragma once

#include <string>
#include <vector>

namespace mirrorcal::evaluation {

// How a program run by run_program ended.
struct ProgramExit {
  int status = -1;    // its exit status, 128 + the signal that killed it, or -1: it did not start
  std::string error;  // empty when it exited with 0; else what happened, naming the program
};

// Runs argv[0] (searched on PATH) with the arguments argv[1..] and waits for it. Its input is
// /dev/null; its output and errors go to output_path when given (created or truncated), and it
// runs in the folder cwd when given.
ProgramExit run_program(const std::vector<std::string>& argv, const std::string& cwd = "",
                        const std::string& output_path = "");

}  // namespace mirrorcal::evaluation
