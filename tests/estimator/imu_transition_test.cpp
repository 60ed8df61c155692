// The analytic covariance propagation of one IMU step (imu_transition.hpp): its Jacobian against
// central finite differences of propagate_imu itself, and F P F^T + Q against the sigma-point
// transform of the IMU block that the filter's predict uses (equal to first order: the difference
// falls as the square of the spread).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "mirrorcal/estimator/calibration_filter.hpp"
#include "mirrorcal/estimator/imu_transition.hpp"
#include "test_support.hpp"

namespace mirrorcal {
namespace {

using StateD = MirrorState<double, 3, 0>;
using FilterD = CalibrationFilter<double, 3, 0>;

// A state and two samples far from rest: fast rotation (so that the coning term and the right
// Jacobian matter), large specific force, non-zero biases.
struct Step {
  StateD x;
  ImuSample s0, s1;
};

Step lively_step(unsigned seed, std::int64_t dt_ns) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  const auto vec = [&](double sigma) -> Eigen::Vector3d {
    return Eigen::Vector3d(n(rng), n(rng), n(rng)) * sigma;
  };
  Step st;
  st.x.v = vec(0.5);
  st.x.b_a = vec(0.1);
  st.x.b_g = vec(0.02);
  st.x.p = vec(0.3);
  st.x.q_n_b = test::rotvec(vec(1.0));
  st.s0.t_ns = 1'000'000'000;
  st.s1.t_ns = st.s0.t_ns + dt_ns;
  st.s0.gyro = vec(3.0);
  st.s1.gyro = st.s0.gyro + vec(1.0);
  st.s0.accel = Eigen::Vector3d(0.0, 0.0, 9.81) + vec(3.0);
  st.s1.accel = st.s0.accel + vec(1.0);
  return st;
}

const Eigen::Vector3d kGravity(0.0, -9.81, 0.0);

TEST(ImuTransition, RightJacobianMatchesTheIndependentOne) {
  for (const Eigen::Vector3d& phi :
       {Eigen::Vector3d(0.3, -1.1, 0.7), Eigen::Vector3d(1e-3, 2e-3, -1e-3),
        Eigen::Vector3d(1e-7, 0.0, 3e-7), Eigen::Vector3d(2.5, 0.2, -0.4)}) {
    EXPECT_LT((so3_right_jacobian<double>(phi) - test::right_jacobian(phi)).norm(), 1e-12)
        << phi.transpose();
  }
}

// Column j of F is d(propagated error)/d(error_j): central differences through the manifold.
TEST(ImuTransition, MatchesFiniteDifferencesOfTheIntegration) {
  for (unsigned seed = 1; seed <= 5; ++seed) {
    for (const std::int64_t dt_ns : {5'000'000LL, 50'000'000LL}) {
      const Step st = lively_step(seed, dt_ns);
      const Eigen::Matrix<double, 15, 15> f = imu_transition(st.x, st.s0, st.s1).dense();
      StateD centre = st.x;
      propagate_imu(centre, st.s0, st.s1, kGravity);
      const double h = 1e-6;
      Eigen::Matrix<double, 15, 15> numeric;
      for (int j = 0; j < 15; ++j) {
        StateD plus = st.x, minus = st.x;
        Eigen::Matrix<double, 15, 1> d = Eigen::Matrix<double, 15, 1>::Zero();
        d(j) = h;
        plus.boxplus_block<0, 15>(d);
        minus.boxplus_block<0, 15>(-d);
        propagate_imu(plus, st.s0, st.s1, kGravity);
        propagate_imu(minus, st.s0, st.s1, kGravity);
        numeric.col(j) =
            (plus.boxminus_block<0, 15>(centre) - minus.boxminus_block<0, 15>(centre)) / (2 * h);
      }
      EXPECT_LT((f - numeric).cwiseAbs().maxCoeff(), 1e-8)
          << "seed " << seed << " dt " << dt_ns << "\nanalytic\n"
          << f << "\nnumeric\n"
          << numeric;
    }
  }
}

TEST(ImuTransition, BlockProductEqualsTheDenseOne) {
  const Step st = lively_step(7, 5'000'000);
  const ImuTransition<double> f = imu_transition(st.x, st.s0, st.s1);
  Eigen::Matrix<double, 15, 15> dense = Eigen::Matrix<double, 15, 15>::Identity();
  dense.block<3, 3>(0, 3) = f.v_ba;
  dense.block<3, 3>(0, 6) = f.v_bg;
  dense.block<3, 3>(0, 12) = f.v_theta;
  dense.block<3, 3>(9, 0) = f.dt * Eigen::Matrix3d::Identity();
  dense.block<3, 3>(9, 3) = f.p_ba;
  dense.block<3, 3>(9, 6) = f.p_bg;
  dense.block<3, 3>(9, 12) = f.p_theta;
  dense.block<3, 3>(12, 6) = f.theta_bg;
  dense.block<3, 3>(12, 12) = f.theta_theta;
  const Eigen::Matrix<double, 15, 40> x = Eigen::Matrix<double, 15, 40>::Random();
  Eigen::Matrix<double, 15, 40> out;
  f.left_multiply(x, out);
  EXPECT_LT((out - dense * x).cwiseAbs().maxCoeff(), 1e-14);
  const Eigen::Matrix<double, 40, 15> xt = x.transpose();
  Eigen::Matrix<double, 40, 15> out_t;
  f.right_multiply_transposed(xt, out_t);
  EXPECT_LT((out_t - xt * dense.transpose()).cwiseAbs().maxCoeff(), 1e-14);
  EXPECT_EQ(f.dense(), dense);
}

// A run of steps composes into one transition of the same block form: the product of the dense
// ones, in order.
TEST(ImuTransition, StepsComposeIntoTheProductOfTheirTransitions) {
  EXPECT_EQ(ImuTransition<double>::identity().dense(), (Eigen::Matrix<double, 15, 15>::Identity()));
  ImuTransition<double> composed = ImuTransition<double>::identity();
  Eigen::Matrix<double, 15, 15> product = Eigen::Matrix<double, 15, 15>::Identity();
  for (unsigned seed = 1; seed <= 6; ++seed) {
    const Step st = lively_step(seed, seed * 3'000'000LL);
    const ImuTransition<double> f = imu_transition(st.x, st.s0, st.s1);
    composed = composed.followed_by(f);
    product = f.dense() * product;
    EXPECT_LT((composed.dense() - product).cwiseAbs().maxCoeff(), 1e-13 * product.norm())
        << "after " << seed << " steps";
  }
}

// A covariance with the paper's priors on the calibration and correlations everywhere.
FilterD::Covariance correlated_covariance(unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Matrix<double, FilterD::kDim, 1> sigma;
  sigma << Eigen::Vector3d::Constant(0.05), Eigen::Vector3d::Constant(0.03),
      Eigen::Vector3d::Constant(0.002), Eigen::Vector3d::Constant(0.02),
      Eigen::Vector3d::Constant(1.0 * test::kDeg), Eigen::Vector3d::Constant(0.01),
      Eigen::Vector3d::Constant(2.0 * test::kDeg), Eigen::Matrix<double, 9, 1>::Constant(0.1), 0.02;
  FilterD::Covariance a;
  for (int i = 0; i < a.size(); ++i) a.data()[i] = n(rng);
  FilterD::Covariance corr = a * a.transpose() / double(FilterD::kDim) +
                             FilterD::Covariance::Identity();  // well conditioned
  const Eigen::Matrix<double, FilterD::kDim, 1> d = corr.diagonal().cwiseSqrt().cwiseInverse();
  corr = d.asDiagonal() * corr * d.asDiagonal();
  return sigma.asDiagonal() * corr * sigma.asDiagonal();
}

// The analytic covariance propagation, P_dd <- F P_dd F^T + Q, P_dc <- F P_dc, by F's blocks.
FilterD::Covariance analytic_predict(const StateD& x, const FilterD::Covariance& p,
                                     const ImuSample& s0, const ImuSample& s1,
                                     const Eigen::Matrix<double, 15, 15>& q) {
  constexpr int D = 15, C = FilterD::kDim - D;
  const ImuTransition<double> f = imu_transition(x, s0, s1);
  Eigen::Matrix<double, D, FilterD::kDim> fp;
  f.left_multiply(p.topRows<D>(), fp);
  const Eigen::Matrix<double, D, D> fp_dd_t = fp.leftCols<D>().transpose();
  Eigen::Matrix<double, D, D> p_dd;
  f.left_multiply(fp_dd_t, p_dd);
  FilterD::Covariance next = p;
  next.topLeftCorner<D, D>() = p_dd + q;
  next.topRightCorner<D, C>() = fp.rightCols<C>();
  next.bottomLeftCorner<C, D>() = fp.rightCols<C>().transpose();
  return next;
}

// The difference of the analytic propagation from the sigma-point transform of the IMU block (the
// filter's predict), relative to the covariance, for the covariance scaled by scale^2.
double difference_from_sigma_points(double scale, unsigned seed) {
  const Step st = lively_step(seed, 5'000'000);
  const FilterD::Covariance p = scale * scale * correlated_covariance(seed);
  CalibrationConfig cfg;
  cfg.gravity_n = kGravity;

  SigmaPointFilter<StateD> sigma_points(cfg.sigma_points);
  sigma_points.reset(st.x, p);
  const auto q = imu_process_noise<double>(cfg.imu, 0.005);
  EXPECT_EQ((sigma_points.predict<0, 15>(
                [&](StateD& x) { propagate_imu(x, st.s0, st.s1, kGravity); }, q)),
            FilterStatus::kOk);
  // Both add the same process noise: the difference is what the linearisation leaves out.
  return (analytic_predict(st.x, p, st.s0, st.s1, q) - sigma_points.covariance()).norm() / p.norm();
}

TEST(ImuTransition, AnalyticPropagationAgreesWithTheSigmaPointTransformToFirstOrder) {
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const double at_prior = difference_from_sigma_points(1.0, seed);
    const double tenth = difference_from_sigma_points(0.1, seed);
    // At the paper's priors the two differ by about 1e-6 of the covariance.
    EXPECT_LT(at_prior, 1e-5) << "seed " << seed;
    // Second-order terms only: a tenth of the spread, a hundredth of the relative difference.
    EXPECT_NEAR(tenth / at_prior, 0.01, 0.001)
        << "seed " << seed << ": " << at_prior << " -> " << tenth;
  }
}

// The filter's predict defers the cross-covariance of the IMU block with the calibration to when
// the covariance is read: after ten steps it is the step-by-step propagation's (analytic_predict,
// a product by F's rows rather than the filter's by its columns), and a read between the steps
// changes nothing but the rounding.
TEST(ImuTransition, FilterCovarianceAfterStepsIsTheStepByStepOne) {
  CalibrationConfig cfg;
  cfg.gravity_n = kGravity;
  FilterD deferred(cfg), read_every_step(cfg);
  const Step first = lively_step(11, 5'000'000);
  const FilterD::Covariance p0 = correlated_covariance(11);
  deferred.reset(first.x, p0);
  read_every_step.reset(first.x, p0);
  FilterD::Covariance reference = p0;
  ImuSample s0 = first.s0;
  for (unsigned k = 0; k < 10; ++k) {
    ImuSample s1 = lively_step(20 + k, 5'000'000).s1;
    s1.t_ns = s0.t_ns + 5'000'000;
    reference = analytic_predict(deferred.state(), reference, s0, s1,
                                 imu_process_noise<double>(cfg.imu, 0.005));
    ASSERT_EQ(deferred.predict(s0, s1), FilterStatus::kOk);
    ASSERT_EQ(read_every_step.predict(s0, s1), FilterStatus::kOk);
    const double read = read_every_step.covariance()(0, 0);  // settles this step
    EXPECT_GT(read, 0.0);
    s0 = s1;
  }
  EXPECT_EQ(deferred.state().p, read_every_step.state().p);
  const double scale = reference.norm();
  EXPECT_LT((deferred.covariance() - reference).norm(), 1e-13 * scale);
  EXPECT_LT((deferred.covariance() - read_every_step.covariance()).norm(), 1e-14 * scale);
  constexpr int C = FilterD::kDim - 15;
  const double moved = (deferred.covariance() - p0).bottomLeftCorner<C, 15>().norm();
  EXPECT_GT(moved, 1e-3 * scale);  // the steps did move the cross-covariance
}

}  // namespace
}  // namespace mirrorcal
