// The IMU's intrinsics (imu_intrinsics.hpp): the state's reading of raw samples inverts the sensor
// model the simulator draws from (f_m = T_a a + b_a, w_m = T_g w + T_s a + b_g), and the
// propagation's Jacobian over the larger dynamic block matches central finite differences of
// propagate_imu, composes as the product of its steps and applies as its dense form.
#include <gtest/gtest.h>

#include <random>

#include "mirrorcal/estimator/calibration_filter.hpp"
#include "mirrorcal/estimator/imu_transition.hpp"
#include "test_support.hpp"

namespace mirrorcal {
namespace {

const Eigen::Vector3d kGravity(0.0, -9.81, 0.0);

template <int NI>
using StateI = MirrorState<double, 3, 0, NI>;

// A state far from rest with intrinsics a few per cent from the ideal (a poor part, so that every
// column of the Jacobian is far from zero), and two samples.
template <int NI>
struct Step {
  StateI<NI> x;
  ImuSample s0, s1;
};

template <int NI>
Step<NI> lively_step(unsigned seed, std::int64_t dt_ns) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  const auto vec = [&](double sigma) -> Eigen::Vector3d {
    return Eigen::Vector3d(n(rng), n(rng), n(rng)) * sigma;
  };
  const auto mat = [&](double sigma) -> Eigen::Matrix3d {
    Eigen::Matrix3d m;
    for (int i = 0; i < 9; ++i) m.data()[i] = n(rng) * sigma;
    return m;
  };
  Step<NI> st;
  st.x.v = vec(0.5);
  st.x.b_a = vec(0.1);
  st.x.b_g = vec(0.02);
  st.x.p = vec(0.3);
  st.x.q_n_b = test::rotvec(vec(1.0));
  st.x.imu.d_a = (Eigen::Matrix3d::Identity() + mat(0.03)).template triangularView<Eigen::Lower>();
  st.x.imu.d_g = Eigen::Matrix3d::Identity() + mat(0.03);
  if constexpr (NI == 12) st.x.imu.d_g = st.x.imu.d_g.template triangularView<Eigen::Lower>();
  if constexpr (NI == 24) st.x.imu.t_s = mat(1e-3);
  st.s0.t_ns = 1'000'000'000;
  st.s1.t_ns = st.s0.t_ns + dt_ns;
  st.s0.gyro = vec(3.0);
  st.s1.gyro = st.s0.gyro + vec(1.0);
  st.s0.accel = Eigen::Vector3d(0.0, 0.0, 9.81) + vec(3.0);
  st.s1.accel = st.s0.accel + vec(1.0);
  return st;
}

template <int NI>
void expect_reading_inverts_the_sensor_model() {
  const Step<NI> st = lively_step<NI>(3, 5'000'000);
  const Eigen::Matrix3d t_a = st.x.imu.d_a.inverse(), t_g = st.x.imu.d_g.inverse();
  const Eigen::Vector3d a(1.0, -9.0, 2.5), w(0.4, -1.2, 2.0);
  const Eigen::Vector3d f_m = t_a * a + st.x.b_a;
  const Eigen::Vector3d w_m = t_g * w + st.x.imu.t_s * a + st.x.b_g;
  EXPECT_LT((st.x.specific_force(f_m) - a).norm(), 1e-12);
  EXPECT_LT((st.x.body_rate(w_m, f_m) - w).norm(), 1e-12);
  EXPECT_LT((st.x.gyro_sample(w, a) - w_m).norm(), 1e-12);
  EXPECT_TRUE(t_a.isLowerTriangular());  // the accelerometer's axes define the IMU frame
  if constexpr (NI == 12) {
    EXPECT_TRUE(t_g.isLowerTriangular());
  }
}
TEST(ImuIntrinsics, ReadingInvertsTheSensorModel) {
  expect_reading_inverts_the_sensor_model<12>();
  expect_reading_inverts_the_sensor_model<15>();
  expect_reading_inverts_the_sensor_model<24>();
}

TEST(ImuIntrinsics, ErrorStateRoundTripsThroughTheMatrices) {
  StateI<24> x = lively_step<24>(5, 5'000'000).x, y = x;
  Eigen::Matrix<double, 24, 1> d;
  for (int j = 0; j < 24; ++j) d(j) = 0.001 * (j + 1);
  y.boxplus_block<StateI<24>::kImu, 24>(d);
  EXPECT_LT((y.boxminus_block<StateI<24>::kImu, 24>(x) - d).norm(), 1e-15);
  EXPECT_TRUE(y.imu.d_a.isLowerTriangular());
  // The accelerometer's entries: three scales, then the three below the diagonal.
  EXPECT_DOUBLE_EQ(y.imu.d_a(1, 1) - x.imu.d_a(1, 1), d(1));
  EXPECT_DOUBLE_EQ(y.imu.d_a(2, 1) - x.imu.d_a(2, 1), d(5));
  EXPECT_DOUBLE_EQ(y.imu.d_g(2, 1) - x.imu.d_g(2, 1), d(6 + 5));
  EXPECT_DOUBLE_EQ(y.imu.d_g(1, 2) - x.imu.d_g(1, 2), d(12 + 2));
  EXPECT_DOUBLE_EQ(y.imu.t_s(2, 0) - x.imu.t_s(2, 0), d(15 + 6));
}

// Column j of F is d(propagated error)/d(error_j): central differences through the manifold.
template <int NI>
void expect_jacobian_matches_finite_differences() {
  using X = StateI<NI>;
  constexpr int D = X::kDynamicDim;
  for (unsigned seed = 1; seed <= 4; ++seed) {
    for (const std::int64_t dt_ns : {5'000'000LL, 50'000'000LL}) {
      const Step<NI> st = lively_step<NI>(seed, dt_ns);
      const Eigen::Matrix<double, D, D> f = imu_transition(st.x, st.s0, st.s1).dense();
      X centre = st.x;
      propagate_imu(centre, st.s0, st.s1, kGravity);
      const double h = 1e-6;
      Eigen::Matrix<double, D, D> numeric;
      for (int j = 0; j < D; ++j) {
        X plus = st.x, minus = st.x;
        Eigen::Matrix<double, D, 1> d = Eigen::Matrix<double, D, 1>::Zero();
        d(j) = h;
        plus.template boxplus_block<0, D>(d);
        minus.template boxplus_block<0, D>(-d);
        propagate_imu(plus, st.s0, st.s1, kGravity);
        propagate_imu(minus, st.s0, st.s1, kGravity);
        numeric.col(j) = (plus.template boxminus_block<0, D>(centre) -
                          minus.template boxminus_block<0, D>(centre)) /
                         (2 * h);
      }
      EXPECT_LT((f - numeric).cwiseAbs().maxCoeff(), 1e-8)
          << "NI " << NI << " seed " << seed << " dt " << dt_ns << "\nanalytic\n"
          << f << "\nnumeric\n"
          << numeric;
    }
  }
}
// 12 and 24 states: 24 holds every entry 15 has (D_g's upper triangle) and T_s besides, and 12 the
// lower-triangular path; a third size would add a minute of compiling in each build.
TEST(ImuIntrinsics, JacobianMatchesFiniteDifferencesOfTheIntegration) {
  expect_jacobian_matches_finite_differences<12>();
  expect_jacobian_matches_finite_differences<24>();
}

template <int NI>
void expect_block_products_and_composition() {
  constexpr int D = StateI<NI>::kDynamicDim;
  const Step<NI> st = lively_step<NI>(7, 5'000'000);
  const ImuTransition<double, NI> f = imu_transition(st.x, st.s0, st.s1);
  const Eigen::Matrix<double, D, D> dense = f.dense();
  const Eigen::Matrix<double, D, 40> x = Eigen::Matrix<double, D, 40>::Random();
  Eigen::Matrix<double, 40, D> out_t;
  const Eigen::Matrix<double, 40, D> xt = x.transpose();
  f.right_multiply_transposed(xt, out_t);
  EXPECT_LT((out_t - xt * dense.transpose()).cwiseAbs().maxCoeff(), 1e-14);
  // F P F^T of a symmetric P, which the predict builds from its motion rows alone: the dense
  // product's.
  const Eigen::Matrix<double, D, D> p = x * x.transpose();
  Eigen::Matrix<double, D, D> fpf;
  f.sandwich(p, fpf);
  EXPECT_LT((fpf - dense * p * dense.transpose()).cwiseAbs().maxCoeff(), 1e-13 * p.norm());

  ImuTransition<double, NI> composed = ImuTransition<double, NI>::identity();
  EXPECT_EQ(composed.dense(), (Eigen::Matrix<double, D, D>::Identity()));
  Eigen::Matrix<double, D, D> product = Eigen::Matrix<double, D, D>::Identity();
  for (unsigned seed = 1; seed <= 6; ++seed) {
    const Step<NI> s = lively_step<NI>(seed, seed * 3'000'000LL);
    const ImuTransition<double, NI> g = imu_transition(s.x, s.s0, s.s1);
    composed = composed.followed_by(g);
    product = g.dense() * product;
    EXPECT_LT((composed.dense() - product).cwiseAbs().maxCoeff(), 1e-13 * product.norm())
        << "NI " << NI << " after " << seed << " steps";
  }
}
TEST(ImuIntrinsics, TransitionAppliesAndComposesAsItsDenseForm) {
  expect_block_products_and_composition<12>();
  expect_block_products_and_composition<24>();
}

// The filter's predicts, whose IMU block waits with its cross-covariance (settle), give the
// covariance of the dense steps P <- F P F^T + Q, F at each step's estimate.
template <int NI>
void expect_predicts_as_the_dense_steps() {
  using Filter = CalibrationFilter<double, 3, 0, NI>;
  constexpr int N = Filter::kDim, D = StateI<NI>::kDynamicDim;
  CalibrationConfig config;
  config.gravity_n = kGravity;
  config.imu.accel_noise_density = 0.02;  // large, so that the noise's share shows
  config.imu.gyro_noise_density = 0.002;
  Filter filter(config);
  Step<NI> st = lively_step<NI>(11, 5'000'000);
  const Eigen::Matrix<double, N, N> a = Eigen::Matrix<double, N, N>::Random();
  Eigen::Matrix<double, N, N> p =
      1e-2 * (a * a.transpose()) + 1e-3 * Eigen::Matrix<double, N, N>::Identity();
  filter.reset(st.x, p);
  StateI<NI> x = st.x;
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0.0, 1.0);
  ImuSample s0 = st.s0;
  for (int k = 0; k < 10; ++k) {
    ImuSample s1 = s0;
    s1.t_ns += 5'000'000;
    s1.gyro += 0.5 * Eigen::Vector3d(n(rng), n(rng), n(rng));
    s1.accel += 0.5 * Eigen::Vector3d(n(rng), n(rng), n(rng));
    ASSERT_EQ(filter.predict(s0, s1), FilterStatus::kOk);
    Eigen::Matrix<double, N, N> f = Eigen::Matrix<double, N, N>::Identity();
    f.template topLeftCorner<D, D>() = imu_transition(x, s0, s1).dense();
    p = f * p * f.transpose();
    p.template topLeftCorner<D, D>() += imu_process_noise<double, D>(config.imu, 0.005);
    propagate_imu(x, s0, s1, kGravity);
    s0 = s1;
  }
  EXPECT_LT((filter.covariance() - p).cwiseAbs().maxCoeff(), 1e-12 * p.norm()) << "NI " << NI;
  EXPECT_EQ(filter.state().p, x.p);
}
template <int NI>
bool predicts_as_the_dense_steps_if_built() {
  if constexpr (imu_model_built(NI)) {
    expect_predicts_as_the_dense_steps<NI>();
    return true;
  }
  return false;
}
TEST(ImuIntrinsics, PredictsGiveTheCovarianceOfTheDenseSteps) {
  if (!predicts_as_the_dense_steps_if_built<12>()) GTEST_SKIP() << "scale-misalignment not built";
}

// With the intrinsics the predicts leave the IMU block's covariance to settle, so an indefinite
// block (an intrinsic's variance below zero) is found where settle reads it: the frame's update
// is refused, the estimate as it was, and so is every predict after it until a reset.
template <int NI>
void expect_indefinite_imu_block_refused() {
  using Filter = CalibrationFilter<double, 3, 0, NI>;
  constexpr int N = Filter::kDim;
  CalibrationConfig config;
  config.gravity_n = kGravity;
  Filter filter(config);
  const Step<NI> st = lively_step<NI>(13, 5'000'000);
  Eigen::Matrix<double, N, N> p = 1e-4 * Eigen::Matrix<double, N, N>::Identity();
  p(StateI<NI>::kImu + 1, StateI<NI>::kImu + 1) = -1e-6;
  filter.reset(st.x, p);
  ASSERT_EQ(filter.predict(st.s0, st.s1), FilterStatus::kOk);  // P_dd not read yet
  const StateI<NI> before = filter.state();
  MarkerFrame<3> frame;
  frame.t_ns = st.s1.t_ns;
  EXPECT_EQ(filter.update(frame).status, FilterStatus::kCovarianceNotPositiveDefinite);
  EXPECT_EQ(filter.state().p, before.p);
  EXPECT_EQ(filter.state().imu.d_a, before.imu.d_a);
  ImuSample s2 = st.s1;
  s2.t_ns += 5'000'000;
  EXPECT_EQ(filter.predict(st.s1, s2), FilterStatus::kCovarianceNotPositiveDefinite);
  EXPECT_EQ(filter.state().p, before.p);
  EXPECT_EQ(filter.counters().failures, 2u);
  filter.reset(st.x, 1e-4 * Eigen::Matrix<double, N, N>::Identity());
  EXPECT_EQ(filter.predict(st.s0, st.s1), FilterStatus::kOk);
  EXPECT_EQ(filter.update(frame).status, FilterStatus::kNoMeasurement);
}
template <int NI>
bool indefinite_imu_block_refused_if_built() {
  if constexpr (imu_model_built(NI)) {
    expect_indefinite_imu_block_refused<NI>();
    return true;
  }
  return false;
}
TEST(ImuIntrinsics, AnIndefiniteImuBlockIsRefusedWhereSettleReadsIt) {
  if (!indefinite_imu_block_refused_if_built<12>()) GTEST_SKIP() << "scale-misalignment not built";
}

// The ideal IMU is the model with intrinsics at the identity: both integrate a step to the same
// state, and the Jacobian's common blocks agree.
TEST(ImuIntrinsics, IdentityIntrinsicsIntegrateAsTheIdealImu) {
  const Step<12> st = lively_step<12>(9, 5'000'000);
  StateI<12> with = st.x;
  with.imu = ImuIntrinsics<double>{};
  StateI<0> ideal;
  ideal.v = with.v;
  ideal.b_a = with.b_a;
  ideal.b_g = with.b_g;
  ideal.p = with.p;
  ideal.q_n_b = with.q_n_b;
  propagate_imu(with, st.s0, st.s1, kGravity);
  propagate_imu(ideal, st.s0, st.s1, kGravity);
  EXPECT_LT((with.p - ideal.p).norm(), 1e-15);
  EXPECT_LT((with.v - ideal.v).norm(), 1e-15);
  EXPECT_LT(with.q_n_b.angularDistance(ideal.q_n_b), 1e-15);
  StateI<12> at_identity = st.x;
  at_identity.imu = ImuIntrinsics<double>{};
  StateI<0> same;
  same.b_a = at_identity.b_a;
  same.b_g = at_identity.b_g;
  same.q_n_b = at_identity.q_n_b;
  const auto a = imu_transition(at_identity, st.s0, st.s1);
  const auto b = imu_transition(same, st.s0, st.s1);
  EXPECT_LT((a.v_theta - b.v_theta).norm() + (a.p_ba - b.p_ba).norm() +
                (a.theta_bg - b.theta_bg).norm() + (a.v_bg - b.v_bg).norm(),
            1e-14);
}

}  // namespace
}  // namespace mirrorcal
