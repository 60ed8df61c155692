// The float build over a 10-minute run (the paper scenario, 200 Hz IMU, 60 Hz camera): the
// covariance stays symmetric positive definite after every frame, no predict or update is refused,
// and the calibration still ends within its uncertainty.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/loop/loop_impl.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mc = mirrorcal;
using FilterF = mc::CalibrationFilter<float, 3, 0>;

namespace {

// Checks the covariance of every published estimate, in double so that the check itself does not
// round: symmetric to float rounding, and positive definite in the float the filter computes with.
class DefinitenessSink final : public mc::loop::EstimateSink<FilterF> {
 public:
  void publish(std::int64_t, const FilterF& f) override {
    ++published;
    const FilterF::Covariance& p = f.covariance();
    const double scale = double(p.cwiseAbs().maxCoeff());
    max_asymmetry =
        std::max(max_asymmetry, double((p - p.transpose()).cwiseAbs().maxCoeff()) / scale);
    if (Eigen::LLT<FilterF::Covariance>(p).info() != Eigen::Success) ++not_positive_definite;
    min_variance = std::min(min_variance, double(p.diagonal().minCoeff()));
  }
  long published = 0, not_positive_definite = 0;
  double max_asymmetry = 0.0;  // largest |P - P^T| relative to the largest |P|
  double min_variance = INFINITY;
};

}  // namespace

TEST(FloatLongRun, StaysPositiveDefiniteForTenMinutes) {
  mc::sim::Scenario s = mc::sim::paper_scenario();
  s.duration_s = 600.0;
  const mc::sim::SimData data = mc::sim::simulate(s, 9);
  const auto prior = mc::sim::draw_prior<3>(s, data, 9);
  FilterF filter(mc::evaluation::scenario_config(s));
  FilterF::State x0;
  FilterF::Covariance p0;
  mc::initialise(prior, x0, p0);
  filter.reset(x0, p0);
  mc::io::VectorImuSource imu(data.imu);
  mc::io::VectorMarkerSource<3> markers(data.frames);
  DefinitenessSink sink;
  mc::loop::LoopConfig lc;
  mc::loop::CalibrationLoop<float, 3, 0> loop(filter, imu, markers, lc, &sink);
  ASSERT_EQ(loop.run(), mc::loop::LoopEnd::kEndOfStream);

  // What toolchain/perf-report quotes in docs/performance.md.
  std::printf(
      "float-long-run: %ld estimates over %.0f s, %ld not positive definite, "
      "largest |P - P^T| %.2e of the largest |P|, smallest variance %.3e\n",
      sink.published, s.duration_s, sink.not_positive_definite, sink.max_asymmetry,
      sink.min_variance);
  // An estimate for every frame the loop applies and the final one when the streams end: every
  // frame taken while the IMU ran, but for those within the time offset's prior (3 sigma) of either
  // end, which the filter's guess of the offset may place outside the IMU's span.
  const auto frames_within = [&](double margin_s) {
    const auto margin_ns = static_cast<std::int64_t>(margin_s * 1e9);
    return std::count_if(data.frames.begin(), data.frames.end(), [&](const auto& f) {
      return f.t_ns >= data.imu.front().t_ns + margin_ns &&
             f.t_ns <= data.imu.back().t_ns - margin_ns;
    });
  };
  EXPECT_EQ(sink.published, long(loop.counters().frames) + 1);
  EXPECT_GE(sink.published, frames_within(3.0 * s.priors.time_offset) + 1);
  EXPECT_LE(sink.published, frames_within(0.0) + 1);
  EXPECT_NEAR(double(frames_within(0.0)), s.camera_rate_hz * s.duration_s, 1.0);
  EXPECT_LT(sink.max_asymmetry, 1e-5);  // a few float epsilons
  EXPECT_EQ(sink.not_positive_definite, 0);
  EXPECT_GT(sink.min_variance, 0.0);
  EXPECT_EQ(filter.counters().failures, 0u);
  EXPECT_EQ(loop.counters().filter_failures, 0u);
  // Still a calibration: the camera position within 4 sigma of the truth on every axis.
  for (int i = 0; i < 3; ++i) {
    const double err = double(filter.state().p_b_c(i)) - s.truth.p_b_c(i);
    const double sigma =
        std::sqrt(double(filter.covariance()(FilterF::State::kPbc + i, FilterF::State::kPbc + i)));
    EXPECT_LT(std::abs(err), 4.0 * sigma) << "axis " << i << ": " << err << " m, sigma " << sigma;
  }
}
