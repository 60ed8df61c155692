// printf into a std::string, for the texts the calibration writes (the report, imu-noise's
// summary). Internal to the calibration library.
#pragma once

#include <cstdarg>
#include <cstdio>
#include <string>

namespace mirrorcal::calibration {

inline std::string format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
inline std::string format(const char* fmt, ...) {
  va_list args, again;
  va_start(args, fmt);
  va_copy(again, args);
  const int n = std::vsnprintf(nullptr, 0, fmt, args);
  va_end(args);
  std::string text(n > 0 ? std::size_t(n) : 0, '\0');
  std::vsnprintf(text.data(), text.size() + 1, fmt, again);
  va_end(again);
  return text;
}

}  // namespace mirrorcal::calibration
