// run's live feedback: each group's least-known direction and sigma against an independent
// construction, the motion advised for it, and the verdicts over a simulated calibration (uncertain
// first, converged once the sigmas stop falling, "hardly moved" for a rig held still).
#include <gtest/gtest.h>

#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "live_feedback.hpp"
#include "mirrorcal/estimator/so3.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/loop/loop.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mc = mirrorcal;
using mc::app::FeedbackGroup;
using LiveFeedback = mc::app::LiveFeedback<mc::sim::kPaperMarkers>;
using Filter = LiveFeedback::Filter;
using State = Filter::State;
// With the IMU's intrinsics: the scale-misalignment model's, in a build that has it (the board's
// cross-test has the ideal IMU's only).
constexpr int kImuIntrinsics = mc::imu_intrinsics_dim(mc::ImuModel::kScaleMisalignment);
#define SKIP_WITHOUT_THE_IMU_MODEL()        \
  if (!mc::imu_model_built(kImuIntrinsics)) \
  GTEST_SKIP() << "built without the scale-misalignment model"
template <class F>
void with_the_imu_model(F&& f) {
  mc::with_imu_model(kImuIntrinsics, [&](auto ni) {
    if constexpr (decltype(ni)::value == kImuIntrinsics) f(ni);
  });
}

namespace {

Eigen::Quaterniond random_rotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n;
  return Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized();
}

// Everything the live loop printed into a temporary file.
std::string read_all(std::FILE* f) {
  std::string text;
  std::rewind(f);
  for (int c; (c = std::fgetc(f)) != EOF;) text.push_back(static_cast<char>(c));
  return text;
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::size_t start = 0;
  for (std::size_t end; (end = text.find('\n', start)) != std::string::npos; start = end + 1)
    lines.push_back(text.substr(start, end - start));
  return lines;
}

// A scenario's calibration (the paper's by default) through the loop with the feedback as its
// sink, estimating NI of the IMU's intrinsics; motion scaled by `motion` (0: held still in front
// of the mirror), or turning about the body's x axis alone (`one_axis`). With `allocations`, the
// heap allocations the loop made once it ran.
template <int NI = 0>
std::string live_run(double motion, double seconds, long* allocations = nullptr,
                     bool one_axis = false, mc::sim::Scenario s = mc::sim::paper_scenario()) {
  using Feedback = mc::app::LiveFeedback<mc::sim::kPaperMarkers, NI>;
  using Filter = typename Feedback::Filter;
  s.duration_s = seconds;
  const auto scale = [&](std::vector<mc::sim::Sine>& terms) {
    for (mc::sim::Sine& term : terms) term.amplitude *= motion;
  };
  for (auto& axis : s.motion.position) scale(axis);
  for (auto& axis : s.motion.angles) scale(axis);
  scale(s.motion.about_normal);
  if (one_axis) {
    s.motion.angles[1].clear();
    s.motion.angles[2].clear();
    s.motion.about_normal.clear();
  }
  const mc::sim::SimData d = mc::sim::simulate(s, 5);
  Filter f(mc::evaluation::scenario_config(s));
  typename Filter::State x;
  typename Filter::Covariance p0;
  mc::initialise(mc::sim::draw_prior<mc::sim::kPaperMarkers>(s, d, 5), x, p0);
  f.reset(x, p0);
  std::FILE* out = std::tmpfile();
  EXPECT_NE(out, nullptr);
  Feedback feedback(p0, out, true);
  mc::io::VectorImuSource imu(d.imu);
  mc::io::VectorMarkerSource<mc::sim::kPaperMarkers> markers(d.frames);
  mc::loop::LoopConfig lc;
  lc.imu_period_ns = 5'000'000;
  mc::loop::CalibrationLoop<double, mc::sim::kPaperMarkers, 0, NI> loop(f, imu, markers, lc,
                                                                        &feedback);
  std::fputs("start\n", out);  // the stream's buffer is made before the loop, as run's stdout's
  mc::test::AllocCounter counting;
  loop.run();
  const auto counted = counting.stop();
  if (allocations != nullptr) *allocations = counted.total();
  const std::string text = read_all(out).substr(6);
  std::fclose(out);
  return text;
}

}  // namespace

// A block built as R diag(s^2) R^T: the worst direction is R's column of the largest s, its sigma
// that s; the camera's position is rotated from the IMU frame into the camera's.
TEST(LiveFeedback, WorstDirectionOfEachGroupIsFoundInTheCameraFrame) {
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Quaterniond q_b_c = random_rotation(rng);
    const Eigen::Matrix3d axes = random_rotation(rng).toRotationMatrix();  // in the camera frame
    const Eigen::Vector3d sigmas(0.001, 0.004, 0.002);
    const Eigen::Matrix3d block_c = axes * sigmas.cwiseAbs2().asDiagonal() * axes.transpose();
    Filter::Covariance p = Filter::Covariance::Identity() * 1e-6;
    const Filter::Covariance p0 = Filter::Covariance::Identity() * 1e-2;
    const Eigen::Matrix3d r_b_c = q_b_c.toRotationMatrix();
    p.block<3, 3>(State::kPbc, State::kPbc) = r_b_c * block_c * r_b_c.transpose();
    p.block<3, 3>(State::kPhi, State::kPhi) = block_c;
    p.block<3, 3>(State::kPi + 3, State::kPi + 3) = block_c;  // the second marker is the worst
    p(State::kTd, State::kTd) = 4e-6;
    const mc::app::CalibrationUncertainty u =
        mc::app::calibration_uncertainty<mc::sim::kPaperMarkers>(p, p0, q_b_c);
    for (int g = 0; g < 3; ++g) {
      SCOPED_TRACE(mc::app::group_name(static_cast<FeedbackGroup>(g)));
      const auto& got = u[static_cast<std::size_t>(g)];
      EXPECT_NEAR(got.sigma, 0.004, 1e-12);
      EXPECT_NEAR(std::abs(got.direction.dot(axes.col(1))), 1.0, 1e-9);
      EXPECT_NEAR(got.prior_sigma, 0.1, 1e-12);
    }
    EXPECT_NEAR(u[3].sigma, 2e-3, 1e-15);
  }
}

// A rotation about an axis informs the lever arm and the hand-eye rotation only across it: the
// advised axis is the one of the three whose cross product with the direction is longest.
TEST(LiveFeedback, RotationAdvisedIsAboutTheAxisMostAcrossTheWeakDirection) {
  const std::string about[3] = {"camera's x axis", "camera's y axis", "optical axis"};
  std::mt19937_64 rng(4);
  std::normal_distribution<double> n;
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::Vector3d d = Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
    int best = 0;
    for (int a = 1; a < 3; ++a)
      if (Eigen::Vector3d::Unit(a).cross(d).norm() > Eigen::Vector3d::Unit(best).cross(d).norm())
        best = a;
    for (FeedbackGroup g : {FeedbackGroup::kCameraPosition, FeedbackGroup::kCameraRotation})
      EXPECT_NE(std::string(mc::app::motion_advice(g, d)).find(about[best]), std::string::npos);
  }
  EXPECT_NE(
      std::string(mc::app::motion_advice(FeedbackGroup::kMarkers, Eigen::Vector3d(0.1, 0.2, 0.97)))
          .find("towards and away from the mirror"),
      std::string::npos);
  EXPECT_NE(
      std::string(mc::app::motion_advice(FeedbackGroup::kMarkers, Eigen::Vector3d(0.9, 0.3, 0.3)))
          .find("sweep across the image"),
      std::string::npos);
}

// Over the paper scenario's minute: uncertain with advice first; converged once the sigmas stop
// falling, and not before the data have had time to inform the calibration.
TEST(LiveFeedback, SaysUncertainFirstAndConvergedWhenTheSigmasStopFalling) {
  const std::vector<std::string> lines = lines_of(live_run(1.0, 90.0));
  ASSERT_GE(lines.size(), 10u);
  EXPECT_NE(lines.front().find("still uncertain: "), std::string::npos) << lines.front();
  EXPECT_NE(lines.front().find("; for the "), std::string::npos) << lines.front();
  std::size_t first_converged = lines.size();
  for (std::size_t i = 0; i < lines.size(); ++i)
    if (lines[i].find("converged") != std::string::npos) {
      first_converged = i;
      break;
    }
  ASSERT_LT(first_converged, lines.size()) << lines.back();
  EXPECT_GE(first_converged, 3u);  // not in the first windows
  // And it stays converged: the verdict does not flicker as the sigmas keep falling slowly.
  for (std::size_t i = first_converged; i < lines.size(); ++i)
    EXPECT_NE(lines[i].find("converged"), std::string::npos) << lines[i];
}

// A rig held still in front of the mirror gains nothing: the feedback says to move, never that the
// calibration converged.
TEST(LiveFeedback, ARigHeldStillIsToldToMove) {
  const std::vector<std::string> lines = lines_of(live_run(0.0, 30.0));
  ASSERT_GE(lines.size(), 3u);
  for (std::size_t i = 1; i < lines.size(); ++i) {
    EXPECT_EQ(lines[i].find("converged"), std::string::npos) << lines[i];
    EXPECT_NE(lines[i].find("hardly moved"), std::string::npos) << lines[i];
  }
}

// The feedback runs inside the loop, which never allocates after start-up.
TEST(LiveFeedback, AllocatesNothingInTheLoop) {
  ASSERT_TRUE(mc::test::alloc_counter_installed());
  long allocations = -1;
  const std::vector<std::string> lines = lines_of(live_run(1.0, 30.0, &allocations));
  EXPECT_GE(lines.size(), 5u);
  EXPECT_EQ(allocations, 0);
}

// A rig turned about one axis only tells nothing of the lever arm along it: that direction never
// falls, which must not read as converged; the feedback keeps asking for other rotations.
TEST(LiveFeedback, MotionAboutOneAxisIsNeverCalledConverged) {
  const std::vector<std::string> lines = lines_of(live_run(1.0, 90.0, nullptr, true));
  ASSERT_GE(lines.size(), 3u);
  bool asked_to_turn = false;
  for (const std::string& line : lines) {
    EXPECT_EQ(line.find("converged"), std::string::npos) << line;
    asked_to_turn = asked_to_turn || line.find("for the camera position: ") != std::string::npos;
  }
  EXPECT_TRUE(asked_to_turn) << lines.back();
}

// An IMU group's least-known intrinsic is the one with the largest sigma against its own prior,
// and the axis named is the one whose reading that entry multiplies (its column in D_a or D_g,
// found by perturbing the entry).
template <int NI>
void expect_worst_imu_intrinsic_and_its_axis() {
  using ImuFilter = typename mc::app::LiveFeedback<mc::sim::kPaperMarkers, NI>::Filter;
  using ImuState = typename ImuFilter::State;
  using Covariance = typename ImuFilter::Covariance;
  std::mt19937_64 rng(5);
  std::uniform_int_distribution<int> entry(0, NI - 1);
  for (int trial = 0; trial < 30; ++trial) {
    const int j = entry(rng);
    Covariance p0 = Covariance::Identity() * 1e-2;
    for (int i = 0; i < NI; ++i)  // the priors differ by entry: ratios, not sigmas
      p0(ImuState::kImu + i, ImuState::kImu + i) = std::pow(0.01 * (1 + i % 3), 2);
    Covariance p = p0 * 0.04;  // every entry at 20 % of its prior
    p(ImuState::kImu + j, ImuState::kImu + j) = p0(ImuState::kImu + j, ImuState::kImu + j) * 0.25;
    const mc::app::CalibrationUncertainty u =
        mc::app::calibration_uncertainty<mc::sim::kPaperMarkers, NI>(
            p, p0, Eigen::Quaterniond::Identity());
    mc::ImuIntrinsics<double> perturbed;
    Eigen::Matrix<double, NI, 1> e = Eigen::Matrix<double, NI, 1>::Zero();
    e(j) = 1.0;
    perturbed.template add<NI>(e);
    const bool accelerometer = !perturbed.d_a.isIdentity();
    const Eigen::Matrix3d moved =
        (accelerometer ? perturbed.d_a : perturbed.d_g) - Eigen::Matrix3d::Identity();
    int column = 0;
    moved.cwiseAbs().colwise().sum().maxCoeff(&column);
    const FeedbackGroup g =
        accelerometer ? FeedbackGroup::kAccelerometer : FeedbackGroup::kGyroscope;
    const auto& got = u[static_cast<std::size_t>(g)];
    SCOPED_TRACE(j);
    EXPECT_NEAR(got.sigma / got.prior_sigma, 0.5, 1e-12);
    EXPECT_NEAR(got.prior_sigma, std::sqrt(p0(ImuState::kImu + j, ImuState::kImu + j)), 1e-15);
    EXPECT_EQ(got.direction, Eigen::Vector3d::Unit(column));
    const FeedbackGroup other =
        accelerometer ? FeedbackGroup::kGyroscope : FeedbackGroup::kAccelerometer;
    EXPECT_NEAR(
        u[static_cast<std::size_t>(other)].sigma / u[static_cast<std::size_t>(other)].prior_sigma,
        0.2, 1e-12);
    const std::string advice = mc::app::motion_advice(g, got.direction);
    const char axis[] = {'x', 'y', 'z'};
    EXPECT_NE(advice.find(std::string("IMU's ") + axis[column] + " axis"), std::string::npos)
        << advice;
    EXPECT_NE(advice.find(accelerometer ? "pointing up, then down" : "rotate the rig briskly"),
              std::string::npos)
        << advice;
  }
}

TEST(LiveFeedback, WorstImuIntrinsicAndTheAxisThatInformsIt) {
  SKIP_WITHOUT_THE_IMU_MODEL();
  with_the_imu_model(
      [](auto ni) { expect_worst_imu_intrinsic_and_its_axis<decltype(ni)::value>(); });
}

// The paper's minute and a half with the IMU's intrinsics estimated: the feedback names them while
// they fall, and the verdict still comes, naming the intrinsics the motion leaves near their prior.
TEST(LiveFeedback, TheImuIntrinsicsAreNamedAndDoNotHoldBackTheVerdict) {
  SKIP_WITHOUT_THE_IMU_MODEL();
  long allocations = -1;
  std::vector<std::string> lines;
  with_the_imu_model([&](auto ni) {
    lines = lines_of(
        live_run<decltype(ni)::value>(1.0, 90.0, &allocations, false, mc::sim::paper_scenario()));
  });
  ASSERT_GE(lines.size(), 10u);
  EXPECT_EQ(allocations, 0);
  bool imu_named = false;
  for (const std::string& line : lines)
    imu_named = imu_named || line.find("'s intrinsics") != std::string::npos;
  EXPECT_TRUE(imu_named) << lines.front();
  EXPECT_NE(lines.back().find("converged"), std::string::npos) << lines.back();
  // The mirror's motion hardly sees the accelerometer's (docs/estimator.md): weak, and named so.
  EXPECT_NE(lines.back().find("accelerometer's intrinsics stay weak"), std::string::npos)
      << lines.back();
}
