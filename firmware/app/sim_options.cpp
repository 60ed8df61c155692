#include "sim_options.hpp"

#include <cstdlib>
#include <string>

namespace mirrorcal::app {

FrameMode frame_mode_option(const Options& o) {
  FrameMode frames;
  frames.enabled = o.flag("frames");
  const std::string format = o.get("format", "grey");
  if (format == "yuyv")
    frames.format = hal::PixelFormat::kYuyv;
  else if (format != "grey")
    fail("--format: '" + format + "' is not a pixel format (grey or yuyv)");
  if (o.flag("format") && !frames.enabled) fail("--format applies to --frames only");
  const auto pixels = [&](const char* key, double& value, bool zero_allowed) {
    if (!o.flag(key)) return;
    if (!frames.enabled) fail(std::string("--") + key + " applies to --frames only");
    const std::string text = o.get(key, "");
    char* end = nullptr;
    value = std::strtod(text.c_str(), &end);
    if (end == text.c_str() || *end != '\0' || !(value > 0.0 || (zero_allowed && value == 0.0)))
      fail(std::string("--") + key + ": '" + text + "' is not a " +
           (zero_allowed ? "non-negative" : "positive") + " number of pixels");
  };
  pixels("spot-noise", frames.spot_noise_px, true);
  pixels("pixel-sigma", frames.pixel_sigma, false);
  return frames;
}

}  // namespace mirrorcal::app
