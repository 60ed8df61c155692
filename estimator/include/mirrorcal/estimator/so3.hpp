// Rotations as unit quaternions (Hamilton, as Eigen stores them) with the exponential and
// logarithm maps that the error state uses. Header-only, fixed-size, no heap.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace mirrorcal::so3 {

template <typename S>
using Vec3 = Eigen::Matrix<S, 3, 1>;
template <typename S>
using Mat3 = Eigen::Matrix<S, 3, 3>;
template <typename S>
using Quat = Eigen::Quaternion<S>;

// Below this angle (rad) log, and exp below series_angle, take the first two terms of their
// series, whose truncation error is then below the scalar's epsilon (angle^4/1920 for exp in
// double at 1e-4 is ~5e-20).
template <typename S>
constexpr S small_angle() {
  return sizeof(S) == sizeof(float) ? S(1e-2) : S(1e-4);
}

template <typename S>
Mat3<S> hat(const Vec3<S>& w) {
  Mat3<S> m;
  m << S(0), -w.z(), w.y(), w.z(), S(0), -w.x(), -w.y(), w.x(), S(0);
  return m;
}

// Below this angle (rad) exp and the right Jacobian use their series to the sixth power, whose
// truncation (angle^8 / 1e7 relative) is below the scalar's epsilon there. The filter's rotations
// are mostly this small (a 5 ms IMU step, a sigma point's few milliradians), and the series costs
// a few multiplications where the trigonometric functions cost a library call each.
template <typename S>
constexpr S series_angle() {
  return sizeof(S) == sizeof(float) ? S(0.2) : S(0.05);
}

// Exp: rotation vector -> unit quaternion.
template <typename S>
Quat<S> exp(const Vec3<S>& phi) {
  const S a2 = phi.squaredNorm();
  S w, k;  // q = (w, k * phi): w = cos(angle / 2), k = sin(angle / 2) / angle
  if (a2 < small_angle<S>() * small_angle<S>()) {  // the series' first two terms suffice
    w = S(1) - a2 / S(8);
    k = S(0.5) - a2 / S(48);
  } else if (a2 < series_angle<S>() * series_angle<S>()) {
    w = S(1) - a2 / S(8) * (S(1) - a2 / S(48) * (S(1) - a2 / S(120)));
    k = S(0.5) * (S(1) - a2 / S(24) * (S(1) - a2 / S(80) * (S(1) - a2 / S(168))));
  } else {
    using std::cos, std::sin, std::sqrt;  // unqualified: autodiff's scalars bring their own
    const S angle = sqrt(a2);
    w = cos(S(0.5) * angle);
    k = sin(S(0.5) * angle) / angle;
  }
  Quat<S> q(w, k * phi.x(), k * phi.y(), k * phi.z());
  return q;
}

// Log: unit quaternion -> rotation vector with angle in [0, pi]. q and -q give the same result.
template <typename S>
Vec3<S> log(const Quat<S>& q_in) {
  Quat<S> q = q_in;
  if (q.w() < S(0)) q.coeffs() = -q.coeffs();
  const Vec3<S> v = q.vec();
  // The series in sin^2, not sin: the norm's square root has no derivative at the identity, which
  // an autodiff scalar (the batch solver's) would carry as NaN.
  const S sin_half2 = v.squaredNorm();
  if (sin_half2 < small_angle<S>() * small_angle<S>()) {
    // angle = 2 asin(s) ~ 2 s (1 + s^2/6); divide by w for the tan form's accuracy.
    return (S(2) / q.w()) * (S(1) - sin_half2 / (S(3) * q.w() * q.w())) * v;
  }
  using std::atan2, std::sqrt;
  const S sin_half = sqrt(sin_half2);
  const S angle = S(2) * atan2(sin_half, q.w());
  return (angle / sin_half) * v;
}

// Right (body-frame) perturbation: q boxplus d = q * Exp(d); boxminus is its inverse. (Qualified
// calls: unqualified, argument-dependent lookup would offer Eigen's array exp and log too.)
template <typename S>
Quat<S> boxplus(const Quat<S>& q, const Vec3<S>& d) {
  return (q * so3::exp<S>(d)).normalized();
}

template <typename S>
Vec3<S> boxminus(const Quat<S>& a, const Quat<S>& b) {
  return so3::log<S>(b.conjugate() * a);
}

}  // namespace mirrorcal::so3
