#include "cli.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include <unistd.h>

#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/io/files.hpp"

namespace mirrorcal::app {

std::string usage() {
  std::string u = "usage: mirrorcal <command> [options]   (mirrorcal --version: which build)\n";
  for (const auto& c : commands()) u += c.usage;
  return u;
}

std::string usage(const std::string& command) {
  for (const auto& c : commands())
    if (command == c.name) return "usage: mirrorcal " + command + " [options]\n" + c.usage;
  return usage();
}

int refuse(const std::string& msg, int code) {
  // What the command printed so far comes first, also when both streams go to one file (a run
  // that ends on a device error prints its counters, then why it ended).
  std::fflush(stdout);
  std::fprintf(stderr, "mirrorcal: %s\n", msg.c_str());
  return code;
}

bool asks_for_help(int argc, char** argv, int first) {
  for (int i = first; i < argc; ++i)
    if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") return true;
  return false;
}

bool parse(int argc, char** argv, int first, const std::vector<std::string>& with_value,
           const std::vector<std::string>& flags, Options& o, std::string& error,
           std::size_t max_positional) {
  // A command used wrongly shows its own usage only, so that the one-line error stays in sight.
  const std::string command_usage = usage(first > 1 ? argv[first - 1] : "");
  for (int i = first; i < argc; ++i) {
    const std::string a = argv[i];
    auto in = [&](const std::vector<std::string>& v) {
      for (const auto& s : v)
        if (a == "--" + s) return true;
      return false;
    };
    if (in(with_value)) {
      if (i + 1 >= argc) {
        error = "option " + a + " needs a value\n" + command_usage;
        return false;
      }
      o.values[a.substr(2)] = argv[++i];
    } else if (in(flags)) {
      o.values[a.substr(2)] = "1";
    } else if (a.rfind("-", 0) != 0 && o.positional.size() < max_positional) {
      o.positional.push_back(a);
    } else {
      error = "unknown argument '" + a + "'\n" + command_usage;
      return false;
    }
  }
  return true;
}

bool parse_count(const Options& o, const std::string& key, std::uint64_t def, std::uint64_t min,
                 std::uint64_t& value, std::string& error, std::uint64_t max) {
  const std::string s = o.get(key, "");
  if (s.empty()) {
    value = def;
    return true;
  }
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(s.c_str(), &end, 10);
  if (errno != 0 || end == s.c_str() || *end != '\0' || s[0] == '-' || v < min || v > max) {
    error = "--" + key + " must be an integer " +
            (max == UINT64_MAX ? ">= " + std::to_string(min)
                               : "within " + std::to_string(min) + ".." + std::to_string(max)) +
            ", not '" + s + "'";
    return false;
  }
  value = v;
  return true;
}

std::string marker_count_not_built(int m) {
  if (m < 1) return std::to_string(m) + " markers: a calibration needs at least one";
  std::string counts, option;
  for (const int built : kMarkerCounts) {
    counts += (counts.empty() ? "" : ", ") + std::to_string(built);
    option += std::to_string(built) + ";";
  }
  return std::to_string(m) + " markers: this build has marker counts " + counts +
         "; rebuild with -DMIRRORCAL_MARKERS=\"" + option + std::to_string(m) + "\"";
}

bool imu_model_option(const Options& o, ImuModel fallback, ImuModel& model, std::string& error) {
  const std::string name = o.get("imu-model", to_string(fallback));
  if (!imu_model_from_string(name, model)) {
    error = "--imu-model: '" + name +
            "' is not an IMU model (calibrated, scale-misalignment, scale-misalignment-rotation, "
            "scale-misalignment-rotation-g-sensitivity)";
    return false;
  }
  if (!imu_model_built(imu_intrinsics_dim(model))) {
    error = "--imu-model: " + imu_model_not_built(model);
    return false;
  }
  return true;
}

std::string imu_model_not_built(ImuModel model) {
  std::string built = "calibrated", option = "calibrated";
  for (const ImuModel m :
       {ImuModel::kScaleMisalignment, ImuModel::kRotation, ImuModel::kGSensitivity})
    if (imu_model_built(imu_intrinsics_dim(m))) {
      built += std::string(", ") + to_string(m);
      option += std::string(";") + to_string(m);
    }
  return std::string("the IMU model ") + to_string(model) + " is not in this build (it has " +
         built + "); rebuild with -DMIRRORCAL_IMU_MODELS=\"" + option + ";" + to_string(model) +
         "\"";
}

void print_final_nees(std::size_t states, double nees, const char* against) {
  const double k = static_cast<double>(states);
  std::printf("\nNEES of the %zu calibration states%s: %.2f (95 %% interval %.2f..%.2f)\n", states,
              against, nees, calibration::chi2_quantile(0.025, k),
              calibration::chi2_quantile(0.975, k));
}

void print_result_warnings(const calibration::CalibrationResult& r) {
  for (const std::string& w : calibration::result_warnings(r))
    std::fprintf(stderr, "mirrorcal: WARNING: %s\n", w.c_str());
}

int calibration_exit_status(const calibration::CalibrationResult& r) {
  if (calibration::consistent(r)) return 0;
  std::fprintf(stderr,
               "mirrorcal: the calibration says consistent: false (the WARNING above): its files "
               "are written and say so, not to be used as they are (exit status %d)\n",
               kExitNotConsistent);
  return kExitNotConsistent;
}

bool calibration_imu_model(const Options& o, const io::SensorInfo& sensors,
                           const std::string& folder, ImuModel& model, std::string& error) {
  model = kDefaultImuModel;
  if (o.flag("imu-model")) {
    if (!imu_model_option(o, kDefaultImuModel, model, error)) return false;
  } else if (sensors.imu_model) {
    model = *sensors.imu_model;
    if (!imu_model_built(imu_intrinsics_dim(model))) {
      error = folder + "/imu.yaml: imu_model: " + imu_model_not_built(model);
      return false;
    }
  }
  if (model == ImuModel::kCalibrated) return true;
  if (sensors.imu_tolerances_defaulted)
    std::fprintf(stderr,
                 "mirrorcal: note: %s/imu.yaml: not every tolerance of the IMU's intrinsics is "
                 "given; using 1-sigma defaults that cover common MEMS parts (scale 2 %%, "
                 "cross-axis 1.2 %%, g-sensitivity 5e-4 (rad/s)/(m/s^2)) for those missing "
                 "(docs/recordings.md, imu.yaml)\n",
                 folder.c_str());
  return true;
}

bool create_out_dir(const std::string& dir, std::string& error) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    error = "cannot create output directory " + dir + ": " + ec.message();
    return false;
  }
  return io::lock_folder(dir, error);
}

bool make_out_dir(const Options& o, const std::string& def, std::string& dir, std::string& error) {
  dir = o.get("out", def);
  return create_out_dir(dir, error);
}

namespace {

bool stderr_is_terminal() {
  static const bool terminal = isatty(STDERR_FILENO) == 1;
  return terminal;
}

}  // namespace

void print_progress(const char* what, double fraction) {
  if (stderr_is_terminal()) {
    std::fprintf(stderr, "\r%s %3.0f %%", what, 100.0 * fraction);
    std::fflush(stderr);
    return;
  }
  // A line when the tenth changes (backwards too: a new stage starts again from 0).
  static int last_tenth = -1;
  const int tenth = static_cast<int>(std::floor(10.0 * fraction));
  if (tenth == last_tenth) return;
  last_tenth = tenth;
  std::fprintf(stderr, "%s %3d %%\n", what, 10 * tenth);
}

void end_progress(const char* done_text) {
  // On a terminal, blanks cover what is left of the last "\r<what> NN %".
  if (stderr_is_terminal())
    std::fprintf(stderr, "\r%-24s\n", done_text);
  else
    std::fprintf(stderr, "%s\n", done_text);
}

}  // namespace mirrorcal::app
