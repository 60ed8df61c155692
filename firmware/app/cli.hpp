// Command-line plumbing shared by the mirrorcal commands: options, errors, progress.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "mirrorcal/calibration/result.hpp"
#include "mirrorcal/estimator/marker_counts.hpp"
#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::app {

// One subcommand of the mirrorcal program.
struct Command {
  const char* name;
  const char* usage;  // options, indented, for the program's usage text
  int (*run)(int argc, char** argv);
};

// The program's commands (main.cpp) and the usage text built from them: all, or one command's.
const std::vector<Command>& commands();
std::string usage();
std::string usage(const std::string& command);

struct Options {
  std::map<std::string, std::string> values;
  std::vector<std::string> positional;
  bool flag(const std::string& k) const { return values.count(k) != 0; }
  std::string get(const std::string& k, const std::string& def) const {
    auto it = values.find(k);
    return it == values.end() ? def : it->second;
  }
};

// Prints "mirrorcal: msg" to stderr and returns code, the exit status the command returns to main
// (the program's one exit, so that every object unwinds: files closed, temporary ones removed).
// Only the commands (cmd_*.cpp) and main call it: the helpers return false with the message, and
// the command chooses the code (2: the command line or the files it names are wrong; 1: a file, a
// device or an output failed).
int refuse(const std::string& msg, int code = 2);

// The exit status of a command whose calibration says consistent: false (its files are written,
// and say so): distinct from 1 (a failure) and 2 (bad input), so that no script takes a flagged
// calibration for a good one. export refusing such a result (without --force) returns it too.
constexpr int kExitNotConsistent = 3;
// The NEES of a calibration's `states` states against the truth (`against`: where it comes from,
// "" for a simulation's) with its 95 % interval, as sim, calibrate and batch end their tables.
void print_final_nees(std::size_t states, double nees, const char* against = "");
// A calibration's warnings on stderr, a WARNING line each.
void print_result_warnings(const calibration::CalibrationResult& r);
// The status a command that wrote the calibration r returns: 0, or kExitNotConsistent with a
// last line on stderr saying so.
int calibration_exit_status(const calibration::CalibrationResult& r);

// Whether --help (or -h) is anywhere in argv[first..): main then prints the command's usage.
bool asks_for_help(int argc, char** argv, int first);

// Parses argv[first..) as --key value (keys in with_value) and --flag (flags) into o; anything
// else is an error naming the argument, unless max_positional allows that many plain arguments.
bool parse(int argc, char** argv, int first, const std::vector<std::string>& with_value,
           const std::vector<std::string>& flags, Options& o, std::string& error,
           std::size_t max_positional = 0);

// An unsigned integer option within min..max into value, or def when absent; anything else is an
// error.
bool parse_count(const Options& o, const std::string& key, std::uint64_t def, std::uint64_t min,
                 std::uint64_t& value, std::string& error, std::uint64_t max = UINT64_MAX);

// What a count this build does not have gets told: the counts it has and how to add one.
std::string marker_count_not_built(int m);

// The IMU model a user's data are calibrated with (imu_intrinsics.hpp) when neither --imu-model
// nor imu.yaml names one: a MEMS part's scale factors and axes, as an ordinary board's IMU has
// them (the ideal IMU's where the build lacks that model).
constexpr ImuModel kDefaultImuModel =
    imu_model_built(imu_intrinsics_dim(ImuModel::kScaleMisalignment)) ? ImuModel::kScaleMisalignment
                                                                      : ImuModel::kCalibrated;
// --imu-model NAME (default: fallback), a model this build has.
bool imu_model_option(const Options& o, ImuModel fallback, ImuModel& model, std::string& error);
// What a model not built gets told: the models this build has and how to add one.
std::string imu_model_not_built(ImuModel model);
// The IMU model a calibration from the sensors folder `folder` (its imu.yaml read into sensors)
// estimates: --imu-model, else imu.yaml's imu_model, else kDefaultImuModel. Notes on stderr any
// tolerance imu.yaml leaves to the defaults. Refused: a model not built.
bool calibration_imu_model(const Options& o, const io::SensorInfo& sensors,
                           const std::string& folder, ImuModel& model, std::string& error);

// Calls f(ImuIntrinsicsCount<NI>{}) for model's NI (marker_counts.hpp) and returns its exit code; a
// model not built is refused (exit code 2).
template <class F>
int with_imu_model_of(ImuModel model, F&& f) {
  int code = 0;
  if (!with_imu_model(imu_intrinsics_dim(model), [&](auto ni) { code = f(ni); }))
    return refuse(imu_model_not_built(model));
  return code;
}

// The camera block a calibration estimates (MirrorState's NK): none, camchain.yaml's intrinsics
// held (0); fu fv cu cv and the skew (5); the same with the skew held (4); or fu fv cu cv and the
// lens's coefficients, the skew held (8).
constexpr int camera_block(bool intrinsics, bool hold_skew, bool distortion) {
  return !intrinsics ? 0 : distortion ? 8 : hold_skew ? 4 : 5;
}

// Calls f(std::integral_constant<int, NK>{}) for nk (camera_block) and returns its result.
template <class F>
auto with_camera_block(int nk, F&& f) {
  switch (nk) {
    case 4:
      return f(std::integral_constant<int, 4>{});
    case 5:
      return f(std::integral_constant<int, 5>{});
    case 8:
      return f(std::integral_constant<int, 8>{});
    default:
      return f(std::integral_constant<int, 0>{});
  }
}

// Calls f(std::integral_constant<int, NK>{}, ImuIntrinsicsCount<NI>{}) for the filter of nk
// (camera_block) and model, and returns its exit code: every command reaches its filter's
// instantiation through here (with_markers first).
template <class F>
int with_filter_blocks(int nk, ImuModel model, F&& f) {
  return with_imu_model_of(
      model, [&](auto ni) { return with_camera_block(nk, [&](auto k) { return f(k, ni); }); });
}

// Calls f(MarkerCount<M>{}) (marker_counts.hpp) for the built M equal to markers and returns its
// exit code: every command reaches its instantiation for the rig's number of markers through here.
// A count not built is refused, saying which are and how to build another (exit code 2).
template <class F>
int with_markers(int markers, F&& f) {
  int code = 0;
  if (!with_marker_count(markers, [&](auto m) { code = f(m); }))
    return refuse(marker_count_not_built(markers));
  return code;
}

// Creates dir and locks it against a second mirrorcal writing into it (io::lock_folder) for as
// long as this one runs; an error if it cannot.
bool create_out_dir(const std::string& dir, std::string& error);
// The same for --out (or def), which goes into dir.
bool make_out_dir(const Options& o, const std::string& def, std::string& dir, std::string& error);

// "\r<what> NN %" on stderr when it is a terminal; otherwise (a log, a CI capture) a line
// "<what> NN %" at every tenth, so that the log gets a few lines rather than one of thousands of
// carriage returns.
void print_progress(const char* what, double fraction);
// Ends the progress indicator with done_text on a line of its own.
void end_progress(const char* done_text);

}  // namespace mirrorcal::app
