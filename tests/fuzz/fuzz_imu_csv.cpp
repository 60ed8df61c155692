// libFuzzer target: mav0/imu0/data.csv. Any input gives samples or a message, never a crash.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "mirrorcal/io/recording.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  std::vector<mirrorcal::ImuSample> imu;
  std::string error;
  const bool ok = mirrorcal::io::parse_imu_csv(text, "data.csv", imu, error);
  // What the parser promises: a message on failure, and on success finite samples in
  // strictly increasing time.
  if (ok != error.empty()) std::abort();
  if (ok)
    for (std::size_t k = 0; k < imu.size(); ++k) {
      if (!imu[k].gyro.allFinite() || !imu[k].accel.allFinite()) std::abort();
      if (k > 0 && imu[k].t_ns <= imu[k - 1].t_ns) std::abort();
    }
  return 0;
}
