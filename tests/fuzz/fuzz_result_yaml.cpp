// libFuzzer target: mirrorcal-result.yaml as `calibrate --from` reads it. Any input gives a start
// or a message naming the file, never a crash; an accepted start has a finite estimate and a
// symmetric positive definite covariance of the calibration block's size.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include <Eigen/Cholesky>

#include "mirrorcal/io/recording.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace io = mirrorcal::io;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  std::string error;
  io::CalibrationStart start;
  const bool ok = io::parse_calibration_start(text, "mirrorcal-result.yaml", start, error);
  if (ok != error.empty()) std::abort();
  if (!ok) {
    if (error.rfind("mirrorcal-result.yaml", 0) != 0) std::abort();
    return 0;
  }
  // Rows p_b_c (3), rotation (3), 3 a marker, and the time offset when the result has one.
  const long n = start.layout().size();
  const Eigen::MatrixXd& c = start.covariance;
  if (c.rows() != n || c.cols() != n || !c.allFinite()) std::abort();
  if (c.llt().info() != Eigen::Success) std::abort();
  if (!start.p_b_c.allFinite() || !start.q_b_c.coeffs().allFinite() || !std::isfinite(start.t_d))
    std::abort();
  for (const Eigen::Vector3d& m : start.features_c)
    if (!m.allFinite()) std::abort();
  return 0;
}
