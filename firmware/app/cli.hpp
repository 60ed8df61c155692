// Command-line plumbing shared by the mirrorcal commands: options, errors, progress.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "mirrorcal/sim_host/scenario.hpp"

namespace mirrorcal::app {

// One subcommand of the mirrorcal program.
struct Command {
  const char* name;
  const char* usage;  // options, indented, for the program's usage text
  int (*run)(int argc, char** argv);
};

// The program's commands (commands.cpp) and the usage text built from them.
const std::vector<Command>& commands();
std::string usage();

struct Options {
  std::map<std::string, std::string> values;
  std::vector<std::string> positional;
  bool flag(const std::string& k) const { return values.count(k) != 0; }
  std::string get(const std::string& k, const std::string& def) const {
    auto it = values.find(k);
    return it == values.end() ? def : it->second;
  }
};

// Prints "mirrorcal: msg" to stderr and exits with code.
[[noreturn]] void fail(const std::string& msg, int code = 2);

// Parses argv[first..) as --key value (keys in with_value) and --flag (flags); anything else is an
// error naming the argument, unless max_positional allows that many plain arguments.
Options parse(int argc, char** argv, int first, const std::vector<std::string>& with_value,
              const std::vector<std::string>& flags, std::size_t max_positional = 0);

// An unsigned integer option within min..max, or def when absent; anything else fails with a
// message.
std::uint64_t parse_count(const Options& o, const std::string& key, std::uint64_t def,
                          std::uint64_t min, std::uint64_t max = UINT64_MAX);

// The scenario named by --scenario (default "paper"); the random family's draw for seed. With
// --timeshift S (s, within +-kMaxSimulatedTimeshiftS), the true camera-IMU time offset is S; with
// --distortion MODEL, the camera has that lens (sim::set_lens).
constexpr double kMaxSimulatedTimeshiftS = 0.5;
sim::Scenario scenario_option(const Options& o, std::uint64_t seed);

// Creates dir and locks it against a second mirrorcal writing into it (files::lock_folder) for as
// long as this one runs; fails with a message if it cannot.
void create_out_dir(const std::string& dir);
// The same for --out (or def), which it returns.
std::string make_out_dir(const Options& o, const std::string& def);

// "\r<what> NN %" on stderr.
void print_progress(const char* what, double fraction);

}  // namespace mirrorcal::app
