// libFuzzer target: the YAML beside a recording (mirrorcal.yaml, imu.yaml, camchain.yaml,
// truth.yaml) and a result to start from (calibrate --from), each parser on the same input. Any
// input gives values or a message, never a crash. fuzz_priors_yaml and fuzz_result_yaml go deeper
// into the two files users write or edit most.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "mirrorcal/io/recording.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace io = mirrorcal::io;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  std::string error;
  std::vector<std::string> notes;
  io::RecordingPriors priors;
  bool ok =
      io::parse_priors_yaml(text, "mirrorcal.yaml", {800, 800, 320, 240, 0}, priors, notes, error);
  if (ok != error.empty()) std::abort();
  if (ok) {
    // Whatever was accepted has positive sigmas and as many sigmas as markers.
    if (!(priors.sigma_p_b_c.minCoeff() > 0) || !(priors.sigma_rot_n_b.minCoeff() > 0) ||
        !(priors.pixel_sigma > 0) || priors.features_c.size() != priors.sigma_features_c.size())
      std::abort();
    mirrorcal::Prior<3> p;
    if (io::to_prior(priors, p, error) == (priors.features_c.size() != 3)) std::abort();
  }
  io::SensorInfo sensors;
  error.clear();
  ok = io::parse_imu_yaml(text, "imu.yaml", sensors, notes, error);
  if (ok != error.empty()) std::abort();
  error.clear();
  ok = io::parse_camchain_yaml(text, "camchain.yaml", sensors, notes, error);
  if (ok != error.empty()) std::abort();
  if (ok && (sensors.width < 1 || sensors.height < 1)) std::abort();
  io::RecordingTruth truth;
  error.clear();
  ok = io::parse_truth_yaml(text, "truth.yaml", truth, error);
  if (ok != error.empty()) std::abort();
  // A start accepted for calibrate --from is a square block of the markers' size.
  io::CalibrationStart start;
  error.clear();
  ok = io::parse_calibration_start(text, "mirrorcal-result.yaml", start, error);
  if (ok != error.empty()) std::abort();
  const long n = start.layout().size();
  if (ok && (start.covariance.rows() != n || start.covariance.cols() != n)) std::abort();
  return 0;
}
