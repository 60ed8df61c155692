// The random scenario family: every draw is a rig docs/scenarios.md's "The `random` family"
// describes, its motion's body rate is the derivative of its attitude, and the camera sees the
// markers. A rolling shutter and a long exposure: the simulator's reflections and the estimator's
// model of them agree.
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>

#include "mirrorcal/estimator/mirror_model.hpp"
#include "mirrorcal/estimator/so3.hpp"
#include "mirrorcal/sim/frame_renderer.hpp"
#include "mirrorcal/sim/scenario.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mirrorcal::sim {
namespace {

constexpr double kDeg = M_PI / 180.0;

TEST(RandomFamily, EveryDrawIsARigTheDocsDescribe) {
  std::set<std::string> mirrors, motions;
  for (std::uint64_t seed = 0; seed < 300; ++seed) {
    const Scenario s = random_scenario(seed);
    SCOPED_TRACE("seed " + std::to_string(seed));
    const Rig& r = s.truth;
    EXPECT_NEAR(r.q_b_c.norm(), 1.0, 1e-12);
    EXPECT_LE(r.p_b_c.cwiseAbs().maxCoeff(), 0.08);
    ASSERT_EQ(r.markers.size(), 3u);
    for (std::size_t i = 0; i < 3; ++i) {
      const Eigen::Vector3d& m = r.markers[i];
      EXPECT_LE(m.head<2>().norm(), 0.10);
      EXPECT_GE(m.head<2>().norm(), 0.015);
      EXPECT_GE(m.z(), -0.05);
      EXPECT_LE(m.z(), 0.01);
      for (std::size_t j = 0; j < i; ++j) EXPECT_GE((m - r.markers[j]).norm(), 0.03);
    }
    EXPECT_GE(r.intrinsics.fu, 450.0);
    EXPECT_LE(r.intrinsics.fu, 900.0);
    EXPECT_LE(std::abs(r.intrinsics.fv / r.intrinsics.fu - 1.0), 0.02);
    EXPECT_LE(std::abs(r.intrinsics.cu - 319.5), 15.0);
    EXPECT_LE(std::abs(r.intrinsics.cv - 239.5), 15.0);
    EXPECT_EQ(r.intrinsics.skew, 0.0);
    // Gravity along the mirror (wall) or along its normal (floor).
    ASSERT_TRUE(s.mirror == "wall" || s.mirror == "floor") << s.mirror;
    EXPECT_EQ(s.mirror == "wall" ? s.gravity_n.z() : s.gravity_n.head<2>().norm(), 0.0);
    EXPECT_NEAR(s.gravity_n.norm(), 9.81, 1e-12);
    mirrors.insert(s.mirror);
    motions.insert(s.motion_kind);
    // The camera 0.4-0.8 m in front of the mirror (the sweeps add up to 12 cm) and facing it.
    const Kinematics k = kinematics(s.motion, 0.0);
    const Eigen::Vector3d p_n_c = k.p + k.q_n_b * r.p_b_c;
    EXPECT_GT(p_n_c.z(), 0.4 - 0.13);
    EXPECT_LT(p_n_c.z(), 0.8 + 0.13);
    const Eigen::Vector3d axis = (k.q_n_b * r.q_b_c) * Eigen::Vector3d::UnitZ();
    EXPECT_LT(axis.z(), -std::cos(60.0 * kDeg));
    EXPECT_GE(s.camera_rate_hz, 20.0);
    EXPECT_LE(s.camera_rate_hz, 60.0);
    EXPECT_GE(s.pixel_sigma, 0.25);
    EXPECT_LE(s.pixel_sigma, 1.0);
    EXPECT_GE(s.imu_noise_scale, 1.0);
    EXPECT_LE(s.imu_noise_scale, 5.0);
    EXPECT_GE(s.priors.marker, 0.03);
    EXPECT_LE(s.priors.marker, 0.10);
    EXPECT_GE(s.priors.p_b_c, 0.01);
    EXPECT_LE(s.priors.p_b_c, 0.03);
    EXPECT_GE(s.priors.rot_b_c, 2.0 * kDeg);
    EXPECT_LE(s.priors.rot_b_c, 5.0 * kDeg);
    EXPECT_EQ(s.priors.position, 0.10);
    EXPECT_EQ(s.priors.attitude, 5.0 * kDeg);
    EXPECT_EQ(s.priors.velocity, 0.2);
  }
  EXPECT_EQ(mirrors, (std::set<std::string>{"wall", "floor"}));
  EXPECT_EQ(motions, (std::set<std::string>{"slow", "fast"}));
}

TEST(RandomFamily, SameSeedSameRigOtherSeedOtherRig) {
  const Scenario a = random_scenario(7), b = random_scenario(7), c = random_scenario(8);
  EXPECT_EQ(a.truth.p_b_c, b.truth.p_b_c);
  EXPECT_EQ(a.truth.markers, b.truth.markers);
  EXPECT_NE(a.truth.p_b_c, c.truth.p_b_c);
}

// The IMU the simulator synthesises is exact only if omega_b is the attitude's derivative:
// checked against a central difference of the attitude, with the rotation about the mirror normal
// and the constant tail of the random family's motion.
TEST(RandomFamily, BodyRateIsTheDerivativeOfTheAttitude) {
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    const Scenario s = random_scenario(seed);
    for (double t : {0.0, 3.7, 21.2, 44.9}) {
      const double h = 1e-5;
      const Eigen::Quaterniond q0 = kinematics(s.motion, t - h).q_n_b,
                               q1 = kinematics(s.motion, t + h).q_n_b;
      const Eigen::Vector3d rate = so3::boxminus<double>(q1, q0) / (2.0 * h);
      EXPECT_LT((rate - kinematics(s.motion, t).omega_b).norm(), 1e-6)
          << "seed " << seed << " t " << t;
    }
  }
}

// The camera sees most reflections over the minute (the tilts take some out of the image).
TEST(RandomFamily, MostReflectionsAreInTheImage) {
  for (std::uint64_t seed = 0; seed < 10; ++seed) {
    const Scenario s = random_scenario(seed);
    const SimData d = simulate(s, seed);
    std::size_t seen = 0;
    for (const io::ObservedFrame& f : d.frames) seen += f.markers.size();
    const double share = double(seen) / double(seen + d.markers_out_of_image);
    EXPECT_GT(share, 0.5) << "seed " << seed;
  }
}

// The rig's true state at IMU time t_f, and the IMU's true signal there: what the filter would
// hold and be given at a frame, to compare its model with the simulator.
template <int M>
struct TrueAt {
  MirrorState<double, M, 0> x;
  Exposure<double> e;
  TrueAt(const Scenario& s, double t_f) {
    const Kinematics k = kinematics(s.motion, t_f);
    x.p = k.p;
    x.v = k.v;
    x.q_n_b = k.q_n_b;
    x.p_b_c = s.truth.p_b_c;
    x.q_b_c = s.truth.q_b_c;
    for (int i = 0; i < M; ++i) x.markers.template segment<3>(3 * i) = s.truth.markers[size_t(i)];
    e.gyro = k.omega_b;
    e.gyro_rate =
        (kinematics(s.motion, t_f + 1e-6).omega_b - kinematics(s.motion, t_f - 1e-6).omega_b) /
        2e-6;
    e.accel = k.q_n_b.conjugate() * (k.a - s.gravity_n);
    e.gravity_n = s.gravity_n;
  }
};

// The simulator reads each marker's row line_delay * row after the frame's stamp from the rig's
// exact motion; the estimator, at the frame's mean marker row (where the loop takes the frame),
// moves the pose on to each marker's row with the IMU's rates there. With 30 us per row the two
// agree to a small fraction of the pixel noise on the paper's fast motion and on hand-held rigs;
// the model without the shutter is up to pixels off.
TEST(RollingShutter, TheModelPredictsEachMarkerAtItsRowAsTheSimulatorReadsIt) {
  constexpr int M = 3;
  for (std::uint64_t seed = 0; seed < 6; ++seed) {
    Scenario s = seed == 0 ? paper_scenario() : random_scenario(seed);
    s.truth.t_d = 0.0;
    s.truth.intrinsics.line_delay_s = 30e-6;
    double worst_modelled = 0.0, worst_global = 0.0;
    for (std::uint64_t j = 0; j < frame_count(s); j += 7) {
      const std::int64_t stamp = frame_time_ns(s, j);
      MarkerFrame<M> frame;
      frame.t_ns = stamp;
      for (int i = 0; i < M; ++i) frame.seen[i] = true_pixel(s, stamp, i, frame.uv[i]);
      // The filter's time: the stamp plus the mean row's readout; the true state there.
      const double t_f = stamp * 1e-9 + 30e-6 * readout_anchor_row(frame);
      TrueAt<M> at(s, t_f);
      at.e.stamp_minus_filter_s = stamp * 1e-9 - t_f;
      const auto compare = [&](const std::array<double, M>& readout, double& worst) {
        Eigen::Matrix<double, 2 * M, 1> z;
        std::array<bool, M> ok = frame.seen;
        predict_markers(at.x, s.truth.intrinsics, at.e, readout, z, ok);
        for (int i = 0; i < M; ++i)
          if (frame.seen[i] && ok[i])
            worst = std::max(worst, (z.segment<2>(2 * i) - frame.uv[i]).norm());
      };
      compare(marker_readout_s(s.truth.intrinsics, frame), worst_modelled);
      std::array<double, M> at_the_mean_row;
      at_the_mean_row.fill(t_f - stamp * 1e-9);
      compare(at_the_mean_row, worst_global);
    }
    std::printf("seed %llu: worst pixel error %.4f px modelled, %.2f px as a global shutter\n",
                static_cast<unsigned long long>(seed), worst_modelled, worst_global);
    EXPECT_LT(worst_modelled, 0.02) << "seed " << seed;
    EXPECT_LT(worst_modelled, 0.1 * worst_global) << "seed " << seed;
  }
}

// A spot smeared over the exposure has its centroid at the mean of its projection over it. The
// model's two-point mean agrees with the simulator's reflection averaged over 401 instants of an
// 8 ms exposure to a ten-thousandth of a pixel on fast and hand-held rigs, where the projection at
// the exposure's middle, as the model took it before, is off by the image's acceleration times
// exposure^2 / 24 (a hundredth of a pixel or more on brisk motion, the same way in every frame).
TEST(Exposure, TheModelPredictsTheMeanOfTheReflectionOverTheExposure) {
  constexpr int M = 3;
  constexpr double kExposure = 0.008;
  constexpr int kInstants = 401;
  for (std::uint64_t seed = 0; seed < 6; ++seed) {
    Scenario s = seed == 0 ? paper_scenario() : random_scenario(seed);
    s.truth.t_d = 0.0;
    s.truth.intrinsics.line_delay_s = 0.0;
    Pinhole<double> exposed = s.truth.intrinsics;
    exposed.exposure_s = kExposure;
    double worst_modelled = 0.0, worst_middle = 0.0;
    for (std::uint64_t j = 0; j < frame_count(s); j += 10) {
      const std::int64_t stamp = frame_time_ns(s, j);
      MarkerFrame<M> frame;  // the mean of the true reflection over the exposure
      for (int i = 0; i < M; ++i) {
        frame.seen[i] = true;
        frame.uv[i].setZero();
        for (int k = 0; k < kInstants && frame.seen[i]; ++k) {
          const double dt = kExposure * (double(k) / (kInstants - 1) - 0.5);
          Eigen::Vector2d uv;
          frame.seen[i] = true_pixel(s, stamp + std::llround(dt * 1e9), i, uv);
          // The trapezoid rule: the end instants weigh half.
          frame.uv[i] += (k == 0 || k == kInstants - 1 ? 0.5 : 1.0) / (kInstants - 1) * uv;
        }
      }
      const TrueAt<M> at(s, stamp * 1e-9);
      const auto compare = [&](const Pinhole<double>& k, double& worst) {
        Eigen::Matrix<double, 2 * M, 1> z;
        std::array<bool, M> ok = frame.seen;
        predict_markers(at.x, k, at.e, std::array<double, M>{}, z, ok);
        for (int i = 0; i < M; ++i)
          if (frame.seen[i] && ok[i])
            worst = std::max(worst, (z.segment<2>(2 * i) - frame.uv[i]).norm());
      };
      compare(exposed, worst_modelled);
      compare(s.truth.intrinsics, worst_middle);
    }
    std::printf(
        "seed %llu (%s motion): worst pixel error %.5f px modelled, %.4f px at the middle\n",
        static_cast<unsigned long long>(seed), s.motion_kind.c_str(), worst_modelled, worst_middle);
    EXPECT_LT(worst_modelled, 1e-4) << "seed " << seed;
    EXPECT_LT(worst_modelled, 0.1 * worst_middle) << "seed " << seed;
  }
}

// The mems family's stated noise (docs/scenarios.md): each of the three factors 0.5-5 times the
// truth, log-uniform (about half below 1.58, the range's geometric middle), the truth untouched and
// every other draw the random family's.
TEST(MemsFamily, TheStatedNoiseIsHalfToFiveTimesTheTruthAndChangesNoOtherDraw) {
  constexpr int kRigs = 200;
  int below_middle = 0;
  for (std::uint64_t seed = 1; seed <= kRigs; ++seed) {
    const Scenario r = random_scenario(seed), m = mems_scenario(seed);
    ASSERT_FALSE(r.told_imu.has_value());
    ASSERT_TRUE(m.told_imu.has_value() && m.told_pixel_sigma.has_value());
    EXPECT_EQ(m.imu.gyro_noise_density, r.imu.gyro_noise_density);
    EXPECT_EQ(m.imu.accel_noise_density, r.imu.accel_noise_density);
    EXPECT_EQ(m.pixel_sigma, r.pixel_sigma);
    EXPECT_EQ(m.truth.p_b_c, r.truth.p_b_c);
    EXPECT_EQ(m.truth.t_d, r.truth.t_d);
    EXPECT_EQ(m.camera_rate_hz, r.camera_rate_hz);
    const double g = m.told_imu->gyro_noise_density / m.imu.gyro_noise_density;
    const double a = m.told_imu->accel_noise_density / m.imu.accel_noise_density;
    const double p = *m.told_pixel_sigma / m.pixel_sigma;
    for (const double f : {g, a, p}) {
      EXPECT_GE(f, 0.5);
      EXPECT_LE(f, 5.0);
      below_middle += f < std::sqrt(0.5 * 5.0) ? 1 : 0;
    }
    // Each random walk goes with its density.
    EXPECT_NEAR(m.told_imu->gyro_random_walk / m.imu.gyro_random_walk, g, 1e-12);
    EXPECT_NEAR(m.told_imu->accel_random_walk / m.imu.accel_random_walk, a, 1e-12);
  }
  EXPECT_GT(below_middle, 3 * kRigs / 2 - 60);  // binomial(600, 1/2): 300 +- 12
  EXPECT_LT(below_middle, 3 * kRigs / 2 + 60);
}

}  // namespace
}  // namespace mirrorcal::sim
