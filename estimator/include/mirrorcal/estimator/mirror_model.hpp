// The mirror calibration model of Panahandeh & Jansson (paper eqs. (1)-(15)) in the names and
// conventions of docs/design.md: the state, IMU propagation, the mirror image of a rig-fixed marker
// (eq. 11) and the pinhole projection (eqs. 12, 13).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string_view>
#include <type_traits>

#include "mirrorcal/estimator/imu_intrinsics.hpp"
#include "mirrorcal/estimator/so3.hpp"

namespace mirrorcal {

template <typename S>
using Vec2 = Eigen::Matrix<S, 2, 1>;
using so3::Mat3;
using so3::Quat;
using so3::Vec3;

// One IMU sample: body-frame angular rate (rad/s) and specific force (m/s^2).
struct ImuSample {
  std::int64_t t_ns = 0;
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();
};

// IMU noise in Kalibr's continuous-time units: white noise densities (rad/s/sqrt(Hz),
// m/s^2/sqrt(Hz)) and bias random walks (rad/s^2/sqrt(Hz), m/s^3/sqrt(Hz)).
struct ImuNoise {
  double gyro_noise_density = 1.6968e-4;  // EuRoC imu0 (ADIS16448)
  double gyro_random_walk = 1.9393e-5;
  double accel_noise_density = 2.0e-3;
  double accel_random_walk = 3.0e-3;
};

// Lens distortion of the normalised image point (x, y) = (X/Z, Y/Z), as Kalibr and OpenCV define
// it: radtan, the Brown-Conrady model of cv::projectPoints (k1, k2, p1, p2), or equidistant, the
// fisheye model of cv::fisheye::projectPoints (k1..k4).
enum class Distortion : std::uint8_t { kNone, kRadtan, kEquidistant };

// Kalibr's name of a distortion model (camchain.yaml's distortion_model), and back. Files say
// "radtan" with zero coefficients for kNone: the same camera, in a form every reader knows.
inline const char* to_string(Distortion d) {
  return d == Distortion::kRadtan        ? "radtan"
         : d == Distortion::kEquidistant ? "equidistant"
                                         : "none";
}
inline bool distortion_from_string(std::string_view name, Distortion& d) {
  for (const Distortion c : {Distortion::kNone, Distortion::kRadtan, Distortion::kEquidistant})
    if (name == to_string(c)) {
      d = c;
      return true;
    }
  return false;
}

// A camera as Kalibr models one: projection, lens and shutter. Pinhole intrinsics, in the state's
// order, after the lens's distortion of the normalised point: u = fu x_d + skew y_d + cu,
// v = fv y_d + cv. The distortion model and the shutter are known (from camchain.yaml); the
// coefficients are known, or estimated in stage 2 (NK = 8, intrinsics_of).
template <typename S>
struct Pinhole {
  S fu, fv, cu, cv, skew;
  Distortion distortion = Distortion::kNone;
  std::array<S, 4> coeffs{};  // radtan: k1 k2 p1 p2; equidistant: k1 k2 k3 k4
  // A rolling shutter reads row v line_delay_s * v after row 0, which the frame's stamp is for
  // (Kalibr's RollingShutter: the temporal offset of a keypoint is line delay times its row).
  // 0: a global shutter.
  S line_delay_s = S(0);
  // The exposure (s), the frame's stamp at its middle. A spot moving over it is smeared, and its
  // centroid is the mean of its projection over the exposure (ExposedMirror). 0: not modelled.
  S exposure_s = S(0);

  template <typename T>
  Pinhole<T> cast() const {
    return {T(fu),
            T(fv),
            T(cu),
            T(cv),
            T(skew),
            distortion,
            {T(coeffs[0]), T(coeffs[1]), T(coeffs[2]), T(coeffs[3])},
            T(line_delay_s),
            T(exposure_s)};
  }
};

// The 1-sigma of a lens's distortion coefficients before calibrating (Pinhole::coeffs order), the
// spread of real lenses: radtan k1 -0.45..0 (k1 = -0.28 for EuRoC's 2.8 mm lens), k2 0..0.3,
// decentring p1, p2 within a few 1e-3; equidistant k1..k4 within a few 1e-2 (Kalibr's fisheye
// calibrations of the T265, EuRoC, TUM-VI lenses).
inline std::array<double, 4> default_sigma_distortion(Distortion d) {
  if (d == Distortion::kEquidistant) return {0.05, 0.05, 0.05, 0.05};
  return {0.2, 0.1, 0.002, 0.002};
}

// The radtan polynomial describes a lens only within its field: rays up to about 60 deg off the
// optical axis (r^2 = x^2 + y^2 = tan^2 60 deg = 3; wider lenses take the fisheye model). Beyond,
// it grows as r^5, and the sigma points the filter spreads over a wide prior (sqrt(n) times a
// marker's 10 cm) would land tens of image widths away: EuRoC's lens put r = 3 at 13.6 where the
// pinhole says 3, and two of 100 paper runs lost their markers in the first pass and never found
// them again. So the radial factor is held at its value there (the model stays continuous in r
// and in the coefficients, and exact within the field, where every observation lies).
constexpr double kRadtanMaxR2 = 3.0;

// The distorted normalised point of (x, y).
template <typename S>
Vec2<S> distort(const Pinhole<S>& k, S x, S y) {
  const std::array<S, 4>& c = k.coeffs;
  switch (k.distortion) {
    case Distortion::kRadtan: {
      const S r2 = x * x + y * y;
      const S rr = std::min(r2, S(kRadtanMaxR2));
      const S radial = S(1) + rr * (c[0] + rr * c[1]);
      return Vec2<S>(x * radial + S(2) * c[2] * x * y + c[3] * (r2 + S(2) * x * x),
                     y * radial + c[2] * (r2 + S(2) * y * y) + S(2) * c[3] * x * y);
    }
    case Distortion::kEquidistant: {
      using std::atan, std::sqrt;  // unqualified: autodiff's scalars bring their own
      const S r = sqrt(x * x + y * y);
      if (r < S(1e-9)) return Vec2<S>(x, y);  // theta_d / r -> 1 on the axis
      const S theta = atan(r), t2 = theta * theta;
      const S theta_d = theta * (S(1) + t2 * (c[0] + t2 * (c[1] + t2 * (c[2] + t2 * c[3]))));
      return Vec2<S>(x, y) * (theta_d / r);
    }
    case Distortion::kNone:
      break;
  }
  return Vec2<S>(x, y);
}

// The mirror images of the M markers seen in one frame (any subset).
template <int M>
struct MarkerFrame {
  std::int64_t t_ns = 0;
  std::array<bool, M> seen{};
  std::array<Eigen::Vector2d, M> uv{};
};

// Points nearer than this to the camera plane (m) are not projected: behind the camera or at it.
constexpr double kMinDepth = 1e-3;

// Projection through the lens; false when the point is not in front of the camera.
template <typename S>
bool project(const Pinhole<S>& k, const Vec3<S>& p_c, Vec2<S>& uv) {
  if (!(p_c.z() > S(kMinDepth))) return false;
  const S inv_z = S(1) / p_c.z();
  const Vec2<S> d = distort(k, p_c.x() * inv_z, p_c.y() * inv_z);
  uv.x() = k.fu * d.x() + k.skew * d.y() + k.cu;
  uv.y() = k.fv * d.y() + k.cv;
  return true;
}

// Mirror image, in c, of a point pi_c fixed in the camera frame, for the mirror z = 0 of n and a
// camera at (R_n_c, p_n_c): pi_hat = pi - 2 R_n_c^T e_z e_z^T (R_n_c pi + p_n_c)  (paper eq. 11).
template <typename S>
Vec3<S> mirror_image(const Mat3<S>& r_n_c, const Vec3<S>& p_n_c, const Vec3<S>& pi_c) {
  const S height = r_n_c.row(2).dot(pi_c) + p_n_c.z();  // e_z^T (R_n_c pi + p_n_c)
  return pi_c - (S(2) * height) * r_n_c.row(2).transpose();
}

// A run of consecutive indices [begin, begin + size).
struct IndexRange {
  int begin = 0, size = 0;
  constexpr int end() const { return begin + size; }
  constexpr bool contains(int i) const { return i >= begin && i < end(); }
};

// The groups of the calibration parameters, in the state's order.
enum class CalibrationGroup : std::uint8_t {
  kCameraPosition,  // p_b_c (m)
  kCameraRotation,  // phi, the rotation error of R_b_c (rad)
  kMarkers,         // pi_i^c, three per marker (m)
  kTimeOffset,      // t_d (s)
  kIntrinsics,      // fu fv cu cv, and skew when estimated (px)
  kLens,            // the lens's four distortion coefficients (NK = 8; unitless)
};
constexpr int kCalibrationGroups = 6;

// Where each group lies in the calibration block [p_b_c, phi, markers, t_d, intrinsics], counted
// from the block's start. A group not estimated is empty, at the end of the one before it.
struct CalibrationLayout {
  std::array<IndexRange, kCalibrationGroups> groups{};

  constexpr IndexRange operator[](CalibrationGroup g) const {
    return groups[static_cast<std::size_t>(g)];
  }
  constexpr int size() const { return groups.back().end(); }
  // The group of the block's j-th parameter (0 <= j < size()).
  constexpr CalibrationGroup group_of(int j) const {
    int g = 0;
    while (g + 1 < kCalibrationGroups && !groups[static_cast<std::size_t>(g)].contains(j)) ++g;
    return static_cast<CalibrationGroup>(g);
  }
};

// The calibration block of `markers` markers and `intrinsics` estimated camera parameters
// (MirrorState's NK: 0, 4, 5 or 8, of which 8 are fu fv cu cv and the lens's coefficients), with
// or without the time offset (results written before it was estimated have none). For code that
// learns these counts at run time (a result read from a file); MirrorState<S, M, NK>::kCalibration
// is the same layout for its M and NK.
constexpr CalibrationLayout calibration_layout(int markers, int intrinsics, bool has_t_d = true) {
  const int lens = intrinsics == 8 ? 4 : 0;
  const std::array<int, kCalibrationGroups> sizes = {
      3, 3, 3 * markers, has_t_d ? 1 : 0, intrinsics - lens, lens};
  CalibrationLayout l;
  int next = 0;
  for (std::size_t g = 0; g < sizes.size(); ++g) {
    l.groups[g] = {next, sizes[g]};
    next += sizes[g];
  }
  return l;
}

// Calibration state: stage 1 has NK = 0 (22 + 3M error states); stage 2 adds the intrinsics
// (NK = 5: fu, fv, cu, cv, skew; NK = 4 holds skew at the configured value; NK = 8: fu, fv, cu,
// cv and the lens's four distortion coefficients, skew held, OpenVINS's eight camera parameters).
// NI more states hold the IMU's intrinsics (imu_intrinsics.hpp: 0, 12, 15 or 24, the ImuModel's).
//
// The error state is ordered so that the two structured operations touch contiguous blocks:
// IMU propagation changes [v, b_a, b_g, imu, p, theta] = [0, 15 + NI) (the IMU's intrinsics are
// constants, but the propagation's Jacobian reaches them as it does the biases), the camera reads
// [p, theta, p_b_c, phi, markers, t_d, intrinsics] = [kP, kDim). Rotations are perturbed on the
// right (body side): R_n_b = R^_n_b Exp(theta), R_b_c = R^_b_c Exp(phi), so phi is the rotation
// error log(R_b_c,true^T R_b_c,est) up to sign, the figure the paper's tables report.
template <typename S, int M, int NK, int NI = 0>
struct MirrorState {
  static_assert(M >= 1, "at least one marker");
  static_assert(NK == 0 || NK == 4 || NK == 5 || NK == 8,
                "intrinsics: none, fu fv cu cv, with skew, or with the distortion coefficients");
  static_assert(NI == imu_intrinsics_dim(imu_model_of_dim(NI)), "an ImuModel's dimension");
  using Scalar = S;
  static constexpr int kMarkers = M;
  static constexpr int kIntrinsics = NK;
  static constexpr int kImuIntrinsics = NI;
  static constexpr ImuModel kImuModel = imu_model_of_dim(NI);
  // Every block of the error state, {index, dimension}, in order; the rest derives from them.
  static constexpr IndexRange kVelocity{0, 3}, kAccelBias{kVelocity.end(), 3},
      kGyroBias{kAccelBias.end(), 3}, kImuBlock{kGyroBias.end(), NI}, kPosition{kImuBlock.end(), 3},
      kAttitude{kPosition.end(), 3}, kCameraPosition{kAttitude.end(), 3},
      kCameraRotation{kCameraPosition.end(), 3}, kMarkerBlock{kCameraRotation.end(), 3 * M},
      kTimeOffset{kMarkerBlock.end(), 1}, kCameraBlock{kTimeOffset.end(), NK};
  static constexpr int kV = kVelocity.begin, kBa = kAccelBias.begin, kBg = kGyroBias.begin,
                       kImu = kImuBlock.begin, kP = kPosition.begin, kTheta = kAttitude.begin,
                       kPbc = kCameraPosition.begin, kPhi = kCameraRotation.begin,
                       kPi = kMarkerBlock.begin, kTd = kTimeOffset.begin, kK = kCameraBlock.begin,
                       kDim = kCameraBlock.end();
  // The block the IMU moves: velocity to attitude. Its sensor parameters [b_a, b_g, imu] are the
  // constants the propagation's Jacobian reaches.
  static constexpr int kDynamicBegin = kVelocity.begin, kDynamicDim = kAttitude.end();
  static constexpr IndexRange kSensorBlock{kAccelBias.begin, 6 + NI};
  static constexpr int kMeasuredBegin = kP, kMeasuredDim = kDim - kP;
  // The calibration block [p_b_c, phi, markers, t_d, intrinsics], what a calibration reports, and
  // its groups (counted from kCalibrationBegin).
  static constexpr int kCalibrationBegin = kPbc, kCalibrationDim = kDim - kPbc;
  static constexpr int kLensCoeffs = NK == 8 ? 4 : 0;  // the intrinsics' last ones
  static constexpr CalibrationLayout kCalibration = {{{
      {kPbc - kPbc, 3},
      {kPhi - kPbc, 3},
      {kPi - kPbc, 3 * M},
      {kTd - kPbc, 1},
      {kK - kPbc, NK - kLensCoeffs},
      {kDim - kLensCoeffs - kPbc, kLensCoeffs},
  }}};

  Vec3<S> v = Vec3<S>::Zero();    // IMU velocity in n (m/s)
  Vec3<S> b_a = Vec3<S>::Zero();  // accelerometer bias (m/s^2)
  Vec3<S> b_g = Vec3<S>::Zero();  // gyroscope bias (rad/s)
  Vec3<S> p = Vec3<S>::Zero();    // IMU position in n (m)
  Quat<S> q_n_b = Quat<S>::Identity();
  Vec3<S> p_b_c = Vec3<S>::Zero();  // camera position in b (m)
  Quat<S> q_b_c = Quat<S>::Identity();
  Eigen::Matrix<S, 3 * M, 1> markers = Eigen::Matrix<S, 3 * M, 1>::Zero();  // pi_i^c (m)
  // The camera-IMU time offset (s), Kalibr's timeshift_cam_imu: a frame stamped t_cam shows the
  // rig as it was at IMU time t_cam + t_d.
  S t_d = S(0);
  // fu fv cu cv [skew | c0 c1 c2 c3: the lens's Pinhole::coeffs]
  Eigen::Matrix<S, NK, 1> intrinsics = Eigen::Matrix<S, NK, 1>::Zero();
  // The IMU's intrinsics (NI > 0; nothing otherwise).
  std::conditional_t<(NI > 0), ImuIntrinsics<S>, NoImuIntrinsics> imu{};

  Vec3<S> marker(int i) const { return markers.template segment<3>(3 * i); }

  // The specific force (m/s^2) and body rate (rad/s) of the IMU frame that raw samples f_m, w_m
  // read at this state's biases and intrinsics (imu_intrinsics.hpp).
  Vec3<S> specific_force(const Vec3<S>& f_m) const {
    if constexpr (NI == 0) {
      return f_m - b_a;
    } else {
      return imu.d_a * (f_m - b_a);
    }
  }
  Vec3<S> body_rate(const Vec3<S>& w_m, const Vec3<S>& f_m) const {
    if constexpr (NI == 0) {
      (void)f_m;
      return w_m - b_g;
    } else if constexpr (NI < 24) {
      (void)f_m;
      return imu.d_g * (w_m - b_g);
    } else {
      return imu.d_g * (w_m - b_g - imu.t_s * specific_force(f_m));
    }
  }
  // The body rate's change that a change of the raw gyro signal reads.
  Vec3<S> body_rate_change(const Vec3<S>& dw_m) const {
    if constexpr (NI == 0) {
      return dw_m;
    } else {
      return imu.d_g * dw_m;
    }
  }
  // The raw gyro sample that reads body rate w with specific force a (body_rate's inverse).
  Vec3<S> gyro_sample(const Vec3<S>& w, const Vec3<S>& a) const {
    if constexpr (NI == 0) {
      (void)a;
      return w + b_g;
    } else {
      return gyro_reading(imu, b_g, w, a);
    }
  }

  template <int B, int L>
  void boxplus_block(const Eigen::Matrix<S, L, 1>& d) {
    add<B, L, kV>(v, d);
    add<B, L, kBa>(b_a, d);
    add<B, L, kBg>(b_g, d);
    if constexpr (NI > 0 && covers<B, L, kImu, NI>())
      imu.template add<NI>(d.template segment<NI>(kImu - B));
    add<B, L, kP>(p, d);
    if constexpr (covers<B, L, kTheta, 3>()) rotate(q_n_b, d.template segment<3>(kTheta - B));
    add<B, L, kPbc>(p_b_c, d);
    if constexpr (covers<B, L, kPhi, 3>()) rotate(q_b_c, d.template segment<3>(kPhi - B));
    add<B, L, kPi>(markers, d);
    if constexpr (covers<B, L, kTd, 1>()) t_d += d(kTd - B);
    if constexpr (NK > 0) add<B, L, kK>(intrinsics, d);
  }

  template <int B, int L>
  Eigen::Matrix<S, L, 1> boxminus_block(const MirrorState& ref) const {
    Eigen::Matrix<S, L, 1> d;
    sub<B, L, kV>(v, ref.v, d);
    sub<B, L, kBa>(b_a, ref.b_a, d);
    sub<B, L, kBg>(b_g, ref.b_g, d);
    if constexpr (NI > 0 && covers<B, L, kImu, NI>()) {
      auto block = d.template segment<NI>(kImu - B);
      imu.template difference<NI>(ref.imu, block);
    }
    sub<B, L, kP>(p, ref.p, d);
    if constexpr (covers<B, L, kTheta, 3>())
      d.template segment<3>(kTheta - B) = so3::boxminus<S>(q_n_b, ref.q_n_b);
    sub<B, L, kPbc>(p_b_c, ref.p_b_c, d);
    if constexpr (covers<B, L, kPhi, 3>())
      d.template segment<3>(kPhi - B) = so3::boxminus<S>(q_b_c, ref.q_b_c);
    sub<B, L, kPi>(markers, ref.markers, d);
    if constexpr (covers<B, L, kTd, 1>()) d(kTd - B) = t_d - ref.t_d;
    if constexpr (NK > 0) sub<B, L, kK>(intrinsics, ref.intrinsics, d);
    return d;
  }

 private:
  // q boxplus d, skipped when d is zero (where it would only renormalise q): most of the update's
  // sigma points leave both rotations as they are, the Cholesky factor being lower triangular.
  static void rotate(Quat<S>& q, const Vec3<S>& d) {
    if (d != Vec3<S>::Zero()) q = so3::boxplus<S>(q, d);
  }
  // Whether block [B, B+L) holds component [O, O+D); a block may not split a component.
  template <int B, int L, int O, int D>
  static constexpr bool covers() {
    static_assert(O + D <= B || O >= B + L || (O >= B && O + D <= B + L),
                  "an error-state block may not split a component");
    return O >= B && O + D <= B + L;
  }
  template <int B, int L, int O, class V>
  static void add(V& value, const Eigen::Matrix<S, L, 1>& d) {
    constexpr int D = V::RowsAtCompileTime;
    if constexpr (covers<B, L, O, D>()) value += d.template segment<D>(O - B);
  }
  template <int B, int L, int O, class V>
  static void sub(const V& a, const V& b, Eigen::Matrix<S, L, 1>& d) {
    constexpr int D = V::RowsAtCompileTime;
    if constexpr (covers<B, L, O, D>()) d.template segment<D>(O - B) = a - b;
  }
};

// The ideal IMU's dynamic block [v, b_a, b_g, p, theta]: the states the process noise reaches
// whatever the IMU's model (its intrinsics, constants, take none).
inline constexpr int kImuMotionDim = MirrorState<double, 1, 0>::kDynamicDim;

// The IMU signal at time t between samples s0 and s1: the parabola through the sample before s0,
// s0 and s1 when that sample is given (third-order accurate in the sample spacing), else the line
// through s0 and s1. Any three samples on one parabola give the same parabola, so splitting an
// interval at a sample taken from it (a frame time) and integrating the pieces with their own
// "before" samples integrates the same signal.
inline ImuSample imu_signal_at(const ImuSample* before, const ImuSample& s0, const ImuSample& s1,
                               std::int64_t t_ns) {
  const double t = static_cast<double>(t_ns - s0.t_ns);
  const double h1 = static_cast<double>(s1.t_ns - s0.t_ns);
  ImuSample out;
  out.t_ns = t_ns;
  if (before == nullptr) {
    const double f = h1 > 0.0 ? t / h1 : 0.0;
    out.gyro = s0.gyro + f * (s1.gyro - s0.gyro);
    out.accel = s0.accel + f * (s1.accel - s0.accel);
    return out;
  }
  const double h0 = static_cast<double>(s0.t_ns - before->t_ns);
  // Lagrange weights on the nodes -h0, 0, h1.
  const double wb = t * (t - h1) / (h0 * (h0 + h1));
  const double w0 = (t + h0) * (h1 - t) / (h0 * h1);
  const double w1 = (t + h0) * t / ((h0 + h1) * h1);
  out.gyro = wb * before->gyro + w0 * s0.gyro + w1 * s1.gyro;
  out.accel = wb * before->accel + w0 * s0.accel + w1 * s1.accel;
  return out;
}

// Integrates the nominal IMU state from sample s0 to s1.
// Without the sample before s0: second order. The rotation uses the mean bias-corrected rate plus
// the coning term dt^2/12 (w0 x w1) (exact for a linearly varying rate), velocity the trapezoid of
// the navigation-frame accelerations at both ends, position the matching dt^2 (2 a0 + a1)/6 (exact
// for linearly varying acceleration). Global errors fall as dt^2.
// With it: classical Runge-Kutta (fourth order) on the parabola through the three samples
// (imu_signal_at), so the error is the signal reconstruction's, falling as dt^3. On a rig tilting
// at 2 Hz and 200 Hz sampling the second-order scheme's errors are large enough to make marker
// depths over-confident at 60 Hz frames (docs/estimator.md, "IMU propagation"; tested by
// ImuPropagation.ParabolaThroughThreeSamplesFallsAsDtCubed, propagation_test.cpp).
template <class State>
void propagate_imu(State& x, const ImuSample& s0, const ImuSample& s1,
                   const Vec3<typename State::Scalar>& gravity_n,
                   const ImuSample* before = nullptr) {
  using S = typename State::Scalar;
  const S dt = S(static_cast<double>(s1.t_ns - s0.t_ns) * 1e-9);
  if (before == nullptr) {
    const Vec3<S> f0 = s0.accel.cast<S>(), f1 = s1.accel.cast<S>();
    const Vec3<S> w0 = x.body_rate(s0.gyro.cast<S>(), f0);
    const Vec3<S> w1 = x.body_rate(s1.gyro.cast<S>(), f1);
    const Mat3<S> r0 = x.q_n_b.toRotationMatrix();
    const Vec3<S> dtheta = (S(0.5) * dt) * (w0 + w1) + (dt * dt / S(12)) * w0.cross(w1);
    x.q_n_b = (x.q_n_b * so3::exp<S>(dtheta)).normalized();
    const Mat3<S> r1 = x.q_n_b.toRotationMatrix();
    const Vec3<S> a0 = r0 * x.specific_force(f0) + gravity_n;
    const Vec3<S> a1 = r1 * x.specific_force(f1) + gravity_n;
    x.p += dt * x.v + (dt * dt / S(6)) * (S(2) * a0 + a1);
    x.v += (S(0.5) * dt) * (a0 + a1);
    return;
  }
  // y = (q, v, p); y' = (q (0, w/2), R(q) f + g, v) with w, f bias-corrected samples of the signal.
  struct Rate {
    Eigen::Matrix<S, 4, 1> q;
    Vec3<S> v, p;
  };
  const ImuSample mid = imu_signal_at(before, s0, s1, s0.t_ns + (s1.t_ns - s0.t_ns) / 2);
  const auto rate = [&](const ImuSample& sig, const Eigen::Matrix<S, 4, 1>& qc, const Vec3<S>& v) {
    const Eigen::Quaternion<S> q(qc);  // coeffs order x, y, z, w
    const Vec3<S> f = sig.accel.cast<S>();
    const Vec3<S> w = x.body_rate(sig.gyro.cast<S>(), f);
    Rate r;
    r.q = (q * Eigen::Quaternion<S>(S(0), S(0.5) * w.x(), S(0.5) * w.y(), S(0.5) * w.z())).coeffs();
    r.v = q.toRotationMatrix() * x.specific_force(f) + gravity_n;
    r.p = v;
    return r;
  };
  const Eigen::Matrix<S, 4, 1> q0 = x.q_n_b.coeffs();
  const Rate k1 = rate(s0, q0, x.v);
  const Rate k2 = rate(mid, q0 + S(0.5) * dt * k1.q, x.v + S(0.5) * dt * k1.v);
  const Rate k3 = rate(mid, q0 + S(0.5) * dt * k2.q, x.v + S(0.5) * dt * k2.v);
  const Rate k4 = rate(s1, q0 + dt * k3.q, x.v + dt * k3.v);
  const S sixth = dt / S(6);
  x.q_n_b =
      Eigen::Quaternion<S>(q0 + sixth * (k1.q + S(2) * k2.q + S(2) * k3.q + k4.q)).normalized();
  x.p += sixth * (k1.p + S(2) * k2.p + S(2) * k3.p + k4.p);
  x.v += sixth * (k1.v + S(2) * k2.v + S(2) * k3.v + k4.v);
}

// Discrete process noise over the dynamic block [v, b_a, b_g, imu, p, theta] (MirrorState's, of D
// states: the IMU's intrinsics, constants, take none) for an interval dt, from the continuous
// densities: white accelerometer noise integrates into v (sigma^2 dt), p (sigma^2 dt^3/3) with
// their correlation (sigma^2 dt^2/2); white gyro noise into theta; the bias random walks into the
// biases. The noise is isotropic, so rotating it into n changes nothing.
template <typename S, int D>
void add_imu_process_noise(const ImuNoise& n, double dt, Eigen::Matrix<S, D, D>& p) {
  using Layout =
      MirrorState<S, 1, 0, D - kImuMotionDim>;  // the dynamic block's layout is the same for any M
  const double sa2 = n.accel_noise_density * n.accel_noise_density;
  const double sg2 = n.gyro_noise_density * n.gyro_noise_density;
  const auto add = [&p](int row, int col, double q) {  // q I on one 3x3 block
    for (int i = 0; i < 3; ++i) p(row + i, col + i) += S(q);
  };
  constexpr int kV = Layout::kV, kP = Layout::kP;
  add(kV, kV, sa2 * dt);
  add(Layout::kBa, Layout::kBa, n.accel_random_walk * n.accel_random_walk * dt);
  add(Layout::kBg, Layout::kBg, n.gyro_random_walk * n.gyro_random_walk * dt);
  add(kP, kP, sa2 * dt * dt * dt / 3.0);
  add(kV, kP, sa2 * dt * dt / 2.0);
  add(kP, kV, sa2 * dt * dt / 2.0);
  add(Layout::kTheta, Layout::kTheta, sg2 * dt);
}

// The same as a matrix.
template <typename S, int D = kImuMotionDim>
Eigen::Matrix<S, D, D> imu_process_noise(const ImuNoise& n, double dt) {
  Eigen::Matrix<S, D, D> q = Eigen::Matrix<S, D, D>::Zero();
  add_imu_process_noise<S, D>(n, dt, q);
  return q;
}

// What the rig may do while the IMU is silent. Across a gap the loop integrates the straight line
// between the samples either side; a smooth signal whose second derivative is at most `*_jerk`
// strays from that chord by at most jerk T^2 / 8 over a gap of T, and never by more than
// `*_range`. The defaults cover the paper's rig (6 deg tilts at 2 Hz: 190 rad/s^3; gravity turning
// with them in the accelerometer: about 250 m/s^4).
struct GapMotion {
  double gyro_jerk = 300.0;   // rad/s^3
  double gyro_range = 5.0;    // rad/s
  double accel_jerk = 300.0;  // m/s^4
  double accel_range = 20.0;  // m/s^2
};

// The noise densities over a gap of gap_s: the sensor's, plus a white noise standing for the
// unknown signal, whose integral over the gap has the chord bound times the gap as its 1-sigma.
inline ImuNoise noise_across_gap(const ImuNoise& sensor, const GapMotion& m, double gap_s) {
  const auto density = [gap_s](double noise, double jerk, double range) {
    const double stray = std::min(range, jerk * gap_s * gap_s / 8.0);
    return std::sqrt(noise * noise + stray * stray * gap_s);
  };
  ImuNoise n = sensor;
  n.gyro_noise_density = density(sensor.gyro_noise_density, m.gyro_jerk, m.gyro_range);
  n.accel_noise_density = density(sensor.accel_noise_density, m.accel_jerk, m.accel_range);
  return n;
}

// 1-sigma of where the rig may be after an IMU gap too long to propagate across, about where it
// was before it, at rest: the rig's range of motion in front of the mirror. The attitude's is
// narrower than a fast rig's tilts: from 0.5 rad the first frames after the restart could settle
// on a wrong pose and pull the calibration along, and no rig did worse for the narrower width
// (docs/estimator.md, "IMU gaps"; tested by
// ImuGap.Of5SRestartsTheMotionStatesAndTheCalibrationStaysConsistent, imu_gap_test.cpp).
struct MotionRange {
  double position = 0.3;  // m
  double velocity = 1.0;  // m/s
  double attitude = 0.2;  // rad, per axis
};

// A frame's exposure against the filter's time: the frame is stamped stamp_minus_filter_s after
// the filter's time t_f (seconds, either sign), and gyro and accel are the IMU signal at t_f. The
// frame shows the rig at IMU time t_cam + t_d, shift = stamp_minus_filter_s + t_d after t_f. The
// loop brings the filter to t_cam + t_d at the estimate (CalibrationLoop::step), so the shift is
// zero at the mean and, in a sigma point, the time offset's deviation: short enough that the pose
// there is the filter's moved on by the rates at t_f (Li & Mourikis 2014, as OpenVINS does).
// A rolling shutter reads each marker's row later (predict_markers): milliseconds from the filter's
// time even at the mean, over which the rate's change matters on a rig tilting at 2 Hz (0.17 px
// at 30 us per row without it), so the gyro's rate of change comes along.
template <typename S>
struct Exposure {
  S stamp_minus_filter_s = S(0);
  Vec3<S> gyro = Vec3<S>::Zero();       // rad/s, raw (the state's bias is removed here)
  Vec3<S> gyro_rate = Vec3<S>::Zero();  // rad/s^2, the gyro signal's derivative
  Vec3<S> accel = Vec3<S>::Zero();      // m/s^2, raw
  Vec3<S> gravity_n = Vec3<S>::Zero();
};

// The mirror as the camera sees it at an exposure: the mirror's normal (e_z of n) in c and the
// camera's height above the mirror plane. It is all the mirror image needs (mirror_image): row 2
// of R_n_c and the height of p_n_c, so the camera's pose is never formed as a matrix.
template <typename S>
struct MirrorInCamera {
  Vec3<S> normal_c;  // R_n_c^T e_z
  S height;          // e_z^T p_n_c
  // The mirror image, in c, of a point pi_c fixed in the camera frame (paper eq. 11):
  // pi_hat = pi - 2 n (n . pi + height), the point's height above the mirror being n . pi + height.
  Vec3<S> image(const Vec3<S>& pi_c) const {
    return pi_c - (S(2) * (normal_c.dot(pi_c) + height)) * normal_c;
  }
};

// The mirror seen from the camera at the exposure, shift = stamp_minus_filter_s + t_d after the
// filter's time: the IMU rotated on by the bias-corrected rate, moved on by its derivative,
// R_n_b' = R_n_b Exp(w shift), and moved by the velocity and the navigation-frame acceleration
// (second order). Only e_z^T R_n_b' = (Exp(-w shift) R_n_b^T e_z)^T and the height of p' enter.
// A state's velocity and biases are the filter's mean in every sigma point (the update samples
// [p, kDim)); the shift is milliseconds at most, so their errors enter h only at second order,
// and the mean is all they need.
template <class State>
MirrorInCamera<typename State::Scalar> mirror_in_camera(const State& x,
                                                        const Exposure<typename State::Scalar>& e) {
  using S = typename State::Scalar;
  const S dt = e.stamp_minus_filter_s + x.t_d;
  const Quat<S>& q = x.q_n_b;
  // R_n_b^T e_z, the third row of R_n_b.
  const Vec3<S> up_b0(S(2) * (q.x() * q.z() - q.w() * q.y()),
                      S(2) * (q.y() * q.z() + q.w() * q.x()),
                      S(1) - S(2) * (q.x() * q.x() + q.y() * q.y()));
  const Vec3<S> rate =
      x.body_rate(e.gyro, e.accel) + (S(0.5) * dt) * x.body_rate_change(e.gyro_rate);
  const Vec3<S> up_b = so3::exp<S>(-rate * dt) * up_b0;
  const S accel_up = up_b0.dot(x.specific_force(e.accel)) + e.gravity_n.z();  // e_z^T a_n
  MirrorInCamera<S> m;
  m.normal_c = x.q_b_c.conjugate() * up_b;
  m.height = x.p.z() + dt * x.v.z() + (S(0.5) * dt * dt) * accel_up + up_b.dot(x.p_b_c);
  return m;
}

// The mirror over a frame's exposure, which a moving spot's centroid averages over: the centroid
// is the mean of the projection over the exposure, off from the projection at its middle by the
// image's acceleration times exposure^2 / 24 (toward the centre of the rig's swing). With a 4 ms
// exposure and brisk motion that is a hundredth of a pixel, the same way in every frame;
// unmodelled, it moved the markers' depths half a sigma outward in every rendered room's fast run.
// The two Gauss-Legendre points, exposure / (2 sqrt 3) either side of the middle, give the mean to
// fourth order in the exposure; without an exposure the mirror is seen once, at the middle.
template <typename S>
struct ExposedMirror {
  MirrorInCamera<S> early, late;
  bool averaged = false;

  template <class State>
  ExposedMirror(const State& x, const Exposure<S>& e, S exposure_s) {
    if (!(exposure_s > S(0))) {
      early = mirror_in_camera(x, e);
      late = early;  // unused, but a copy of the struct reads it (GCC -O3 warns otherwise)
      return;
    }
    const S half_spread = exposure_s / S(2 * 1.7320508075688772);
    Exposure<S> at = e;
    at.stamp_minus_filter_s = e.stamp_minus_filter_s - half_spread;
    early = mirror_in_camera(x, at);
    at.stamp_minus_filter_s = e.stamp_minus_filter_s + half_spread;
    late = mirror_in_camera(x, at);
    averaged = true;
  }

  // The centroid of the reflection of pi_c (fixed in the camera frame); false where it is not in
  // front of the camera over the exposure.
  bool project_image(const Pinhole<S>& k, const Vec3<S>& pi_c, Vec2<S>& uv) const {
    if (!project<S>(k, early.image(pi_c), uv)) return false;
    if (!averaged) return true;
    Vec2<S> later;
    if (!project<S>(k, late.image(pi_c), later)) return false;
    uv = S(0.5) * (uv + later);
    return true;
  }
};

// The intrinsics a state implies: its own for stage 2, the configured ones otherwise. NK = 8 takes
// the distortion coefficients from the state too (the model stays the configured one's).
template <typename S, int M, int NK, int NI>
Pinhole<S> intrinsics_of(const MirrorState<S, M, NK, NI>& x, const Pinhole<S>& fixed) {
  Pinhole<S> k = fixed;
  if constexpr (NK >= 4) {
    k.fu = x.intrinsics(0);
    k.fv = x.intrinsics(1);
    k.cu = x.intrinsics(2);
    k.cv = x.intrinsics(3);
  }
  if constexpr (NK == 5) k.skew = x.intrinsics(4);
  if constexpr (NK == 8)
    for (int j = 0; j < 4; ++j) k.coeffs[static_cast<std::size_t>(j)] = x.intrinsics(4 + j);
  return k;
}

// The row the loop takes a frame at under a rolling shutter: the mean row of its markers (0 when
// it has none), so that the model's extrapolation from the filter's time to each marker's row
// (Exposure) is as short as it can be.
template <int M>
double readout_anchor_row(const MarkerFrame<M>& frame) {
  double sum = 0.0;
  int n = 0;
  for (int i = 0; i < M; ++i)
    if (frame.seen[i]) {
      sum += frame.uv[i].y();
      ++n;
    }
  return n > 0 ? sum / n : 0.0;
}

// When each marker of a frame was read out after the frame's stamp (s): a rolling shutter reads
// row v line_delay_s * v after row 0 (all zero for a global shutter).
template <typename S, int M>
std::array<S, M> marker_readout_s(const Pinhole<S>& k, const MarkerFrame<M>& frame) {
  std::array<S, M> t{};
  if (k.line_delay_s == S(0)) return t;
  for (int i = 0; i < M; ++i)
    if (frame.seen[i]) t[i] = k.line_delay_s * S(frame.uv[i].y());
  return t;
}

// The predicted pixel of every marker flagged in ok, in a frame exposed at e, marker i read out
// readout_s[i] later (a rolling shutter; all zero for a global one); clears ok[i] for a marker
// whose mirror image is not in front of the camera.
template <class State>
void predict_markers(const State& x, const Pinhole<typename State::Scalar>& fixed,
                     const Exposure<typename State::Scalar>& e,
                     const std::array<typename State::Scalar, State::kMarkers>& readout_s,
                     Eigen::Matrix<typename State::Scalar, 2 * State::kMarkers, 1>& z,
                     std::array<bool, State::kMarkers>& ok) {
  using S = typename State::Scalar;
  std::optional<ExposedMirror<S>> mirror;
  S seen_at = S(0);
  const Pinhole<S> k = intrinsics_of(x, fixed);
  for (int i = 0; i < State::kMarkers; ++i) {
    if (!ok[i]) continue;
    if (!mirror || readout_s[i] != seen_at) {  // a global shutter sees the mirror once
      Exposure<S> row = e;
      row.stamp_minus_filter_s += readout_s[i];
      mirror.emplace(x, row, k.exposure_s);
      seen_at = readout_s[i];
    }
    Vec2<S> uv;
    if (mirror->project_image(k, x.marker(i), uv))
      z.template segment<2>(2 * i) = uv;
    else
      ok[i] = false;
  }
}

}  // namespace mirrorcal
