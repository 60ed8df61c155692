#include "run_config.hpp"

#include <cmath>
#include <cstdlib>
#include <set>

namespace mirrorcal::app {

const char* const kRunKeys[11] = {"imu",    "drdy",       "trigger",    "trigger-every",
                                  "camera", "sensors",    "out",        "duration",
                                  "rate",   "gyro-range", "accel-range"};

namespace {

bool number(const std::string& text, double min, double& out) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end == nullptr || *end != '\0' || !std::isfinite(v) || v < min) return false;
  out = v;
  return true;
}

std::string trim(std::string_view s) {
  const std::size_t a = s.find_first_not_of(" \t\r");
  if (a == std::string_view::npos) return "";
  const std::size_t b = s.find_last_not_of(" \t\r");
  return std::string(s.substr(a, b - a + 1));
}

}  // namespace

bool set_run_setting(RunSettings& s, const std::string& key, const std::string& value,
                     std::string& error) {
  const auto text = [&](std::string& field) {
    if (value.empty()) {
      error = key + ": empty value";
      return false;
    }
    field = value;
    return true;
  };
  const auto positive = [&](double& field, double min, const char* what) {
    if (number(value, min, field)) return true;
    error = key + ": '" + value + "' is not " + what;
    return false;
  };
  if (key == "imu") return text(s.imu);
  if (key == "drdy") return text(s.drdy);
  if (key == "trigger") return text(s.trigger);
  if (key == "trigger-every") {
    double every = 0.0;
    if (number(value, 2.0, every) && every == std::floor(every) && every <= 1e6) {
      s.trigger_every = static_cast<int>(every);
      return true;
    }
    error = key + ": '" + value +
            "' is not a whole number of IMU samples >= 2 (a pulse lasts one IMU period)";
    return false;
  }
  if (key == "camera") return text(s.camera);
  if (key == "sensors") return text(s.sensors);
  if (key == "out") return text(s.out);
  if (key == "duration") return positive(s.duration_s, 0.0, "a duration in seconds (>= 0)");
  if (key == "rate") return positive(s.rate_hz, 1e-3, "a rate in Hz (> 0)");
  if (key == "gyro-range") return positive(s.gyro_range_dps, 1e-3, "a range in deg/s (> 0)");
  if (key == "accel-range") return positive(s.accel_range_g, 1e-3, "a range in g (> 0)");
  error = "unknown key '" + key + "'";
  return false;
}

bool parse_run_config(std::string_view text, const std::string& file, RunSettings& s,
                      std::string& error) {
  std::set<std::string> seen;
  std::size_t line_no = 0;
  while (!text.empty()) {
    ++line_no;
    const std::size_t nl = text.find('\n');
    std::string_view line = text.substr(0, nl);
    text = nl == std::string_view::npos ? std::string_view() : text.substr(nl + 1);
    const std::string where = file + ":" + std::to_string(line_no) + ": ";
    // A '#' starts a comment where it begins a word (device paths hold none).
    for (std::size_t i = 0; i < line.size(); ++i)
      if (line[i] == '#' && (i == 0 || line[i - 1] == ' ' || line[i - 1] == '\t')) {
        line = line.substr(0, i);
        break;
      }
    if (trim(line).empty()) continue;
    const std::size_t colon = line.find(':');
    if (colon == std::string_view::npos ||
        trim(line.substr(0, colon)).find_first_of(" \t") != std::string::npos ||
        trim(line.substr(0, colon)).empty()) {
      error = where + "expected `key: value`, got '" + trim(line) + "'";
      return false;
    }
    const std::string key = trim(line.substr(0, colon));
    std::string value = trim(line.substr(colon + 1));
    if (value.size() >= 2 && (value.front() == '"' || value.front() == '\'') &&
        value.back() == value.front())
      value = value.substr(1, value.size() - 2);
    if (!seen.insert(key).second) {
      error = where + "'" + key + "' given twice";
      return false;
    }
    std::string why;
    if (!set_run_setting(s, key, value, why)) {
      error = where + why;
      return false;
    }
  }
  return true;
}

}  // namespace mirrorcal::app
