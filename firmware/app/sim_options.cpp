#include "sim_options.hpp"

#include <cmath>
#include <cstdlib>
#include <string>

namespace mirrorcal::app {

using namespace calibration;
using namespace evaluation;

namespace {

// A rolling shutter's line delay: seconds per row, the whole frame read within
// kMaxSimulatedReadoutS.
bool line_delay_option(const Options& o, const std::string& key, const sim::Scenario& s,
                       double& line_delay, std::string& error) {
  const std::string text = o.get(key, "");
  char* end = nullptr;
  line_delay = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != '\0' || !(line_delay >= 0.0) ||
      !(line_delay * s.truth.height <= kMaxSimulatedReadoutS)) {
    error = "--" + key + ": '" + text + "' is not seconds per row (a " +
            std::to_string(s.truth.height) + "-row readout within 0.1 s; 30 us is 3e-5)";
    return false;
  }
  return true;
}

}  // namespace

namespace {

// A share of the simulated frames (--outliers, --label-swaps): "0.02" or "2%", within
// 0..kMaxSimulatedMistakeShare; value is left alone when the option is absent.
bool share_option(const Options& o, const std::string& key, const char* what, double& value,
                  std::string& error) {
  if (!o.flag(key)) return true;
  const std::string text = o.get(key, "");
  char* end = nullptr;
  double share = std::strtod(text.c_str(), &end);
  if (end != text.c_str() && *end == '%') {
    share /= 100.0;
    ++end;
  }
  if (end == text.c_str() || *end != '\0' || !(share >= 0.0) ||
      !(share <= kMaxSimulatedMistakeShare)) {
    error = "--" + key + ": '" + text + "' is not a share of frames with " + what +
            " (0..0.5, or 0..50%)";
    return false;
  }
  value = share;
  return true;
}

}  // namespace

bool scenario_option(const Options& o, std::uint64_t seed, sim::Scenario& s, std::string& error) {
  s = sim::Scenario{};
  const std::string name = o.get("scenario", "paper");
  // --markers N: the random family's rig has N markers (a count this build has).
  std::uint64_t markers = sim::kPaperMarkers;
  if (!parse_count(o, "markers", sim::kPaperMarkers, 1, markers, error, 64)) return false;
  // The paper's rig first: no rebuild gives it another count.
  if (name == "paper" && markers != sim::kPaperMarkers) {
    error = "--markers: the paper scenario has " + std::to_string(sim::kPaperMarkers) +
            " markers; other counts are for --scenario random or mems";
    return false;
  }
  if (!marker_count_built(int(markers))) {
    error = "--markers: " + marker_count_not_built(int(markers));
    return false;
  }
  if (!sim::scenario_by_name(name, seed, s, int(markers))) {
    error = "unknown scenario '" + name + "' (known: paper, random, mems)";
    return false;
  }
  // --duration S: a shorter (or longer) stretch of the simulated rig's motion than its minute.
  if (o.flag("duration")) {
    const std::string text = o.get("duration", "");
    char* end = nullptr;
    const double seconds = std::strtod(text.c_str(), &end);
    if (end == text.c_str() || *end != '\0' || !(seconds >= kMinSimulatedDurationS) ||
        !(seconds <= kMaxSimulatedDurationS)) {
      error = "--duration: '" + text + "' is not seconds of simulated data within " +
              std::to_string(int(kMinSimulatedDurationS)) + ".." +
              std::to_string(int(kMaxSimulatedDurationS));
      return false;
    }
    s.duration_s = seconds;
  }
  // --timeshift S: the camera stamps its frames S seconds before the IMU's clock shows them.
  if (o.flag("timeshift")) {
    const std::string text = o.get("timeshift", "");
    char* end = nullptr;
    const double t_d = std::strtod(text.c_str(), &end);
    if (end == text.c_str() || *end != '\0' || !(std::abs(t_d) <= kMaxSimulatedTimeshiftS)) {
      error = "--timeshift: '" + text + "' is not a time offset in seconds within +-" +
              std::to_string(kMaxSimulatedTimeshiftS).substr(0, 3) + " s";
      return false;
    }
    s.truth.t_d = t_d;
  }
  // --outliers P, --label-swaps P: the detector's mistakes in the share P of frames ("0.02" or
  // "2%").
  if (!share_option(o, "outliers", "a mis-detected marker", s.outlier_share, error) ||
      !share_option(o, "label-swaps", "markers 0 and 1 swapped", s.label_swap_share, error))
    return false;
  // --line-delay S: a rolling shutter that reads each row S seconds after the one above;
  // --filter-line-delay S: the line delay the filter is told, if not the true one.
  if (o.flag("line-delay") &&
      !line_delay_option(o, "line-delay", s, s.truth.intrinsics.line_delay_s, error))
    return false;
  if (o.flag("filter-line-delay")) {
    double told = 0.0;
    if (!line_delay_option(o, "filter-line-delay", s, told, error)) return false;
    s.told_line_delay_s = told;
  }
  // --distortion MODEL: the camera's lens (io::lens_of: EuRoC cam0's radtan, or a fisheye).
  if (o.flag("distortion")) {
    const std::string name = o.get("distortion", "");
    Distortion d = Distortion::kNone;
    if (!distortion_from_string(name, d)) {
      error = "--distortion: '" + name + "' is not a lens model (radtan, equidistant or none)";
      return false;
    }
    sim::set_lens(s, d);
  }
  return true;
}

std::string markers_note(const sim::Scenario& s) {
  const int markers = int(s.truth.markers.size());
  return markers == sim::kPaperMarkers ? "" : ", " + std::to_string(markers) + " markers";
}

ImuModel simulated_imu_model(const sim::Scenario& s) {
  return sim::has_imu_intrinsics(s) ? kDefaultImuModel : ImuModel::kCalibrated;
}

bool frame_mode_option(const Options& o, FrameMode& frames, std::string& error) {
  frames = FrameMode{};
  frames.enabled = o.flag("frames");
  // Every option below but --frames itself sets what the frames are: none applies without them.
  for (const char* key : {"format", "spot-noise", "pixel-sigma", "identical-leds", "room", "blink"})
    if (o.flag(key) && !frames.enabled) {
      error = std::string("--") + key + " applies to --frames only";
      return false;
    }
  const std::string format = o.get("format", "grey");
  if (format == "yuyv") {
    frames.format = hal::PixelFormat::kYuyv;
  } else if (format != "grey") {
    error = "--format: '" + format + "' is not a pixel format (grey or yuyv)";
    return false;
  }
  const auto pixels = [&](const char* key, double& value, bool zero_allowed) {
    if (!o.flag(key)) return true;
    const std::string text = o.get(key, "");
    char* end = nullptr;
    value = std::strtod(text.c_str(), &end);
    if (end == text.c_str() || *end != '\0' || !(value > 0.0 || (zero_allowed && value == 0.0))) {
      error = std::string("--") + key + ": '" + text + "' is not a " +
              (zero_allowed ? "non-negative" : "positive") + " number of pixels";
      return false;
    }
    return true;
  };
  frames.identical_leds = o.flag("identical-leds");
  frames.room = o.flag("room");
  if (o.flag("blink")) {
    const std::string text = o.get("blink", "");
    char* end = nullptr;
    const long period = std::strtol(text.c_str(), &end, 10);
    if (end == text.c_str() || *end != '\0' || period < 2 || period > hal::BlinkCode::kMaxPeriod) {
      error = "--blink: '" + text + "' is not a whole number of frames from 2 to " +
              std::to_string(hal::BlinkCode::kMaxPeriod);
      return false;
    }
    frames.blink_period = static_cast<int>(period);
  }
  return pixels("spot-noise", frames.spot_noise_px, true) &&
         pixels("pixel-sigma", frames.pixel_sigma, false);
}

bool blink_fits(const FrameMode& frames, int markers, std::string& error) {
  if (frames.blink_period == 0 || frames.blink_period > markers) return true;
  error = "--blink " + std::to_string(frames.blink_period) + ": " + std::to_string(markers) +
          " markers need a period of at least " + std::to_string(markers + 1) +
          " frames (each marker dark in one, and one with all lit)";
  return false;
}

}  // namespace mirrorcal::app
