#include "sim_options.hpp"

#include <cstdlib>
#include <string>

namespace mirrorcal::app {

using namespace calibration;
using namespace evaluation;

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
