// Noise-free IMU integration (propagate_imu) against an analytic trajectory: without the sample
// before the interval, the error stays within the bound of a second-order scheme and falls as dt^2;
// with it (the parabola through three samples, Runge-Kutta 4), it falls as dt^3.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <utility>

#include "mirrorcal/estimator/mirror_model.hpp"
#include "test_support.hpp"

namespace mirrorcal {
namespace {

using test::SineTrajectory;

// Every axis moves and rotates at a different frequency, with rotations up to 0.8 rad so that the
// coning (non-commuting) part of the attitude integration matters.
SineTrajectory lively_trajectory() {
  SineTrajectory tr;
  tr.gravity_n = Eigen::Vector3d(0.0, -9.81, 0.0);
  tr.q0 = test::rotvec(Eigen::Vector3d(0.3, -1.2, 0.5));
  tr.p0 = Eigen::Vector3d(0.2, -0.1, 0.8);
  tr.pa = Eigen::Vector3d(0.5, 0.3, 0.4);
  tr.pw = Eigen::Vector3d(1.3, 2.1, 2.9);
  tr.pph = Eigen::Vector3d(0.1, 0.7, 1.9);
  tr.ra = Eigen::Vector3d(0.6, 0.4, 0.8);
  tr.rw = Eigen::Vector3d(1.1, 1.9, 2.6);
  tr.rph = Eigen::Vector3d(0.4, 2.2, 1.3);
  return tr;
}

// The truth generator itself: the body rate and specific force are the derivatives of the pose.
TEST(ImuTruth, RatesAreDerivativesOfThePose) {
  const SineTrajectory tr = lively_trajectory();
  const double h = 1e-5;
  for (double t = 0.0; t < 10.0; t += 0.37) {
    // q_dot = 1/2 q (0, w)  =>  w = 2 vec(q^* q_dot).
    Eigen::Quaterniond qp = tr.attitude(t + h), qm = tr.attitude(t - h), q = tr.attitude(t);
    if (qp.dot(q) < 0) qp.coeffs() = -qp.coeffs();
    if (qm.dot(q) < 0) qm.coeffs() = -qm.coeffs();
    Eigen::Quaterniond q_dot;
    q_dot.coeffs() = (qp.coeffs() - qm.coeffs()) / (2.0 * h);
    const Eigen::Vector3d w_fd = 2.0 * (q.conjugate() * q_dot).vec();
    EXPECT_LT((w_fd - tr.body_rate(t)).norm(), 1e-8) << "t=" << t;
    const Eigen::Vector3d v_fd = (tr.position(t + h) - tr.position(t - h)) / (2.0 * h);
    EXPECT_LT((v_fd - tr.velocity(t)).norm(), 1e-8);
    const Eigen::Vector3d a_fd = (tr.velocity(t + h) - tr.velocity(t - h)) / (2.0 * h);
    EXPECT_LT((a_fd - tr.acceleration(t)).norm(), 1e-8);
  }
}

struct RunErrors {
  double att_final = 0, vel_final = 0, pos_final = 0;  // rad, m/s, m at the end
  double att_max = 0, vel_max = 0, pos_max = 0;        // over the run, on a common 100 Hz grid
};

RunErrors integrate(const SineTrajectory& tr, int rate_hz, double duration_s,
                    const Eigen::Vector3d& b_g = Eigen::Vector3d::Zero(),
                    const Eigen::Vector3d& b_a = Eigen::Vector3d::Zero(), bool parabola = false) {
  const std::int64_t dt_ns = 1000000000LL / rate_hz;
  const int steps = static_cast<int>(std::lround(duration_s * rate_hz));
  const int stride = rate_hz / 100;  // compare on a common 100 Hz grid
  MirrorState<double, 1, 0> x;
  x.p = tr.position(0.0);
  x.v = tr.velocity(0.0);
  x.q_n_b = tr.attitude(0.0);
  x.b_g = b_g;
  x.b_a = b_a;
  RunErrors e;
  ImuSample s0 = tr.imu(0);
  s0.gyro += b_g;
  s0.accel += b_a;
  // The sample before the first one, as a sensor running before the filter starts would give.
  ImuSample before = tr.imu(-dt_ns);
  before.gyro += b_g;
  before.accel += b_a;
  for (int k = 1; k <= steps; ++k) {
    ImuSample s1 = tr.imu(k * dt_ns);
    s1.gyro += b_g;
    s1.accel += b_a;
    propagate_imu(x, s0, s1, tr.gravity_n, parabola ? &before : nullptr);
    before = s0;
    s0 = s1;
    if (k % stride != 0 && k != steps) continue;
    const double t = static_cast<double>(k * dt_ns) * 1e-9;
    e.att_final = Eigen::AngleAxisd(tr.attitude(t).conjugate() * x.q_n_b).angle();
    e.vel_final = (x.v - tr.velocity(t)).norm();
    e.pos_final = (x.p - tr.position(t)).norm();
    e.att_max = std::max(e.att_max, e.att_final);
    e.vel_max = std::max(e.vel_max, e.vel_final);
    e.pos_max = std::max(e.pos_max, e.pos_final);
  }
  return e;
}

// Largest |omega_ddot| (rad/s^3), |p''''| (m/s^4) and |f| (m/s^2) over [0, T], on a dense grid;
// omega_ddot by a central difference (h = 1e-3, truncation ~h^2/12 |omega''''| ~ 1e-6).
void trajectory_constants(const SineTrajectory& tr, double duration, double& w_dd, double& p4,
                          double& f_max) {
  w_dd = p4 = f_max = 0.0;
  const double h = 1e-3;
  for (double t = 0.0; t <= duration; t += 1e-3) {
    const Eigen::Vector3d wdd =
        (tr.body_rate(t + h) - 2.0 * tr.body_rate(t) + tr.body_rate(t - h)) / (h * h);
    w_dd = std::max(w_dd, wdd.norm());
    const Eigen::Vector3d w4 = tr.pw.cwiseProduct(tr.pw).cwiseProduct(tr.pw).cwiseProduct(tr.pw);
    p4 = std::max(
        p4,
        tr.pa.cwiseProduct(w4).cwiseProduct((tr.pw * t + tr.pph).array().sin().matrix()).norm());
    f_max = std::max(f_max, tr.specific_force(t).norm());
  }
}

// Error bound of the second-order scheme in propagate_imu (leading order in dt):
//  - attitude: the step's rotation vector is the trapezoid of omega plus the exact two-sample
//    coning term, so its local error is the trapezoid rule's dt^3/12 |omega''| (the Magnus terms
//    beyond the coning one are O(dt^4)). Right-perturbation errors are rotated, not amplified, so
//    the norms add over T/dt steps: e_theta(t) <= t dt^2/12 max|omega''|.
//  - velocity: the trapezoid of a_n = R f + g has local error dt^3/12 |a_n''| = dt^3/12 |p''''|;
//    the attitude error tilts f by e_theta(t), adding |f| e_theta(t) per unit time:
//    e_v(T) <= T dt^2/12 max|p''''| + max|f| T^2 dt^2/24 max|omega''|.
//  - position: dt v + dt^2 (2 a0 + a1)/6 is exact for linear a (local error O(dt^4)), so the
//    position error is the integral of the velocity error:
//    e_p(T) <= T^2 dt^2/24 max|p''''| + max|f| T^3 dt^2/72 max|omega''|.
// These are worst cases (errors added in norm, never cancelling); the neglected terms are a
// factor O(dt |omega|) ~ 1e-2 smaller, covered by the 1.1 below.
TEST(ImuPropagation, SecondOrderErrorBoundOnAnalyticTrajectory) {
  const SineTrajectory tr = lively_trajectory();
  const double duration = 10.0, dt = 1.0 / 200.0;
  double w_dd, p4, f_max;
  trajectory_constants(tr, duration, w_dd, p4, f_max);
  const double att_bound = 1.1 * duration * dt * dt / 12.0 * w_dd;
  const double vel_bound =
      1.1 * (duration * dt * dt / 12.0 * p4 + f_max * duration * duration * dt * dt / 24.0 * w_dd);
  const double pos_bound = 1.1 * (duration * duration * dt * dt / 24.0 * p4 +
                                  f_max * duration * duration * duration * dt * dt / 72.0 * w_dd);

  const RunErrors e = integrate(tr, 200, duration);
  std::printf("max|w''| = %.3f rad/s^3, max|p''''| = %.3f m/s^4, max|f| = %.3f m/s^2\n", w_dd, p4,
              f_max);
  std::printf(
      "200 Hz, 10 s: attitude %.3e rad (bound %.3e), velocity %.3e m/s (bound %.3e), "
      "position %.3e m (bound %.3e)\n",
      e.att_max, att_bound, e.vel_max, vel_bound, e.pos_max, pos_bound);
  EXPECT_LT(e.att_max, att_bound);
  EXPECT_LT(e.vel_max, vel_bound);
  EXPECT_LT(e.pos_max, pos_bound);
  // The design's accuracy target: far below the paper's 0.01 deg on the attitude.
  EXPECT_LT(e.att_max, 0.01 * test::kDeg);
}

// Halving dt divides a second-order scheme's error by 4; a first-order one would give 2.
TEST(ImuPropagation, ErrorFallsAsDtSquared) {
  const SineTrajectory tr = lively_trajectory();
  const RunErrors e100 = integrate(tr, 100, 10.0);
  const RunErrors e200 = integrate(tr, 200, 10.0);
  const RunErrors e400 = integrate(tr, 400, 10.0);
  const auto report = [](const char* what, double a, double b, double c) {
    std::printf("%-16s 100 Hz %.3e  200 Hz %.3e  400 Hz %.3e  ratios %.2f %.2f\n", what, a, b, c,
                a / b, b / c);
  };
  report("attitude final", e100.att_final, e200.att_final, e400.att_final);
  report("velocity final", e100.vel_final, e200.vel_final, e400.vel_final);
  report("position final", e100.pos_final, e200.pos_final, e400.pos_final);
  report("attitude max", e100.att_max, e200.att_max, e400.att_max);
  report("velocity max", e100.vel_max, e200.vel_max, e400.vel_max);
  report("position max", e100.pos_max, e200.pos_max, e400.pos_max);
  for (const auto& [coarse, fine] : {std::pair{e100, e200}, std::pair{e200, e400}}) {
    for (const auto& [a, b] :
         {std::pair{coarse.att_final, fine.att_final}, std::pair{coarse.vel_final, fine.vel_final},
          std::pair{coarse.pos_final, fine.pos_final}, std::pair{coarse.att_max, fine.att_max},
          std::pair{coarse.vel_max, fine.vel_max}, std::pair{coarse.pos_max, fine.pos_max}}) {
      EXPECT_GT(a / b, 3.0);
      EXPECT_LT(a / b, 5.0);
    }
  }
}

// With the parabola through three samples, halving dt divides the error by about 8 (the signal's
// reconstruction error is O(dt^3) per unit time; Runge-Kutta's own is O(dt^4)), and at 200 Hz the
// error is far below the second-order scheme's.
TEST(ImuPropagation, ParabolaThroughThreeSamplesFallsAsDtCubed) {
  const SineTrajectory tr = lively_trajectory();
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  const RunErrors e100 = integrate(tr, 100, 10.0, zero, zero, true);
  const RunErrors e200 = integrate(tr, 200, 10.0, zero, zero, true);
  const RunErrors e400 = integrate(tr, 400, 10.0, zero, zero, true);
  const RunErrors second = integrate(tr, 200, 10.0);
  std::printf(
      "parabola+RK4 max errors: attitude %.3e %.3e %.3e rad, position %.3e %.3e %.3e m "
      "(second order at 200 Hz: %.3e rad, %.3e m)\n",
      e100.att_max, e200.att_max, e400.att_max, e100.pos_max, e200.pos_max, e400.pos_max,
      second.att_max, second.pos_max);
  for (const auto& [coarse, fine] : {std::pair{e100, e200}, std::pair{e200, e400}}) {
    for (const auto& [a, b] :
         {std::pair{coarse.att_max, fine.att_max}, std::pair{coarse.vel_max, fine.vel_max},
          std::pair{coarse.pos_max, fine.pos_max}}) {
      EXPECT_GT(a / b, 6.0);
      EXPECT_LT(a / b, 10.0);
    }
  }
  EXPECT_LT(e200.att_max, 0.1 * second.att_max);
  EXPECT_LT(e200.vel_max, 0.1 * second.vel_max);
  EXPECT_LT(e200.pos_max, 0.1 * second.pos_max);
}

// imu_signal_at reproduces a quadratic signal exactly from three of its samples, anywhere between
// them, with any spacing; and three samples taken from it give back the same parabola (so a frame
// time may split an interval).
TEST(ImuSignal, ParabolaThroughThreeSamplesIsExactForQuadratics) {
  const auto quad = [](std::int64_t t_ns) {
    const double t = static_cast<double>(t_ns) * 1e-9;
    ImuSample s;
    s.t_ns = t_ns;
    s.gyro = Eigen::Vector3d(0.3 + 2.0 * t - 40.0 * t * t, -1.0 + 5.0 * t * t, 0.7 * t);
    s.accel = Eigen::Vector3d(9.0 - 300.0 * t * t, 1.5 * t, -2.0 + 80.0 * t * t);
    return s;
  };
  const ImuSample b = quad(-4'000'000), a = quad(1'000'000), c = quad(6'500'000);
  for (std::int64_t t = a.t_ns; t <= c.t_ns; t += 250'000) {
    const ImuSample got = imu_signal_at(&b, a, c, t), want = quad(t);
    EXPECT_LT((got.gyro - want.gyro).norm(), 1e-12) << t;
    EXPECT_LT((got.accel - want.accel).norm(), 1e-12) << t;
  }
  // Split at a point of the parabola: the pieces see the same signal.
  const ImuSample mid = imu_signal_at(&b, a, c, 2'300'000);
  for (std::int64_t t = mid.t_ns; t <= c.t_ns; t += 100'000)
    EXPECT_LT((imu_signal_at(&a, mid, c, t).accel - quad(t).accel).norm(), 1e-10) << t;
  // Without the third sample: the straight line.
  const ImuSample lin = imu_signal_at(nullptr, a, c, (a.t_ns + c.t_ns) / 2);
  EXPECT_LT((lin.gyro - 0.5 * (a.gyro + c.gyro)).norm(), 1e-15);
}

TEST(ImuPropagation, KnownBiasesAreRemoved) {
  const SineTrajectory tr = lively_trajectory();
  const RunErrors clean = integrate(tr, 200, 2.0);
  const RunErrors biased =
      integrate(tr, 200, 2.0, Eigen::Vector3d(0.01, -0.02, 0.03), Eigen::Vector3d(0.2, 0.1, -0.3));
  EXPECT_NEAR(biased.att_max, clean.att_max, 1e-12);
  EXPECT_NEAR(biased.vel_max, clean.vel_max, 1e-11);
  EXPECT_NEAR(biased.pos_max, clean.pos_max, 1e-11);
}

// The attitude stays a unit quaternion over a long run with fast, changing rotation.
template <typename S>
double worst_norm_error_over_long_run(int steps) {
  MirrorState<S, 1, 0> x;
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n(0.0, 3.0);
  ImuSample s0;
  s0.gyro = Eigen::Vector3d(n(rng), n(rng), n(rng));
  s0.accel = Eigen::Vector3d(0.0, 9.81, 0.0);
  const Vec3<S> g(S(0), S(-9.81), S(0));
  double worst = 0.0;
  for (int k = 1; k <= steps; ++k) {
    ImuSample s1 = s0;
    s1.t_ns = s0.t_ns + 5000000;
    s1.gyro = 0.9 * s0.gyro + 0.3 * Eigen::Vector3d(n(rng), n(rng), n(rng));
    propagate_imu(x, s0, s1, g);
    s0 = s1;
    x.v.setZero();  // keep the translation bounded; only the attitude matters here
    x.p.setZero();
    worst = std::max(worst, std::abs(static_cast<double>(x.q_n_b.norm()) - 1.0));
  }
  return worst;
}

TEST(ImuPropagation, QuaternionStaysUnitOverAMillionSteps) {
  const double worst_d = worst_norm_error_over_long_run<double>(1000000);
  const double worst_f = worst_norm_error_over_long_run<float>(1000000);
  std::printf("worst |norm - 1|: double %.2e, float %.2e\n", worst_d, worst_f);
  EXPECT_LT(worst_d, 4.0 * std::numeric_limits<double>::epsilon());
  EXPECT_LT(worst_f, 4.0 * std::numeric_limits<float>::epsilon());
}

}  // namespace
}  // namespace mirrorcal
