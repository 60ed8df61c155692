// The batch maximum-likelihood reference (evaluation/batch.hpp) on its own terms: its derivatives
// against finite differences, the truth from noise-free data, bit-identical replays, and input it
// cannot solve (its errors against its covariance: batch_campaign_test.cpp).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "batch_runs.hpp"
#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/evaluation/batch.hpp"
#include "mirrorcal/evaluation/batch_factors.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"

namespace {

namespace mc = mirrorcal;
namespace ev = mirrorcal::evaluation;
namespace bf = mirrorcal::evaluation::batch;
using batch_runs::short_random;
using batch_runs::solve_simulated;
using batch_runs::Solved;
using Eigen::Quaterniond;
using Eigen::Vector3d;

// Whether f's Jacobians (autodiff, mapped onto the tangent spaces of the manifolds; nullptr:
// Euclidean) agree with central differences taken along those tangent spaces at params: in each
// parameter block, the largest difference within kRelative of the block's largest entry (an
// analytic zero comes out at rounding's 1e-14 numerically, so an entry-wise relative test would
// fail it). Ceres's GradientChecker steps each ambient coordinate by a step relative to it, which
// for a quaternion's component near zero is far below rounding. why: what disagrees.
constexpr double kRelative = 1e-6;
bool derivatives_match(const ceres::CostFunction& f,
                       const std::vector<const ceres::Manifold*>& manifolds,
                       const std::vector<const double*>& params, std::string& why) {
  const std::vector<int32_t>& sizes = f.parameter_block_sizes();
  const int rows = f.num_residuals();
  std::vector<ceres::Matrix> ambient;
  std::vector<double*> jacobians;
  for (const int32_t size : sizes) {
    ambient.emplace_back(rows, size);
    jacobians.push_back(nullptr);
  }
  // Row-major buffers, as Ceres writes them.
  std::vector<std::vector<double>> buffers;
  for (std::size_t b = 0; b < sizes.size(); ++b) {
    buffers.emplace_back(static_cast<std::size_t>(rows * sizes[b]));
    jacobians[b] = buffers[b].data();
  }
  ceres::Vector residual(rows);
  if (!f.Evaluate(params.data(), residual.data(), jacobians.data())) {
    why = "the cost function failed";
    return false;
  }
  why.clear();
  for (std::size_t b = 0; b < sizes.size(); ++b) {
    const int size = sizes[b];
    const ceres::Manifold* m = manifolds[b];
    const int tangent = m != nullptr ? m->TangentSize() : size;
    const ceres::Matrix j_ambient =
        Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
            buffers[b].data(), rows, size);
    ceres::Matrix plus = ceres::Matrix::Identity(size, tangent);
    if (m != nullptr) {
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> p(size, tangent);
      m->PlusJacobian(params[b], p.data());
      plus = p;
    }
    const ceres::Matrix j = j_ambient * plus;
    ceres::Matrix n(rows, tangent);
    for (int k = 0; k < tangent; ++k) {
      const double h = m != nullptr ? 1e-6 : 1e-6 * std::max(1.0, std::abs(params[b][k]));
      ceres::Vector delta = ceres::Vector::Zero(tangent), up(size), down(size);
      std::vector<const double*> at = params;
      ceres::Vector r_up(rows), r_down(rows);
      for (const double sign : {1.0, -1.0}) {
        delta(k) = sign * h;
        ceres::Vector& moved = sign > 0 ? up : down;
        if (m != nullptr)
          m->Plus(params[b], delta.data(), moved.data());
        else
          moved = Eigen::Map<const ceres::Vector>(params[b], size) + delta;
        at[b] = moved.data();
        if (!f.Evaluate(at.data(), (sign > 0 ? r_up : r_down).data(), nullptr)) {
          why = "the cost function failed at a step";
          return false;
        }
      }
      n.col(k) = (r_up - r_down) / (2.0 * h);
    }
    if (!j.allFinite()) why += "block " + std::to_string(b) + " has a non-finite derivative; ";
    const double scale = std::max(j.cwiseAbs().maxCoeff(), 1e-12);
    const double diff = (j - n).cwiseAbs().maxCoeff();
    if (!(diff <= kRelative * scale))
      why += "block " + std::to_string(b) + ": differs by " + std::to_string(diff / scale) +
             " of its largest entry; ";
  }
  return why.empty();
}

std::array<double, 4> coeffs_of(const Quaterniond& q) {
  return {q.x(), q.y(), q.z(), q.w()};
}

// A motion block and attitude from the scenario's true motion at t, with biases.
struct StateBlocks {
  std::array<double, bf::kMotionSize> motion{};
  std::array<double, bf::kQuatSize> q{};
};
StateBlocks state_at(const mc::sim::Scenario& s, double t) {
  const mc::sim::Kinematics k = mc::sim::kinematics(s.motion, t);
  StateBlocks b;
  const Vector3d parts[4] = {k.p, k.v, Vector3d(0.05, -0.02, 0.03), Vector3d(1e-3, -2e-3, 5e-4)};
  for (std::size_t i = 0; i < 4; ++i)
    for (std::size_t j = 0; j < 3; ++j) b.motion[3 * i + j] = parts[i](static_cast<long>(j));
  b.q = coeffs_of(k.q_n_b);
  return b;
}

TEST(BatchFactors, ImuIntegrationDerivativesMatchFiniteDifferences) {
  const mc::sim::Scenario s = mc::sim::random_scenario(3);
  const mc::sim::SimData data = mc::sim::simulate(s, 3);
  // Ten samples' pieces, the parabola's sample before each from the second on.
  std::vector<bf::ImuPiece> pieces;
  for (std::size_t j = 100; j < 110; ++j) {
    bf::ImuPiece p;
    p.s0 = data.imu[j];
    p.s1 = data.imu[j + 1];
    p.before = data.imu[j - 1];
    p.has_before = j > 100;
    pieces.push_back(p);
  }
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  bf::ImuSqrtInformation w = bf::ImuSqrtInformation::Identity() * 10.0;
  for (int i = 0; i < bf::kImuResiduals; ++i)
    for (int j = 0; j < i; ++j) w(i, j) = n(rng);  // lower triangular, as a Cholesky factor's
  const double t0 = static_cast<double>(data.imu[100].t_ns) * 1e-9;
  const double t1 = static_cast<double>(data.imu[110].t_ns) * 1e-9;
  StateBlocks a = state_at(s, t0), b = state_at(s, t1);
  std::unique_ptr<ceres::CostFunction> f(bf::ImuFactor::create(pieces, s.gravity_n, w, false));
  bf::RightQuaternionManifold q;
  std::string why;
  EXPECT_TRUE(derivatives_match(*f, {nullptr, &q, nullptr, &q},
                                {a.motion.data(), a.q.data(), b.motion.data(), b.q.data()}, why))
      << why;
  // With a MEMS part's intrinsics (scale factors, axes, g-sensitivity: every entry the block has).
  mc::sim::Scenario mems = s;
  mc::sim::add_mems_imperfections(mems, 3);
  const std::array<double, bf::kImuIntrinsicsSize> imu = bf::imu_block_of(mems.imu_intrinsics);
  std::unique_ptr<ceres::CostFunction> g(bf::ImuFactor::create(pieces, s.gravity_n, w, true));
  EXPECT_TRUE(derivatives_match(
      *g, {nullptr, &q, nullptr, &q, nullptr},
      {a.motion.data(), a.q.data(), b.motion.data(), b.q.data(), imu.data()}, why))
      << "with the IMU's intrinsics: " << why;
  // At the state the integration itself ends at: a zero rotation residual (the logarithm's
  // series at the identity, where its norm has no derivative).
  mc::MirrorState<double, 1, 0> x = bf::motion_state(a.motion.data(), a.q.data());
  for (const bf::ImuPiece& p : pieces)
    mc::propagate_imu(x, p.s0, p.s1, s.gravity_n, p.has_before ? &p.before : nullptr);
  b.q = coeffs_of(x.q_n_b);
  EXPECT_TRUE(derivatives_match(*f, {nullptr, &q, nullptr, &q},
                                {a.motion.data(), a.q.data(), b.motion.data(), b.q.data()}, why))
      << why;
}

TEST(BatchFactors, ReprojectionDerivativesMatchFiniteDifferencesForEveryCamera) {
  for (const mc::Distortion lens :
       {mc::Distortion::kNone, mc::Distortion::kRadtan, mc::Distortion::kEquidistant}) {
    for (const double line_delay : {0.0, 30e-6}) {
      mc::sim::Scenario s = mc::sim::random_scenario(5);
      mc::sim::set_lens(s, lens);
      mc::Pinhole<double> camera = s.truth.intrinsics;
      camera.line_delay_s = line_delay;
      camera.skew = 1.5;
      StateBlocks x = state_at(s, 12.3);
      const mc::sim::Kinematics k = mc::sim::kinematics(s.motion, 12.3);
      bf::FrameExposure e;
      e.stamp_minus_state_s = -0.004;
      e.gyro = k.omega_b + Vector3d(1e-3, -2e-3, 5e-4);
      e.gyro_rate = Vector3d(0.3, -0.2, 0.5);
      e.accel = k.q_n_b.conjugate() * (k.a - s.gravity_n) + Vector3d(0.05, -0.02, 0.03);
      std::unique_ptr<ceres::CostFunction> f(bf::ReprojectionFactor::create(
          e, Eigen::Vector2d(300.0, 200.0), line_delay * 200.0, camera, s.gravity_n, 0.7, false));
      std::unique_ptr<ceres::CostFunction> g(bf::ReprojectionFactor::create(
          e, Eigen::Vector2d(300.0, 200.0), line_delay * 200.0, camera, s.gravity_n, 0.7, true));
      mc::sim::Scenario mems = s;
      mc::sim::add_mems_imperfections(mems, 5);
      const std::array<double, bf::kImuIntrinsicsSize> imu = bf::imu_block_of(mems.imu_intrinsics);
      std::array<double, 3> p_b_c = {s.truth.p_b_c.x(), s.truth.p_b_c.y(), s.truth.p_b_c.z()};
      std::array<double, 4> q_b_c = coeffs_of(s.truth.q_b_c);
      const Vector3d m = s.truth.markers[1];
      std::array<double, 3> marker = {m.x(), m.y(), m.z()};
      double t_d = 0.003;
      std::array<double, bf::kCameraSize> cam = {
          camera.fu,        camera.fv,        camera.cu,        camera.cv,       camera.skew,
          camera.coeffs[0], camera.coeffs[1], camera.coeffs[2], camera.coeffs[3]};
      bf::RightQuaternionManifold q;
      std::string why;
      EXPECT_TRUE(derivatives_match(*f, {nullptr, &q, nullptr, &q, nullptr, nullptr, nullptr},
                                    {x.motion.data(), x.q.data(), p_b_c.data(), q_b_c.data(),
                                     marker.data(), &t_d, cam.data()},
                                    why))
          << mc::to_string(lens) << ", line delay " << line_delay << ": " << why;
      EXPECT_TRUE(derivatives_match(*g,
                                    {nullptr, &q, nullptr, &q, nullptr, nullptr, nullptr, nullptr},
                                    {x.motion.data(), x.q.data(), p_b_c.data(), q_b_c.data(),
                                     marker.data(), &t_d, cam.data(), imu.data()},
                                    why))
          << mc::to_string(lens) << ", line delay " << line_delay
          << ", the IMU's intrinsics: " << why;
    }
  }
}

TEST(BatchFactors, PriorDerivativesMatchFiniteDifferencesAtTheGuess) {
  const Quaterniond guess = Quaterniond(0.9, 0.1, -0.3, 0.2).normalized();
  std::array<double, 4> q = coeffs_of(guess);
  std::unique_ptr<ceres::CostFunction> rotation(
      bf::RotationPrior::create(guess, Vector3d(0.01, 0.02, 0.03)));
  bf::RightQuaternionManifold manifold;
  std::string why;
  EXPECT_TRUE(derivatives_match(*rotation, {&manifold}, {q.data()}, why)) << why;
  std::array<double, bf::kMotionSize> motion{};
  for (std::size_t j = 0; j < motion.size(); ++j) motion[j] = 0.1 * static_cast<double>(j);
  Eigen::Matrix<double, bf::kImuResiduals, 1> sigma;
  sigma.setConstant(0.02);
  std::unique_ptr<ceres::CostFunction> start(bf::StartPrior::create(motion.data(), guess, sigma));
  EXPECT_TRUE(derivatives_match(*start, {nullptr, &manifold}, {motion.data(), q.data()}, why))
      << why;
  // The residual at the guess is zero, and a rotation of the guess by d on the right reads d.
  double r[bf::kImuResiduals];
  const double* at[] = {motion.data(), q.data()};
  ASSERT_TRUE(start->Evaluate(at, r, nullptr));
  for (const double v : r) EXPECT_EQ(v, 0.0);
  const Vector3d d(0.004, -0.002, 0.006);
  std::array<double, 4> turned = coeffs_of(guess * mc::so3::exp<double>(d));
  const double* at_turned[] = {turned.data()};
  ASSERT_TRUE(rotation->Evaluate(at_turned, r, nullptr));
  EXPECT_NEAR(r[0], d.x() / 0.01, 1e-9);
  EXPECT_NEAR(r[1], d.y() / 0.02, 1e-9);
  EXPECT_NEAR(r[2], d.z() / 0.03, 1e-9);
}

// The model and the solver, apart from noise and the priors' pull: what is left is the model's
// approximations (the IMU signal's parabola, the exposure's extrapolation) and the convergence.
TEST(Batch, NoiseFreeDataGiveTheTruthToASmallFractionOfItsSigmas) {
  struct Case {
    std::uint64_t seed;
    int camera_parameters;  // NK
    mc::Distortion lens;
    mc::ImuModel imu_model;
  };
  // Stage 1 on two rigs; the camera too (fu fv cu cv skew), and with the lens's coefficients; a
  // MEMS part's IMU, its scale factors and axes estimated.
  constexpr mc::ImuModel kIdeal = mc::ImuModel::kCalibrated;
  for (const Case c :
       {Case{2, 0, mc::Distortion::kNone, kIdeal}, Case{9, 0, mc::Distortion::kNone, kIdeal},
        Case{5, 5, mc::Distortion::kNone, kIdeal}, Case{6, 8, mc::Distortion::kRadtan, kIdeal},
        Case{7, 0, mc::Distortion::kNone, mc::ImuModel::kScaleMisalignment}}) {
    mc::sim::Scenario s = short_random(c.seed, 15.0);
    mc::sim::set_lens(s, c.lens);
    if (c.imu_model != kIdeal) s = mc::sim::mems_scenario(c.seed);
    s.duration_s = 15.0;
    mc::sim::Scenario clean = s;  // the same rig and motion; no noise, no bias walk
    clean.pixel_sigma = 0.0;
    clean.imu.gyro_noise_density = clean.imu.accel_noise_density = 0.0;
    clean.imu.gyro_random_walk = clean.imu.accel_random_walk = 0.0;
    const Solved r = solve_simulated(s, mc::sim::simulate(clean, c.seed), c.seed, true,
                                     c.camera_parameters, c.imu_model);
    ASSERT_EQ(r.error.error.size(), static_cast<long>(r.result.sigma.size()));
    ASSERT_EQ(r.result.estimated_intrinsics, c.camera_parameters);
    ASSERT_EQ(r.result.imu.estimated(), c.imu_model != kIdeal);
    double worst = 0.0;
    for (std::size_t j = 0; j < r.result.sigma.size(); ++j) {
      const double off = std::abs(r.error.error(static_cast<long>(j))) / r.result.sigma[j];
      EXPECT_LT(off, 0.1) << "seed " << c.seed << ", " << r.result.params[j].name;
      worst = std::max(worst, off);
    }
    if (c.imu_model == mc::ImuModel::kScaleMisalignment) {
      Eigen::Matrix<double, 12, 1> d;
      r.result.imu.intrinsics.difference<12>(s.imu_intrinsics, d);
      ASSERT_EQ(r.result.imu.sigma.size(), 12u);
      for (int j = 0; j < 12; ++j) {
        const double off = std::abs(d(j)) / r.result.imu.sigma[static_cast<std::size_t>(j)];
        EXPECT_LT(off, 0.1) << "seed " << c.seed << ", the IMU's intrinsic " << j;
        worst = std::max(worst, off);
      }
    }
    EXPECT_TRUE(r.report.converged) << "seed " << c.seed;
    std::printf("seed %llu, NK %d: the largest error %.3f sigma\n",
                static_cast<unsigned long long>(c.seed), c.camera_parameters, worst);
  }
}

TEST(Batch, ReplaysAreBitIdentical) {
  const mc::sim::Scenario s = short_random(4, 6.0);
  const mc::sim::SimData data = mc::sim::simulate(s, 4);
  const Solved a = solve_simulated(s, data, 4), b = solve_simulated(s, data, 4);
  EXPECT_EQ(a.result.p_b_c, b.result.p_b_c);
  EXPECT_EQ(a.result.q_b_c.coeffs(), b.result.q_b_c.coeffs());
  EXPECT_EQ(a.result.t_d, b.result.t_d);
  // The covariance to rounding: SuiteSparse's QR sums in OpenMP threads, in an order that can
  // vary from run to run (its last bits differed once in some twenty replays).
  EXPECT_LE((a.result.covariance - b.result.covariance).cwiseAbs().maxCoeff(),
            1e-9 * a.result.covariance.cwiseAbs().maxCoeff());
  EXPECT_EQ(a.report.iterations, b.report.iterations);
}

TEST(Batch, RefusesDataWithoutMarkersWithinTheImu) {
  const mc::sim::Scenario s = short_random(4, 5.0);
  mc::sim::SimData data = mc::sim::simulate(s, 4);
  const mc::io::RecordingPriors priors = mc::io::from_prior(
      mc::sim::simulation_prior<3>(s, data, 4), s.gravity_n, s.pixel_sigma, false);
  mc::calibration::CalibrationResult r;
  ev::BatchReport report;
  std::string error;
  // Markers of another rig's ids only.
  for (auto& f : data.frames)
    for (auto& m : f.markers) m.id += 3;
  EXPECT_FALSE(ev::solve_batch(ev::simulated_batch_input(s, data, priors), {}, r, report, error));
  EXPECT_NE(error.find("no frame with markers"), std::string::npos) << error;
  // Frames all after the IMU's last sample.
  data = mc::sim::simulate(s, 4);
  for (auto& f : data.frames) f.t_ns += 10'000'000'000;
  EXPECT_FALSE(ev::solve_batch(ev::simulated_batch_input(s, data, priors), {}, r, report, error));
  EXPECT_NE(error.find("within the IMU"), std::string::npos) << error;
}

}  // namespace
