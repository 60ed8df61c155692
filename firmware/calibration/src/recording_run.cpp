#include "mirrorcal/calibration/recording_run.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numeric>
#include <tuple>
#include <utility>
#include <vector>

#include "mirrorcal/calibration/image_markers.hpp"

namespace mirrorcal::calibration {

CalibrationConfig recording_config(const io::Recording& r) {
  CalibrationConfig c;
  c.gravity_n = r.priors.gravity_n;
  c.imu = r.sensors.imu;
  c.pixel_sigma = r.priors.pixel_sigma;
  c.intrinsics = r.sensors.intrinsics;
  return c;
}

namespace {

// Which of the truth's markers each name is (led[i]: the truth's index of the LED named i): those
// nearest to the shape the look fitted (LedNaming; the identity without one), as identical LEDs
// may be named otherwise than the truth: the estimate of marker i is judged against that LED.
std::vector<std::size_t> truth_order_of_names(const std::vector<Eigen::Vector3d>& truth_c,
                                              const LedNaming* naming) {
  std::vector<std::size_t> led(truth_c.size()), best;
  std::iota(led.begin(), led.end(), std::size_t{0});
  if (naming == nullptr || naming->shape_c.size() != truth_c.size()) return led;
  double least = INFINITY;
  do {
    double d = 0.0;
    for (std::size_t i = 0; i < led.size(); ++i)
      d += (naming->shape_c[i] - truth_c[led[i]]).squaredNorm();
    if (d < least) std::tie(least, best) = std::make_pair(d, led);
  } while (std::next_permutation(led.begin(), led.end()));
  return best;
}

}  // namespace

LoopData recording_loop_data(const io::Recording& r) {
  LoopData d;
  d.imu = r.imu;
  d.frames = r.frames;
  d.streams = r.streams;
  d.stats = r.stats;
  d.imu_period_ns = imu_period_ns(r.sensors.imu_rate_hz);
  d.width = r.sensors.width;
  d.height = r.sensors.height;
  if (r.from_images) {
    d.image_detection = std::make_shared<DetectionReport>();
    d.image_blobs = std::make_shared<ImageBlobs>();
  }
  d.leds = r.priors.leds;
  return d;
}

template <int M, int NK, int NI>
bool calibrate_recording(const io::Recording& r, CalibrationRun<M, NK, NI>& run, std::string& error,
                         const std::function<void(double)>& progress,
                         const io::CalibrationStart* from, Passes passes) {
  Prior<M> prior;
  if (!io::to_prior(r.priors, prior, error)) return false;
  prior.sigma_imu_intrinsics = r.sensors.imu_tolerances;
  typename CalibrationRun<M, NK, NI>::State x0;
  // On the heap: beside the run the pipeline returns, the largest filters' covariance (M = 6 with
  // the lens and the IMU's intrinsics) outgrew the 64 KiB a stack frame is held to.
  const auto p0 = std::make_unique<typename CalibrationRun<M, NK, NI>::Filter::Covariance>();
  initialise(prior, x0, *p0);
  if (from != nullptr) start_from(*from, x0, *p0);  // read_calibration_start checked its M
  const CalibrationConfig config = recording_config(r);
  LoopData data = recording_loop_data(r);
  if (data.image_detection && r.priors.leds.blink_period == 0) {
    // The names a look at the first images gives the reflections' tracks by the rig's shape,
    // which every pass then labels by (sim --frames makes the same look).
    const auto images = r.streams->open_images();
    detection::RigGeometry<M> g =
        detection::prior_geometry(prior, config.intrinsics, config.pixel_sigma);
    if (from != nullptr) {  // the markers as the earlier calibration left them, and their sigma
      using State = typename CalibrationRun<M, NK, NI>::State;
      const IndexRange markers = State::kCalibration[CalibrationGroup::kMarkers];
      g.marker_sigma_m = 0.0;
      for (int j = markers.begin; j < markers.end(); ++j)
        g.marker_sigma_m =
            std::max(g.marker_sigma_m,
                     std::sqrt((*p0)(State::kCalibrationBegin + j, State::kCalibrationBegin + j)));
      for (int i = 0; i < M; ++i)
        g.markers_c[std::size_t(i)] = x0.markers.template segment<3>(3 * i);
    }
    data.led_naming = std::make_shared<LedNaming>(
        name_leds_by_shape<M>(*images, r.priors.leds, g, data.width, data.height));
  }
  // A simulated recording's truth: each history row gets the error and NEES against it.
  typename CalibrationRun<M, NK, NI>::State truth;
  if (r.has_truth) {
    if (r.truth.features_c.size() != static_cast<std::size_t>(M)) {
      error = "truth.yaml lists " + std::to_string(r.truth.features_c.size()) +
              " markers and mirrorcal.yaml " + std::to_string(M);
      return false;
    }
    truth.p_b_c = r.truth.p_b_c;
    truth.q_b_c = r.truth.q_b_c;
    const std::vector<std::size_t> led =
        truth_order_of_names(r.truth.features_c, data.led_naming.get());
    for (int i = 0; i < M; ++i)
      truth.markers.template segment<3>(3 * i) =
          r.truth.features_c[led[static_cast<std::size_t>(i)]];
    truth.t_d = r.truth.t_d;
    if constexpr (NK > 0) {
      // truth.yaml names the lens's coefficients when camchain.yaml holds a guess of them;
      // otherwise a simulated recording's camchain.yaml holds the true ones.
      Pinhole<double> k = r.truth.intrinsics;
      if (!r.truth.has_distortion) k.coeffs = r.sensors.intrinsics.coeffs;
      const std::array<double, NK> v = camera_parameters<NK>(k);
      for (int j = 0; j < NK; ++j) truth.intrinsics(j) = v[static_cast<std::size_t>(j)];
    }
  }
  passes.imu_tolerances = r.sensors.imu_tolerances;  // the ideal-IMU check's prior
  run = run_loop<M, NK, NI>(config, x0, *p0, data, r.has_truth ? &truth : nullptr, progress, {},
                            passes);
  if (from != nullptr) note_start(*from, run.result);
  if (r.streams && !r.streams->error().empty()) {
    error = r.streams->error();
    return false;
  }
  if (data.image_detection) {  // the markers the detection labelled are the data's
    run.detection = *data.image_detection;
    run.features_found = true;
    run.result.markers_observed = run.detection.markers_labelled;
    run.result.detection = detection_counts(run.detection);
  }
  run.result.rostopic = r.sensors.rostopic;
  run.result.recording_fingerprint = r.fingerprint;
  return true;
}

#define MIRRORCAL_CALIBRATE_RECORDING_(M, NK, NI) template MIRRORCAL_CALIBRATE_RECORDING(M, NK, NI);
MIRRORCAL_FOR_EACH_FILTER(MIRRORCAL_CALIBRATE_RECORDING_)
#undef MIRRORCAL_CALIBRATE_RECORDING_

}  // namespace mirrorcal::calibration
