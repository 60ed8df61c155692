// Uses the installed filter as another project would: one second of a rig at rest, after which the
// estimate is still at rest and the covariance of its position has grown with the IMU's noise.
#include <cstdio>

#include "mirrorcal/estimator/calibration_filter.hpp"
#include "mirrorcal/estimator/prior.hpp"
#include "mirrorcal/loop/timing.hpp"

int main() {
  using Filter = mirrorcal::CalibrationFilter<double, 3, 0>;
  mirrorcal::CalibrationConfig config;
  Filter filter(config);
  mirrorcal::Prior<3> prior;
  for (auto& sigma : prior.sigma_markers) sigma = Eigen::Vector3d::Constant(0.05);
  Filter::State x;
  Filter::Covariance p;
  mirrorcal::initialise(prior, x, p);
  filter.reset(x, p);
  const double p0 = filter.covariance()(Filter::State::kP, Filter::State::kP);
  mirrorcal::ImuSample before, now;
  before.accel = now.accel = -config.gravity_n;  // at rest, level: the specific force opposes g
  for (int k = 1; k <= 200; ++k) {
    now.t_ns = k * 5'000'000;
    if (filter.predict(before, now) != mirrorcal::FilterStatus::kOk) {
      std::fprintf(stderr, "predict failed at step %d\n", k);
      return 1;
    }
    before = now;
  }
  const double p1 = filter.covariance()(Filter::State::kP, Filter::State::kP);
  const double drift = filter.state().p.norm();
  std::printf("position sigma %.4f -> %.4f m, drift %.2e m\n", std::sqrt(p0), std::sqrt(p1), drift);
  return p1 > p0 && drift < 1e-6 ? 0 : 1;
}
