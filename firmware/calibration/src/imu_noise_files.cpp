#include "mirrorcal/calibration/imu_noise_files.hpp"

#include <sys/stat.h>

#include <cmath>
#include <cstdio>

#include "mirrorcal/io/files.hpp"
#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::calibration {

namespace {

bool add_bytes(io::OutputSet& out, const std::string& path, const std::string& bytes,
               std::string& error) {
  std::FILE* f = out.add(path, error);
  if (f == nullptr) return false;
  // A short write shows at commit, which flushes and checks every file.
  std::fwrite(bytes.data(), 1, bytes.size(), f);
  return true;
}

std::string bound_note(const char* key, const NoiseFigure& f) {
  char s[256];
  if (f.resolved)
    std::snprintf(s, sizeof s, "# %s: +-%.2g %% (1-sigma, statistical)\n", key,
                  100.0 * f.rel_sigma);
  else
    std::snprintf(s, sizeof s,
                  "# %s: not resolved in this recording: an upper bound (docs/usage.md, "
                  "\"imu-noise\")\n",
                  key);
  return s;
}

}  // namespace

bool read_imu_samples(const std::string& path, std::vector<ImuSample>& out, std::string& file,
                      std::string& error) {
  struct stat st {};
  // A folder is a recording: its IMU data where the EuRoC layout puts them.
  file =
      ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode) ? path + "/mav0/imu0/data.csv" : path;
  std::string text;
  return io::read_file(file, text, error) && io::parse_imu_csv(text, file, out, error);
}

std::string imu_noise_yaml(const ImuNoiseAnalysis& a) {
  io::SensorInfo sensors;
  sensors.imu = a.noise();
  // The rate to a hundredth of a hertz: a board's timestamp jitter moves the median step by less.
  sensors.imu_rate_hz = std::round(a.rate_hz * 100.0) / 100.0;
  std::string y = io::imu_yaml_text(sensors);
  // The file's name goes into a comment: a line break in it would end the comment.
  std::string file = a.file;
  for (char& c : file)
    if (c == '\n' || c == '\r') c = '?';
  y += "# Estimated by mirrorcal imu-noise from " + file + " (" + std::to_string(a.samples) +
       " still samples); the Allan deviations are in allan.csv beside it.\n";
  y += bound_note("accelerometer_noise_density", a.accel.white);
  y += bound_note("accelerometer_random_walk", a.accel.random_walk);
  y += bound_note("gyroscope_noise_density", a.gyro.white);
  y += bound_note("gyroscope_random_walk", a.gyro.random_walk);
  return y;
}

bool write_imu_noise(const std::string& dir, const ImuNoiseAnalysis& a, AllanPlotter plotter,
                     std::string& plot_note, std::string& error) {
  io::OutputSet out;
  if (!add_bytes(out, dir + "/imu.yaml", imu_noise_yaml(a), error) ||
      !add_bytes(out, dir + "/allan.csv", allan_csv(a), error))
    return false;
  plot_note.clear();
  if (plotter != nullptr) {
    std::string png;
    if (plotter(a, png, plot_note)) {
      if (!add_bytes(out, dir + "/allan.png", png, error)) return false;
    } else {
      plot_note = "no allan.png: " + plot_note;
    }
  }
  return out.commit(error);
}

}  // namespace mirrorcal::calibration
