// Shared ground truth for the estimator tests: the paper's rig, an analytic trajectory with its
// exact IMU readings, and a mirror scene computed independently of mirror_model.hpp (reflection in
// the mirror frame, projection with the 3x3 K matrix). Built on Eigen's own AngleAxis so that the
// truth does not come from the code under test.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal::test {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

inline Eigen::Matrix3d skew(const Eigen::Vector3d& w) {
  Eigen::Matrix3d m;
  m << 0.0, -w.z(), w.y(), w.z(), 0.0, -w.x(), -w.y(), w.x(), 0.0;
  return m;
}

// Rotation vector -> rotation, through Eigen's AngleAxis (independent of so3::exp).
inline Eigen::Quaterniond rotvec(const Eigen::Vector3d& phi) {
  const double a = phi.norm();
  if (a == 0.0) return Eigen::Quaterniond::Identity();
  return Eigen::Quaterniond(Eigen::AngleAxisd(a, phi / a));
}

// Right Jacobian of SO(3): d/dt Exp(theta) = Exp(theta) [J_r(theta) theta_dot]_x.
inline Eigen::Matrix3d right_jacobian(const Eigen::Vector3d& theta) {
  const double a = theta.norm();
  const Eigen::Matrix3d k = skew(theta);
  if (a < 1e-5) return Eigen::Matrix3d::Identity() - 0.5 * k + (1.0 / 6.0) * k * k;
  return Eigen::Matrix3d::Identity() - (1.0 - std::cos(a)) / (a * a) * k +
         (a - std::sin(a)) / (a * a * a) * k * k;
}

// The rig of the paper's Tables I-III. R_b_c = Rz(-90) Ry(0) Rx(-90): the optical axis is body x,
// image x is body -y, image y is body -z.
struct Rig {
  Eigen::Vector3d p_b_c{0.01, -0.05, 0.10};
  Eigen::Quaterniond q_b_c =
      Eigen::Quaterniond(Eigen::AngleAxisd(-90.0 * kDeg, Eigen::Vector3d::UnitZ()) *
                         Eigen::AngleAxisd(-90.0 * kDeg, Eigen::Vector3d::UnitX()));
  std::array<Eigen::Vector3d, 3> markers{Eigen::Vector3d(0.02, -0.03, -0.03),
                                         Eigen::Vector3d(0.05, 0.04, -0.03),
                                         Eigen::Vector3d(-0.08, 0.06, 0.01)};
  // The paper's camera in its centred coordinates (cu, cv from the image centre): these tests
  // render their markers with it and give the filter the same camera (pinhole()), so the
  // convention does not matter here.
  double fu = 833.33, fv = 833.33, cu = 2.0, cv = 8.0, skew = 3.0;

  // The camera for CalibrationConfig::intrinsics.
  Pinhole<double> pinhole() const { return {fu, fv, cu, cv, skew}; }

  Eigen::Matrix3d k_matrix() const {
    Eigen::Matrix3d k;
    k << fu, skew, cu, 0.0, fv, cv, 0.0, 0.0, 1.0;
    return k;
  }
};

// p(t) = p0 + pa .* sin(pw t + pph); R_n_b(t) = R0 Exp(theta(t)), theta_i = ra_i sin(rw_i t +
// rph_i).
struct SineTrajectory {
  Eigen::Vector3d p0 = Eigen::Vector3d::Zero(), pa = Eigen::Vector3d::Zero(),
                  pw = Eigen::Vector3d::Ones(), pph = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q0 = Eigen::Quaterniond::Identity();
  Eigen::Vector3d ra = Eigen::Vector3d::Zero(), rw = Eigen::Vector3d::Ones(),
                  rph = Eigen::Vector3d::Zero();
  Eigen::Vector3d gravity_n{0.0, -9.81, 0.0};

  Eigen::Vector3d position(double t) const {
    return p0 + pa.cwiseProduct((pw * t + pph).array().sin().matrix());
  }
  Eigen::Vector3d velocity(double t) const {
    return pa.cwiseProduct(pw).cwiseProduct((pw * t + pph).array().cos().matrix());
  }
  Eigen::Vector3d acceleration(double t) const {
    return -pa.cwiseProduct(pw).cwiseProduct(pw).cwiseProduct(
        (pw * t + pph).array().sin().matrix());
  }
  Eigen::Vector3d theta(double t) const {
    return ra.cwiseProduct((rw * t + rph).array().sin().matrix());
  }
  Eigen::Vector3d theta_dot(double t) const {
    return ra.cwiseProduct(rw).cwiseProduct((rw * t + rph).array().cos().matrix());
  }
  Eigen::Quaterniond attitude(double t) const { return q0 * rotvec(theta(t)); }
  Eigen::Vector3d body_rate(double t) const { return right_jacobian(theta(t)) * theta_dot(t); }
  // Specific force in b: R_n_b^T (a_n - g_n).
  Eigen::Vector3d specific_force(double t) const {
    return attitude(t).toRotationMatrix().transpose() * (acceleration(t) - gravity_n);
  }
  ImuSample imu(std::int64_t t_ns) const {
    const double t = static_cast<double>(t_ns) * 1e-9;
    ImuSample s;
    s.t_ns = t_ns;
    s.gyro = body_rate(t);
    s.accel = specific_force(t);
    return s;
  }
};

// Ground truth pose of the IMU at t as a filter state (biases zero).
template <typename S, int M, int NK>
MirrorState<S, M, NK> truth_state(const SineTrajectory& traj, const Rig& rig, double t) {
  MirrorState<S, M, NK> x;
  x.v = traj.velocity(t).cast<S>();
  x.p = traj.position(t).cast<S>();
  x.q_n_b = traj.attitude(t).cast<S>();
  x.p_b_c = rig.p_b_c.cast<S>();
  x.q_b_c = rig.q_b_c.cast<S>();
  for (int i = 0; i < M; ++i) x.markers.template segment<3>(3 * i) = rig.markers[i].cast<S>();
  if constexpr (NK >= 4) {
    x.intrinsics(0) = S(rig.fu);
    x.intrinsics(1) = S(rig.fv);
    x.intrinsics(2) = S(rig.cu);
    x.intrinsics(3) = S(rig.cv);
  }
  if constexpr (NK == 5) x.intrinsics(4) = S(rig.skew);
  return x;
}

// The mirror image of a marker, computed the long way round (paper eq. 9): marker into n, reflect
// through the plane z = 0, back into c.
inline Eigen::Vector3d reflect_in_n(const Eigen::Matrix3d& r_n_c, const Eigen::Vector3d& p_n_c,
                                    const Eigen::Vector3d& pi_c) {
  Eigen::Vector3d pi_n = r_n_c * pi_c + p_n_c;
  pi_n.z() = -pi_n.z();
  return r_n_c.transpose() * (pi_n - p_n_c);
}

// Pixel of every marker reflection for the rig at time t; false if any is not in front.
inline bool render_markers(const SineTrajectory& traj, const Rig& rig, double t,
                           std::array<Eigen::Vector2d, 3>& uv) {
  const Eigen::Matrix3d r_n_b = traj.attitude(t).toRotationMatrix();
  const Eigen::Matrix3d r_n_c = r_n_b * rig.q_b_c.toRotationMatrix();
  const Eigen::Vector3d p_n_c = traj.position(t) + r_n_b * rig.p_b_c;
  const Eigen::Matrix3d k = rig.k_matrix();
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d img = reflect_in_n(r_n_c, p_n_c, rig.markers[i]);
    if (!(img.z() > 0.05)) return false;
    const Eigen::Vector3d h = k * img;
    uv[i] = h.head<2>() / h.z();
  }
  return true;
}

// A rig waved in front of a wall mirror (gravity along -y of n, the reflective side z > 0): the
// camera (body x) faces the mirror from about 0.6 m and the rig rocks by up to ~0.45 rad about
// every axis at up to 3 rad/s, which makes the camera-IMU lever arm and all rotations observable
// (the lever arm along the optical axis only at second order: see ConvergesOnNoiseFreeData).
inline SineTrajectory wall_mirror_trajectory() {
  SineTrajectory tr;
  tr.gravity_n = Eigen::Vector3d(0.0, -9.81, 0.0);
  Eigen::Matrix3d r0;  // columns: body x -> -z_n (into the mirror), body y -> -x_n, body z -> +y_n
  r0.col(0) = Eigen::Vector3d(0, 0, -1);
  r0.col(1) = Eigen::Vector3d(-1, 0, 0);
  r0.col(2) = Eigen::Vector3d(0, 1, 0);
  tr.q0 = Eigen::Quaterniond(r0);
  tr.p0 = Eigen::Vector3d(0.0, 0.0, 0.6);
  tr.pa = Eigen::Vector3d(0.15, 0.10, 0.10);
  tr.pw = Eigen::Vector3d(2.0, 2.6, 3.1);
  tr.pph = Eigen::Vector3d(0.3, 1.1, 2.0);
  tr.ra = Eigen::Vector3d(0.375, 0.45, 0.30);
  tr.rw = Eigen::Vector3d(3.4, 4.6, 5.8);
  tr.rph = Eigen::Vector3d(0.5, 1.9, 2.7);
  return tr;
}

}  // namespace mirrorcal::test
