// Shared by the recording tests: temporary folders, files as text, a short simulated recording.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <sys/types.h>
#include <unistd.h>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/io/recording.hpp"

namespace rectest {

namespace fs = std::filesystem;
namespace mc = mirrorcal;

// A fresh folder under the system's temporary one, for this process (builds may test at once).
inline std::string temp_dir(const std::string& name) {
  const fs::path p =
      fs::temp_directory_path() / ("mirrorcal-test-" + std::to_string(getpid()) + "-" + name);
  fs::remove_all(p);
  fs::create_directories(p);
  return p.string();
}

// A temp_dir() removed when the test ends.
struct TempDir {
  explicit TempDir(const std::string& name) : path(temp_dir(name)) {}
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string path;
};

inline std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

inline void spit(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

// The paper scenario, shortened to seconds of data: enough for every marker to be seen.
inline mc::sim::Scenario short_scenario(double seconds = 2.0) {
  mc::sim::Scenario s = mc::sim::paper_scenario();
  s.duration_s = seconds;
  return s;
}

inline mc::io::SensorInfo sensors_of(const mc::sim::Scenario& s) {
  mc::io::SensorInfo i;
  i.imu = s.imu;
  i.imu_rate_hz = s.imu_rate_hz;
  i.intrinsics = s.truth.intrinsics;
  i.width = s.truth.width;
  i.height = s.truth.height;
  return i;
}

// imu.yaml and camchain.yaml of sensors, and mirrorcal.yaml of the prior of data and seed, into
// dir.
inline void write_sensor_files(const std::string& dir, const mc::sim::Scenario& s,
                               const mc::io::SensorInfo& sensors, const mc::sim::SimData& data,
                               std::uint64_t seed) {
  std::string err;
  const auto prior = mc::sim::simulation_prior<mc::sim::kPaperMarkers>(s, data, seed);
  if (!mc::io::write_sensor_yaml(dir, sensors, err) ||
      !mc::io::write_priors_yaml(dir, mc::io::from_prior(prior, s.gravity_n, s.pixel_sigma, false),
                                 err))
    throw std::runtime_error(err);
}

// Writes a complete recording of data with the prior of seed into dir.
inline void write_recording(const std::string& dir, const mc::sim::Scenario& s,
                            const mc::sim::SimData& data, std::uint64_t seed) {
  std::string err;
  mc::io::RecordingWriter w;
  if (!w.open(dir, err)) throw std::runtime_error(err);
  for (const auto& smp : data.imu) w.add_imu(smp);
  for (const auto& f : data.frames) w.add_frame(f);
  if (!w.close(err)) throw std::runtime_error(err);
  write_sensor_files(dir, s, sensors_of(s), data, seed);
}

#ifdef MIRRORCAL_BIN
// Starts mirrorcal with args, its output and errors into log, with env's NAME=VALUE entries added
// to its environment; its pid, for the caller to wait for (wait4 for its peak memory) or signal,
// or -1 if it could not fork.
inline pid_t spawn_mirrorcal(const std::vector<std::string>& args, const std::string& log,
                             const std::vector<std::string>& env = {}) {
  std::vector<std::string> words = {MIRRORCAL_BIN};
  words.insert(words.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& w : words) argv.push_back(w.data());
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    if (!freopen(log.c_str(), "w", stdout) || dup2(fileno(stdout), 2) < 0) _exit(126);
    for (const std::string& e : env) {
      const std::size_t eq = e.find('=');
      if (eq == std::string::npos || setenv(e.substr(0, eq).c_str(), e.c_str() + eq + 1, 1) != 0)
        _exit(126);
    }
    execv(argv[0], argv.data());
    _exit(127);
  }
  return pid;
}
#endif

}  // namespace rectest
