// The Jacobian F of one step of propagate_imu with respect to the error state of the IMU block
// [v, b_a, b_g, p, theta] (rotations perturbed on the right, as MirrorState does), at the
// estimate the step starts from. With it the covariance propagates as P_dd <- F P_dd F^T + Q and
// the cross-covariance with the constant calibration states as P_dc <- F P_dc.
//
// Derivation, for the mid-point scheme of propagate_imu: with u_i = f_i - b_a, w_i = g_i - b_g,
// dtheta = dt/2 (w0 + w1) + dt^2/12 (w0 x w1), R_d = Exp(dtheta), R1 = R0 R_d:
//   theta'  = R_d^T theta + J_r(dtheta) D db_g,   D = -dt I + dt^2/12 ([w1]x - [w0]x)
//   da_0    = -R0 [u0]x theta - R0 db_a
//   da_1    = -R1 [u1]x theta' - R1 db_a
//   dv'     = dv + dt/2 (da_0 + da_1)
//   dp'     = dp + dt dv + dt^2/6 (2 da_0 + da_1)
// and the biases are unchanged. With the IMU's intrinsics (NI > 0) the signals are
// u_i = D_a (f_i - b_a), w_i = D_g (g_i - b_g - T_s u_i), and every sensor parameter
// s = [b_a, b_g, imu] enters through du_i = U_i ds and dw_i = W_i ds (signal_jacobians):
//   theta'  = R_d^T theta + J_r(dtheta) (P0 W_0 + P1 W_1) ds,
//             P0 = dt/2 I - dt^2/12 [w1]x,  P1 = dt/2 I + dt^2/12 [w0]x
//   da_0    = -R0 [u0]x theta + R0 U_0 ds,   da_1 = -R1 [u1]x theta' + R1 U_1 ds
// (with U = -I on b_a and W = -I on b_g this is the bias-only Jacobian above).
#pragma once

#include <cmath>

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal {

// Right Jacobian of SO(3): Exp(phi + d) = Exp(phi) Exp(J_r(phi) d) to first order in d.
template <typename S>
Mat3<S> so3_right_jacobian(const Vec3<S>& phi) {
  const S a2 = phi.squaredNorm();
  const Mat3<S> h = so3::hat<S>(phi);
  S c1, c2;  // J_r = I - c1 [phi]x + c2 [phi]x^2
  if (a2 < so3::series_angle<S>() * so3::series_angle<S>()) {
    c1 = S(0.5) * (S(1) - a2 / S(12) * (S(1) - a2 / S(30) * (S(1) - a2 / S(56))));
    c2 = (S(1) - a2 / S(20) * (S(1) - a2 / S(42) * (S(1) - a2 / S(72)))) / S(6);
  } else {
    const S a = std::sqrt(a2);
    c1 = (S(1) - std::cos(a)) / a2;
    c2 = (a - std::sin(a)) / (a2 * a);
  }
  return Mat3<S>::Identity() - c1 * h + c2 * (h * h);
}

// F in its 3x3 blocks. In block rows and columns [v, b_a, b_g, imu, p, theta]:
//   v'     = [ I     v_ba      v_bg   v_imu      0   v_theta ]
//   b_a'   = [ 0     I         0      0          0   0       ]
//   b_g'   = [ 0     0         I      0          0   0       ]
//   imu'   = [ 0     0         0      I          0   0       ]
//   p'     = [ dt I  p_ba      p_bg   p_imu      I   p_theta ]
//   theta' = [ 0     theta_ba  th_bg  theta_imu  0   th_th   ]
// so applying it costs 8 products of 3x3 blocks instead of a dense 15x15 one. The imu columns
// and theta_ba (the gyro's g-sensitivity) exist with NI intrinsics only (ImuModel).
template <typename S, int NI>
struct ImuIntrinsicColumns {
  Eigen::Matrix<S, 3, NI> v, p, theta;
  Mat3<S> theta_ba;
};
template <typename S>
struct ImuIntrinsicColumns<S, 0> {};

template <typename S, int NI = 0>
struct ImuTransition {
  using Layout = MirrorState<S, 1, 0, NI>;  // the dynamic block's is the same for any M and NK
  static constexpr int kDim = Layout::kDynamicDim, kImu = Layout::kImu, kP = Layout::kP,
                       kTheta = Layout::kTheta;
  S dt;
  Mat3<S> v_ba, v_bg, v_theta, p_ba, p_bg, p_theta, theta_bg, theta_theta;
  ImuIntrinsicColumns<S, NI> imu;

  // Whether every entry of F is finite (the identity's rows are).
  bool all_finite() const {
    bool finite = std::isfinite(dt) && v_ba.allFinite() && v_bg.allFinite() &&
                  v_theta.allFinite() && p_ba.allFinite() && p_bg.allFinite() &&
                  p_theta.allFinite() && theta_bg.allFinite() && theta_theta.allFinite();
    if constexpr (NI > 0)
      finite = finite && imu.v.allFinite() && imu.p.allFinite() && imu.theta.allFinite() &&
               imu.theta_ba.allFinite();
    return finite;
  }

  // out = F x, for x with the kDim rows of the IMU block; out must not alias x.
  template <class In, class Out>
  void left_multiply(const Eigen::MatrixBase<In>& x, Eigen::MatrixBase<Out>& out) const {
    const auto xv = x.template middleRows<3>(0), xba = x.template middleRows<3>(3),
               xbg = x.template middleRows<3>(6), xp = x.template middleRows<3>(kP),
               xth = x.template middleRows<3>(kTheta);
    // lazyProduct: coefficient-wise, which for a 3x3 factor beats the general matrix product.
    out.template middleRows<3>(0) =
        xv + v_ba.lazyProduct(xba) + v_bg.lazyProduct(xbg) + v_theta.lazyProduct(xth);
    out.template middleRows<3>(3) = xba;
    out.template middleRows<3>(6) = xbg;
    out.template middleRows<3>(kP) =
        dt * xv + p_ba.lazyProduct(xba) + p_bg.lazyProduct(xbg) + xp + p_theta.lazyProduct(xth);
    out.template middleRows<3>(kTheta) = theta_bg.lazyProduct(xbg) + theta_theta.lazyProduct(xth);
    if constexpr (NI > 0) {
      const auto xi = x.template middleRows<NI>(kImu);
      out.template middleRows<NI>(kImu) = xi;
      // lazyProduct again: at these sizes Eigen's general product packs its operands for a
      // blocked kernel, which cost a predict at NI = 12 five times the ideal IMU's.
      out.template middleRows<3>(0) += imu.v.lazyProduct(xi);
      out.template middleRows<3>(kP) += imu.p.lazyProduct(xi);
      out.template middleRows<3>(kTheta) +=
          imu.theta.lazyProduct(xi) + imu.theta_ba.lazyProduct(xba);
    }
  }

  // out = x F^T, for x with the kDim columns of the IMU block; out must not alias x. Each column
  // of out is x's columns combined by a row of F: whole columns of x, contiguous, so for x = P's
  // IMU columns (P F^T = (F P)^T, P symmetric) this vectorises where left_multiply's 3-row blocks
  // cannot.
  template <class In, class Out>
  void right_multiply_transposed(const Eigen::MatrixBase<In>& x,
                                 Eigen::MatrixBase<Out>& out) const {
    const auto xv = x.template middleCols<3>(0), xba = x.template middleCols<3>(3),
               xbg = x.template middleCols<3>(6), xp = x.template middleCols<3>(kP),
               xth = x.template middleCols<3>(kTheta);
    for (int r = 0; r < 3; ++r) {
      out.col(r) =
          xv.col(r) + row_of(xba, v_ba, r) + row_of(xbg, v_bg, r) + row_of(xth, v_theta, r);
      out.col(kP + r) = dt * xv.col(r) + row_of(xba, p_ba, r) + row_of(xbg, p_bg, r) + xp.col(r) +
                        row_of(xth, p_theta, r);
      out.col(kTheta + r) = row_of(xbg, theta_bg, r) + row_of(xth, theta_theta, r);
    }
    out.template middleCols<6 + NI>(3) = x.template middleCols<6 + NI>(3);
    if constexpr (NI > 0) {
      // Column by column of x, as row_of does: each a whole contiguous column (one product of
      // x's intrinsics columns by F's 9 x NI block costs more: Eigen packs it for a blocked
      // kernel).
      const auto xi = x.template middleCols<NI>(kImu);
      for (int r = 0; r < 3; ++r) {
        for (int j = 0; j < 3; ++j) out.col(kTheta + r) += imu.theta_ba(r, j) * xba.col(j);
        for (int j = 0; j < NI; ++j) {
          out.col(r) += imu.v(r, j) * xi.col(j);
          out.col(kP + r) += imu.p(r, j) * xi.col(j);
          out.col(kTheta + r) += imu.theta(r, j) * xi.col(j);
        }
      }
    }
  }

  // F P F^T for a symmetric P of the IMU block, into out (not aliasing p). Of F's rows only the
  // motion's (v, p, theta) differ from the identity's, so of F (P F^T) only the motion rows'
  // motion columns need the left product; the sensor's rows are P F^T's, and the motion rows'
  // sensor columns their transposes (the result is symmetric). A third of the left product's cost.
  // CalibrationFilter's settle applies it once a frame with the IMU's intrinsics.
  template <class In, class Out>
  void sandwich(const Eigen::MatrixBase<In>& p, Eigen::MatrixBase<Out>& out) const {
    constexpr int kSensor = 3, kSensors = 6 + NI;  // b_a, b_g and the intrinsics: F's identity
    static_assert(kP == kSensor + kSensors && kTheta == kP + 3 && kDim == kTheta + 3,
                  "the motion states are v, then p and theta after the sensor's");
    Eigen::Matrix<S, kDim, kDim> pf;  // P F^T
    right_multiply_transposed(p, pf);
    Eigen::Matrix<S, kDim, 9> motion_cols, f_motion_cols;
    motion_cols << pf.template leftCols<3>(), pf.template rightCols<6>();
    left_multiply(motion_cols, f_motion_cols);
    out = pf;
    out.template block<3, kSensors>(0, kSensor) =
        pf.template block<kSensors, 3>(kSensor, 0).transpose();
    out.template block<6, kSensors>(kP, kSensor) =
        pf.template block<kSensors, 6>(kSensor, kP).transpose();
    out.template block<3, 3>(0, 0) = f_motion_cols.template block<3, 3>(0, 0);
    out.template block<3, 6>(0, kP) = f_motion_cols.template block<3, 6>(0, 3);
    out.template block<6, 3>(kP, 0) = f_motion_cols.template block<6, 3>(kP, 0);
    out.template block<6, 6>(kP, kP) = f_motion_cols.template block<6, 6>(kP, 3);
  }

  // F without the intrinsics' columns and rows, in the ideal IMU's layout [v, b_a, b_g, p, theta]:
  // what the process noise reaches (the intrinsics have none), but for the gyro's g-sensitivity
  // (theta's b_a columns, imu.theta_ba), which motion_sandwich adds.
  ImuTransition<S, 0> without_intrinsics() const {
    ImuTransition<S, 0> m;
    m.dt = dt;
    m.v_ba = v_ba;
    m.v_bg = v_bg;
    m.v_theta = v_theta;
    m.p_ba = p_ba;
    m.p_bg = p_bg;
    m.p_theta = p_theta;
    m.theta_bg = theta_bg;
    m.theta_theta = theta_theta;
    return m;
  }

  // The process noise a run of steps accumulates: on the states other than the intrinsics, in the
  // ideal IMU's layout.
  using MotionNoise = Eigen::Matrix<S, kImuMotionDim, kImuMotionDim>;
  // F Q F^T for such a Q: the ideal IMU's products, and the g-sensitivity's.
  void motion_sandwich(const MotionNoise& q, MotionNoise& out) const {
    static_assert(NI > 0, "the ideal IMU's F is its own without_intrinsics");
    using Ideal = ImuTransition<S, 0>;
    constexpr int kBa = Ideal::Layout::kBa, kTheta0 = Ideal::kTheta;
    const Ideal m = without_intrinsics();
    MotionNoise qf;  // Q F^T
    m.right_multiply_transposed(q, qf);
    for (int r = 0; r < 3; ++r)
      for (int j = 0; j < 3; ++j) qf.col(kTheta0 + r) += imu.theta_ba(r, j) * q.col(kBa + j);
    m.left_multiply(qf, out);
    out.template middleRows<3>(kTheta0) += imu.theta_ba.lazyProduct(qf.template middleRows<3>(kBa));
  }

  // Row r of a 3x3 block applied to three columns, as one expression, so that each sum in
  // right_multiply_transposed is a single pass over the rows. Inlined by force: as a lambda GCC
  // called it out of line at M = 3, 1.1k instructions of an 11.5k predict.
  template <class X3>
  static EIGEN_ALWAYS_INLINE auto row_of(const X3& x3, const Mat3<S>& m, int r) {
    return m(r, 0) * x3.col(0) + m(r, 1) * x3.col(1) + m(r, 2) * x3.col(2);
  }

  // No motion: F = I.
  static ImuTransition identity() {
    ImuTransition f;
    f.dt = S(0);
    for (Mat3<S>* b : {&f.v_ba, &f.v_bg, &f.v_theta, &f.p_ba, &f.p_bg, &f.p_theta, &f.theta_bg})
      b->setZero();
    f.theta_theta.setIdentity();
    if constexpr (NI > 0) {
      f.imu.v.setZero();
      f.imu.p.setZero();
      f.imu.theta.setZero();
      f.imu.theta_ba.setZero();
    }
    return f;
  }

  // This step followed by next: next's F times this F. The product has F's block structure again
  // (the velocity reaches the position by the steps' summed dt), so a run of steps composes at the
  // cost of six 3x3 products per step instead of a 15x15 one.
  ImuTransition followed_by(const ImuTransition& next) const {
    const ImuTransition& a = *this;
    const ImuTransition& b = next;
    ImuTransition c;
    c.dt = a.dt + b.dt;
    c.v_ba = a.v_ba + b.v_ba;
    c.v_bg = a.v_bg + b.v_bg + b.v_theta.lazyProduct(a.theta_bg);
    c.v_theta = a.v_theta + b.v_theta.lazyProduct(a.theta_theta);
    c.p_ba = b.dt * a.v_ba + b.p_ba + a.p_ba;
    c.p_bg = b.dt * a.v_bg + b.p_bg + a.p_bg + b.p_theta.lazyProduct(a.theta_bg);
    c.p_theta = b.dt * a.v_theta + a.p_theta + b.p_theta.lazyProduct(a.theta_theta);
    c.theta_bg = b.theta_bg + b.theta_theta.lazyProduct(a.theta_bg);
    c.theta_theta = b.theta_theta.lazyProduct(a.theta_theta);
    if constexpr (NI > 0) {  // the intrinsics' columns compose as the biases' do
      c.v_ba += b.v_theta * a.imu.theta_ba;
      c.p_ba += b.p_theta * a.imu.theta_ba;
      c.imu.theta_ba = b.imu.theta_ba + b.theta_theta * a.imu.theta_ba;
      c.imu.v = a.imu.v + b.imu.v + b.v_theta * a.imu.theta;
      c.imu.p = b.dt * a.imu.v + b.imu.p + a.imu.p + b.p_theta * a.imu.theta;
      c.imu.theta = b.imu.theta + b.theta_theta * a.imu.theta;
    }
    return c;
  }

  Eigen::Matrix<S, kDim, kDim> dense() const {
    Eigen::Matrix<S, kDim, kDim> f;
    left_multiply(Eigen::Matrix<S, kDim, kDim>::Identity(), f);
    return f;
  }
};

// imu_transition for a state with the IMU's intrinsics: the same scheme with every sensor
// parameter's column from signal_jacobians (the header's derivation).
template <class State>
ImuTransition<typename State::Scalar, State::kImuIntrinsics> imu_transition_with_intrinsics(
    const State& x, const ImuSample& s0, const ImuSample& s1) {
  using S = typename State::Scalar;
  constexpr int NI = State::kImuIntrinsics;
  const S dt = S(static_cast<double>(s1.t_ns - s0.t_ns) * 1e-9);
  const Vec3<S> f0 = s0.accel.cast<S>(), f1 = s1.accel.cast<S>();
  const Vec3<S> g0 = s0.gyro.cast<S>(), g1 = s1.gyro.cast<S>();
  const Vec3<S> u0 = x.specific_force(f0), u1 = x.specific_force(f1);
  const Vec3<S> w0 = x.body_rate(g0, f0), w1 = x.body_rate(g1, f1);
  const Vec3<S> dtheta = (S(0.5) * dt) * (w0 + w1) + (dt * dt / S(12)) * w0.cross(w1);
  const Mat3<S> r_d = so3::exp<S>(dtheta).toRotationMatrix();
  const Mat3<S> r0 = x.q_n_b.toRotationMatrix();
  const Mat3<S> r1 = r0 * r_d;
  const SignalJacobians<S, NI> j0 = signal_jacobians<S, NI>(x.imu, x.b_a, x.b_g, f0, g0);
  const SignalJacobians<S, NI> j1 = signal_jacobians<S, NI>(x.imu, x.b_a, x.b_g, f1, g1);
  const Mat3<S> p0 = (S(0.5) * dt) * Mat3<S>::Identity() - (dt * dt / S(12)) * so3::hat<S>(w1);
  const Mat3<S> p1 = (S(0.5) * dt) * Mat3<S>::Identity() + (dt * dt / S(12)) * so3::hat<S>(w0);
  using Cols = Eigen::Matrix<S, 3, 6 + NI>;
  // lazyProduct: a 3x3 times 3 x (6 + NI) is past the size where Eigen's product stops packing.
  const Cols theta_s = so3_right_jacobian<S>(dtheta).lazyProduct(
      Cols(p0.lazyProduct(j0.gyro) + p1.lazyProduct(j1.gyro)));
  const Mat3<S> a0_theta = -r0 * so3::hat<S>(u0);
  const Mat3<S> a1_theta_prime = -r1 * so3::hat<S>(u1);
  const Cols a0_s = r0.lazyProduct(j0.accel);
  const Cols a1_s = r1.lazyProduct(j1.accel) + a1_theta_prime.lazyProduct(theta_s);
  const S h = S(0.5) * dt, k = dt * dt / S(6);
  const Cols v_s = h * (a0_s + a1_s);
  const Cols p_s = k * (S(2) * a0_s + a1_s);

  ImuTransition<S, NI> f;
  f.dt = dt;
  f.theta_theta = r_d.transpose();
  f.v_theta = h * (a0_theta + a1_theta_prime * f.theta_theta);
  f.p_theta = k * (S(2) * a0_theta + a1_theta_prime * f.theta_theta);
  f.v_ba = v_s.template leftCols<3>();
  f.v_bg = v_s.template middleCols<3>(3);
  f.p_ba = p_s.template leftCols<3>();
  f.p_bg = p_s.template middleCols<3>(3);
  f.theta_bg = theta_s.template middleCols<3>(3);
  f.imu.theta_ba = theta_s.template leftCols<3>();
  f.imu.v = v_s.template rightCols<NI>();
  f.imu.p = p_s.template rightCols<NI>();
  f.imu.theta = theta_s.template rightCols<NI>();
  return f;
}

template <class State>
ImuTransition<typename State::Scalar, State::kImuIntrinsics> imu_transition(const State& x,
                                                                            const ImuSample& s0,
                                                                            const ImuSample& s1) {
  using S = typename State::Scalar;
  constexpr int NI = State::kImuIntrinsics;
  using F = ImuTransition<S, NI>;
  static_assert(State::kDynamicBegin == 0 && State::kDynamicDim == F::kDim && State::kV == 0 &&
                    State::kBa == 3 && State::kBg == 6 && State::kImu == F::kImu &&
                    State::kP == F::kP && State::kTheta == F::kTheta,
                "IMU block layout");
  if constexpr (NI > 0) {
    return imu_transition_with_intrinsics(x, s0, s1);
  } else {
    const S dt = S(static_cast<double>(s1.t_ns - s0.t_ns) * 1e-9);
    const Vec3<S> w0 = s0.gyro.cast<S>() - x.b_g;
    const Vec3<S> w1 = s1.gyro.cast<S>() - x.b_g;
    const Vec3<S> dtheta = (S(0.5) * dt) * (w0 + w1) + (dt * dt / S(12)) * w0.cross(w1);
    const Mat3<S> r_d = so3::exp<S>(dtheta).toRotationMatrix();
    const Mat3<S> r0 = x.q_n_b.toRotationMatrix();
    const Mat3<S> r1 = r0 * r_d;

    F f;
    f.dt = dt;
    // theta' = theta_theta theta + theta_bg db_g
    f.theta_theta = r_d.transpose();
    f.theta_bg =
        so3_right_jacobian<S>(dtheta) *
        (-dt * Mat3<S>::Identity() + (dt * dt / S(12)) * (so3::hat<S>(w1) - so3::hat<S>(w0)));
    // da_i = a_i_theta theta + a_i_ba db_a (+ a1_bg db_g)
    const Mat3<S> a0_theta = -r0 * so3::hat<S>(s0.accel.cast<S>() - x.b_a);
    const Mat3<S> a1_theta_prime = -r1 * so3::hat<S>(s1.accel.cast<S>() - x.b_a);
    const Mat3<S> a1_theta = a1_theta_prime * f.theta_theta;
    const Mat3<S> a1_bg = a1_theta_prime * f.theta_bg;

    const S h = S(0.5) * dt, k = dt * dt / S(6);
    f.v_ba = -h * (r0 + r1);
    f.v_bg = h * a1_bg;
    f.v_theta = h * (a0_theta + a1_theta);
    f.p_ba = -k * (S(2) * r0 + r1);
    f.p_bg = k * a1_bg;
    f.p_theta = k * (S(2) * a0_theta + a1_theta);
    return f;
  }
}

}  // namespace mirrorcal
