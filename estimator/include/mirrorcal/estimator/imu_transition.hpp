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
// and the biases are unchanged.
#pragma once

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

// F in its 3x3 blocks. In block rows and columns [v, b_a, b_g, p, theta]:
//   v'     = [ I     v_ba   v_bg   0   v_theta ]
//   b_a'   = [ 0     I      0      0   0       ]
//   b_g'   = [ 0     0      I      0   0       ]
//   p'     = [ dt I  p_ba   p_bg   I   p_theta ]
//   theta' = [ 0     0      th_bg  0   th_th   ]
// so applying it costs 8 products of 3x3 blocks instead of a dense 15x15 one.
template <typename S>
struct ImuTransition {
  S dt;
  Mat3<S> v_ba, v_bg, v_theta, p_ba, p_bg, p_theta, theta_bg, theta_theta;

  // out = F x, for x with the 15 rows of the IMU block; out must not alias x.
  template <class In, class Out>
  void left_multiply(const Eigen::MatrixBase<In>& x, Eigen::MatrixBase<Out>& out) const {
    const auto xv = x.template middleRows<3>(0), xba = x.template middleRows<3>(3),
               xbg = x.template middleRows<3>(6), xp = x.template middleRows<3>(9),
               xth = x.template middleRows<3>(12);
    // lazyProduct: coefficient-wise, which for a 3x3 factor beats the general matrix product.
    out.template middleRows<3>(0) =
        xv + v_ba.lazyProduct(xba) + v_bg.lazyProduct(xbg) + v_theta.lazyProduct(xth);
    out.template middleRows<3>(3) = xba;
    out.template middleRows<3>(6) = xbg;
    out.template middleRows<3>(9) =
        dt * xv + p_ba.lazyProduct(xba) + p_bg.lazyProduct(xbg) + xp + p_theta.lazyProduct(xth);
    out.template middleRows<3>(12) = theta_bg.lazyProduct(xbg) + theta_theta.lazyProduct(xth);
  }

  // out = x F^T, for x with the 15 columns of the IMU block; out must not alias x. Each column of
  // out is x's columns combined by a row of F: whole columns of x, contiguous, so for x = P's
  // IMU columns (P F^T = (F P)^T, P symmetric) this vectorises where left_multiply's 3-row blocks
  // cannot.
  template <class In, class Out>
  void right_multiply_transposed(const Eigen::MatrixBase<In>& x,
                                 Eigen::MatrixBase<Out>& out) const {
    const auto xv = x.template middleCols<3>(0), xba = x.template middleCols<3>(3),
               xbg = x.template middleCols<3>(6), xp = x.template middleCols<3>(9),
               xth = x.template middleCols<3>(12);
    for (int r = 0; r < 3; ++r) {
      out.col(r) =
          xv.col(r) + row_of(xba, v_ba, r) + row_of(xbg, v_bg, r) + row_of(xth, v_theta, r);
      out.col(9 + r) = dt * xv.col(r) + row_of(xba, p_ba, r) + row_of(xbg, p_bg, r) + xp.col(r) +
                       row_of(xth, p_theta, r);
      out.col(12 + r) = row_of(xbg, theta_bg, r) + row_of(xth, theta_theta, r);
    }
    out.template middleCols<6>(3) = x.template middleCols<6>(3);
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
    return c;
  }

  Eigen::Matrix<S, 15, 15> dense() const {
    Eigen::Matrix<S, 15, 15> f;
    left_multiply(Eigen::Matrix<S, 15, 15>::Identity(), f);
    return f;
  }
};

template <class State>
ImuTransition<typename State::Scalar> imu_transition(const State& x, const ImuSample& s0,
                                                     const ImuSample& s1) {
  using S = typename State::Scalar;
  static_assert(State::kDynamicBegin == 0 && State::kDynamicDim == 15 && State::kV == 0 &&
                    State::kBa == 3 && State::kBg == 6 && State::kP == 9 && State::kTheta == 12,
                "IMU block layout");
  const S dt = S(static_cast<double>(s1.t_ns - s0.t_ns) * 1e-9);
  const Vec3<S> w0 = s0.gyro.cast<S>() - x.b_g;
  const Vec3<S> w1 = s1.gyro.cast<S>() - x.b_g;
  const Vec3<S> dtheta = (S(0.5) * dt) * (w0 + w1) + (dt * dt / S(12)) * w0.cross(w1);
  const Mat3<S> r_d = so3::exp<S>(dtheta).toRotationMatrix();
  const Mat3<S> r0 = x.q_n_b.toRotationMatrix();
  const Mat3<S> r1 = r0 * r_d;

  ImuTransition<S> f;
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

}  // namespace mirrorcal
