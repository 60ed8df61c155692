// The IMU's own errors beyond bias and white noise: the scale factors and non-orthogonal axes of
// the accelerometer and gyroscope, the gyro's rotation against the accelerometer's axes and the
// gyro's sensitivity to specific force (docs/estimator.md, "The IMU's intrinsics").
//
// The IMU frame is the accelerometer's, as in Kalibr's and Basalt's models: its x axis is the
// accelerometer's x, its y axis lies in the plane of the accelerometer's x and y. A raw sample
// (f_m, w_m) reads the specific force a and body rate w of that frame as
//   f_m = T_a a + b_a,          T_a lower triangular (scale factors, non-orthogonality)
//   w_m = T_g w + T_s a + b_g,  T_g full (scale, non-orthogonality and the gyro's rotation)
// plus white noise. The state holds the inverses, which turn samples into signals linearly
// (OpenVINS's D_a, D_w):
//   a = D_a (f_m - b_a),   w = D_g (w_m - b_g - T_s a).
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include "mirrorcal/estimator/so3.hpp"

namespace mirrorcal {

// The IMU models (docs/estimator.md, "The IMU's intrinsics"). Each adds states to the one before:
// the error state's first 12 are D_a's and D_g's lower triangles, the next 3 D_g's upper triangle,
// the last 9 T_s.
enum class ImuModel : std::uint8_t {
  kCalibrated,         // Kalibr's "calibrated": bias and white noise only; 0 states
  kScaleMisalignment,  // both sensors' scale factors and non-orthogonality (D_a, D_g lower
                       // triangular; OpenVINS's Da and Dw): 12 states
  kRotation,           // and the gyro's rotation against the accelerometer (D_g full; OpenVINS's
                       // R_IMUtoGYRO): 15 states
  kGSensitivity        // and the gyro's g-sensitivity (T_s; OpenVINS's Tg): 24 states, Kalibr's
                       // "scale-misalignment"
};

constexpr int imu_intrinsics_dim(ImuModel m) {
  return m == ImuModel::kCalibrated          ? 0
         : m == ImuModel::kScaleMisalignment ? 12
         : m == ImuModel::kRotation          ? 15
                                             : 24;
}
inline const char* to_string(ImuModel m) {
  return m == ImuModel::kCalibrated          ? "calibrated"
         : m == ImuModel::kScaleMisalignment ? "scale-misalignment"
         : m == ImuModel::kRotation          ? "scale-misalignment-rotation"
                                             : "scale-misalignment-rotation-g-sensitivity";
}
inline bool imu_model_from_string(std::string_view name, ImuModel& m) {
  for (const ImuModel c : {ImuModel::kCalibrated, ImuModel::kScaleMisalignment, ImuModel::kRotation,
                           ImuModel::kGSensitivity})
    if (name == to_string(c)) {
      m = c;
      return true;
    }
  return false;
}
// The model whose state has dim intrinsics (imu_intrinsics_dim's inverse).
constexpr ImuModel imu_model_of_dim(int dim) {
  return dim == 0    ? ImuModel::kCalibrated
         : dim == 12 ? ImuModel::kScaleMisalignment
         : dim == 15 ? ImuModel::kRotation
                     : ImuModel::kGSensitivity;
}

// A lower triangle in the error state's order: the three scale entries first, then the three
// below the diagonal (row, column); and the gyro's upper triangle, its rotation's share.
constexpr std::array<std::array<int, 2>, 6> kLowerEntries = {
    {{0, 0}, {1, 1}, {2, 2}, {1, 0}, {2, 0}, {2, 1}}};
constexpr std::array<std::array<int, 2>, 3> kUpperEntries = {{{0, 1}, {0, 2}, {1, 2}}};

// D_a, D_g and T_s of a state (the model's: D_g lower triangular below 15 states, T_s zero below
// 24).
template <typename S>
struct ImuIntrinsics {
  so3::Mat3<S> d_a = so3::Mat3<S>::Identity();
  so3::Mat3<S> d_g = so3::Mat3<S>::Identity();
  so3::Mat3<S> t_s = so3::Mat3<S>::Zero();

  // The error state's NI entries: D_a's lower triangle (kLowerEntries), D_g's, then (NI >= 15)
  // D_g's upper triangle (kUpperEntries), then (NI = 24) T_s's nine row by row.
  enum Matrix { kDa, kDg, kTs };
  so3::Mat3<S>& matrix(Matrix m) { return m == kDa ? d_a : m == kDg ? d_g : t_s; }
  const so3::Mat3<S>& matrix(Matrix m) const { return m == kDa ? d_a : m == kDg ? d_g : t_s; }
  // f(matrix, row, column, j) for the error state's j-th entry.
  template <int NI, class F>
  static void for_each_entry(F&& f) {
    static_assert(NI == 12 || NI == 15 || NI == 24, "an IMU model with intrinsics");
    for (int j = 0; j < 6; ++j) f(kDa, kLowerEntries[j][0], kLowerEntries[j][1], j);
    for (int j = 0; j < 6; ++j) f(kDg, kLowerEntries[j][0], kLowerEntries[j][1], 6 + j);
    if constexpr (NI >= 15)
      for (int j = 0; j < 3; ++j) f(kDg, kUpperEntries[j][0], kUpperEntries[j][1], 12 + j);
    if constexpr (NI == 24)
      for (int j = 0; j < 9; ++j) f(kTs, j / 3, j % 3, 15 + j);
  }
  template <int NI, class D>
  void add(const Eigen::MatrixBase<D>& d) {
    for_each_entry<NI>([&](Matrix m, int r, int c, int j) { matrix(m)(r, c) += d(j); });
  }
  template <int NI, class D>
  void difference(const ImuIntrinsics& ref, Eigen::MatrixBase<D>& d) const {
    for_each_entry<NI>(
        [&](Matrix m, int r, int c, int j) { d(j) = matrix(m)(r, c) - ref.matrix(m)(r, c); });
  }

  template <typename T>
  ImuIntrinsics<T> cast() const {
    return {d_a.template cast<T>(), d_g.template cast<T>(), t_s.template cast<T>()};
  }
};

// 1-sigma of the IMU's intrinsics before calibrating (imu.yaml's keys: docs/recordings.md). The
// defaults cover common MEMS parts' datasheet tolerances: sensitivity within +-3 % (1.5 sigma),
// cross-axis sensitivity within +-2 % (about 1 deg, 1.7 sigma).
struct ImuIntrinsicsSigma {
  double accel_scale = 0.02;          // each axis's scale factor, relative
  double accel_misalignment = 0.012;  // each non-orthogonality angle (rad)
  double gyro_scale = 0.02;
  double gyro_misalignment = 0.012;  // non-orthogonality and rotation against the accelerometer
  double g_sensitivity = 5e-4;       // (rad/s) / (m/s^2): 0.3 deg/s per g
};

// The 1-sigma of each of the NI error-state entries (ImuIntrinsics::add's order).
template <int NI>
std::array<double, NI> imu_intrinsics_sigmas(const ImuIntrinsicsSigma& s) {
  static_assert(NI == 12 || NI == 15 || NI == 24, "an IMU model with intrinsics");
  std::array<double, NI> a{};
  for (std::size_t j = 0; j < 6; ++j) {
    a[j] = j < 3 ? s.accel_scale : s.accel_misalignment;
    a[6 + j] = j < 3 ? s.gyro_scale : s.gyro_misalignment;
  }
  for (std::size_t j = 12; j < NI; ++j) a[j] = j < 15 ? s.gyro_misalignment : s.g_sensitivity;
  return a;
}

// What an IMU of intrinsics k and biases b_a, b_g reads (noise-free) for the specific force a and
// body rate w of its frame: f_m = T_a a + b_a, w_m = T_g w + T_s a + b_g (T = D^-1).
template <typename S>
so3::Vec3<S> accel_reading(const ImuIntrinsics<S>& k, const so3::Vec3<S>& b_a,
                           const so3::Vec3<S>& a) {
  return k.d_a.template triangularView<Eigen::Lower>().solve(a) + b_a;
}
template <typename S>
so3::Vec3<S> gyro_reading(const ImuIntrinsics<S>& k, const so3::Vec3<S>& b_g, const so3::Vec3<S>& w,
                          const so3::Vec3<S>& a) {
  return k.d_g.partialPivLu().solve(w) + k.t_s * a + b_g;
}

// What a model-free state holds: nothing.
struct NoImuIntrinsics {};

// The sensitivities of the specific force a and body rate w to the sensor's parameters
// [b_a, b_g, intrinsics] (3 x (6 + NI) each), at samples (f_m, w_m): what the propagation's
// Jacobian is made of (imu_transition.hpp).
template <typename S, int NI>
struct SignalJacobians {
  Eigen::Matrix<S, 3, 6 + NI> accel, gyro;
};
template <typename S, int NI>
SignalJacobians<S, NI> signal_jacobians(const ImuIntrinsics<S>& k, const so3::Vec3<S>& b_a,
                                        const so3::Vec3<S>& b_g, const so3::Vec3<S>& f_m,
                                        const so3::Vec3<S>& w_m) {
  SignalJacobians<S, NI> j;
  j.accel.setZero();
  j.gyro.setZero();
  const so3::Vec3<S> r = f_m - b_a;
  const so3::Vec3<S> a = k.d_a * r;
  const so3::Vec3<S> q = w_m - b_g - k.t_s * a;
  // da = -D_a db_a + dD_a r;  dw = D_g (-db_g - dT_s a - T_s da) + dD_g q
  j.accel.template leftCols<3>() = -k.d_a;
  j.gyro.template middleCols<3>(3) = -k.d_g;
  using K = ImuIntrinsics<S>;
  K::template for_each_entry<NI>([&](typename K::Matrix m, int row, int col, int e) {
    if (m == K::kDa) j.accel(row, 6 + e) = r(col);
    if (m == K::kDg) j.gyro(row, 6 + e) = q(col);
    if (m == K::kTs) j.gyro.col(6 + e) = -k.d_g.col(row) * a(col);
  });
  // Through the specific force (zero without g-sensitivity).
  j.gyro -= so3::Mat3<S>(k.d_g * k.t_s).lazyProduct(j.accel);
  return j;
}

}  // namespace mirrorcal
