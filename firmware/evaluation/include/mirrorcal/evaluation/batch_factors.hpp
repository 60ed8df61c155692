// The batch solution's cost terms (batch.hpp), each a Ceres functor over the filter's own model
// code instantiated with Ceres's autodiff scalar: the IMU's integration between two frames'
// states, one marker's reprojection through the mirror, and the priors. Public for the tests,
// which check the derivatives against finite differences.
//
// Parameter blocks, as batch.cpp lays them out:
//   motion   [p (3), v (3), b_a (3), b_g (3)]   per state, SI units in n and b
//   attitude q_n_b, 4 numbers in Eigen's order (x, y, z, w), on RightQuaternionManifold
//   p_b_c (3); q_b_c (4, RightQuaternionManifold); one block per marker (3); t_d (1)
//   camera   [fu fv cu cv skew c0 c1 c2 c3]    those not estimated held on a SubsetManifold
//   imu      the IMU's intrinsics, ImuIntrinsics's 24 entries as values, those beyond the
//            model's held on a SubsetManifold (only with a model that has them)
// The IMU's and the reprojection's factors take the imu block last when the model has one.
#pragma once

#include <array>
#include <vector>

#include <ceres/autodiff_manifold.h>
#include <ceres/ceres.h>
#include <ceres/normal_prior.h>

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal::evaluation::batch {

constexpr int kMotionSize = 12, kQuatSize = 4, kCameraSize = 9, kImuIntrinsicsSize = 24;
// The IMU residual's order, MirrorState's dynamic block: [v, b_a, b_g, p, theta].
constexpr int kImuResiduals = 15;
using ImuSqrtInformation = Eigen::Matrix<double, kImuResiduals, kImuResiduals>;

// Rotations perturbed on the right, as MirrorState's: q boxplus d = q Exp(d). The tangent space
// is the filter's error state, so the covariance Ceres reports is in the filter's convention.
struct RightQuaternionPlus {
  template <typename T>
  bool Plus(const T* x, const T* delta, T* x_plus_delta) const {
    Eigen::Map<Eigen::Quaternion<T>> out(x_plus_delta);
    out = so3::boxplus<T>(Eigen::Map<const Eigen::Quaternion<T>>(x),
                          Eigen::Map<const Vec3<T>>(delta));
    return true;
  }
  template <typename T>
  bool Minus(const T* y, const T* x, T* y_minus_x) const {
    Eigen::Map<Vec3<T>> out(y_minus_x);
    out = so3::boxminus<T>(Eigen::Map<const Eigen::Quaternion<T>>(y),
                           Eigen::Map<const Eigen::Quaternion<T>>(x));
    return true;
  }
};
using RightQuaternionManifold = ceres::AutoDiffManifold<RightQuaternionPlus, kQuatSize, 3>;

// The IMU's intrinsics an imu block holds (ImuIntrinsics<T>::for_each_entry<24>'s order), and
// the block of some.
template <typename T>
ImuIntrinsics<T> imu_intrinsics_of(const T* block) {
  using K = ImuIntrinsics<T>;
  K k;
  k.d_a.setZero();
  k.d_g.setZero();
  K::template for_each_entry<kImuIntrinsicsSize>(
      [&](typename K::Matrix m, int row, int col, int j) { k.matrix(m)(row, col) = block[j]; });
  return k;
}
inline std::array<double, kImuIntrinsicsSize> imu_block_of(const ImuIntrinsics<double>& k) {
  using K = ImuIntrinsics<double>;
  std::array<double, kImuIntrinsicsSize> block{};
  K::for_each_entry<kImuIntrinsicsSize>([&](K::Matrix m, int row, int col, int j) {
    block[static_cast<std::size_t>(j)] = k.matrix(m)(row, col);
  });
  return block;
}

// The state the model's functions take, from a motion block and an attitude (M = 1: the
// markers are separate blocks), and with NI > 0 the imu block (the full 24-entry model, which
// holds every smaller one).
template <int NI = 0, typename T>
MirrorState<T, 1, 0, NI> motion_state(const T* motion, const T* q_n_b, const T* imu = nullptr) {
  MirrorState<T, 1, 0, NI> s;
  s.p = Eigen::Map<const Vec3<T>>(motion);
  s.v = Eigen::Map<const Vec3<T>>(motion + 3);
  s.b_a = Eigen::Map<const Vec3<T>>(motion + 6);
  s.b_g = Eigen::Map<const Vec3<T>>(motion + 9);
  s.q_n_b = Eigen::Map<const Eigen::Quaternion<T>>(q_n_b);
  if constexpr (NI > 0) s.imu = imu_intrinsics_of(imu);
  (void)imu;
  return s;
}

// The camera a camera block describes: model's lens and shutter, the block's parameters.
template <typename T>
Pinhole<T> camera_of(const Pinhole<double>& model, const T* camera) {
  Pinhole<T> k = model.cast<T>();
  k.fu = camera[0];
  k.fv = camera[1];
  k.cu = camera[2];
  k.cv = camera[3];
  k.skew = camera[4];
  for (std::size_t j = 0; j < 4; ++j) k.coeffs[j] = camera[5 + j];
  return k;
}

// A stretch of the IMU signal the filter would integrate in one step: from s0 to s1, on the
// parabola through `before` when there is one (propagate_imu).
struct ImuPiece {
  ImuSample s0, s1, before;
  bool has_before = false;
};

// The motion from one state to the next: the later state against the earlier one integrated over
// the pieces between them, whitened by the integration's covariance (the white noises and the
// bias random walks, at the estimate the factor was made at).
class ImuFactor {
 public:
  ImuFactor(std::vector<ImuPiece> pieces, const Eigen::Vector3d& gravity_n,
            const ImuSqrtInformation& sqrt_information)
      : pieces_(std::move(pieces)), gravity_n_(gravity_n), sqrt_information_(sqrt_information) {}

  template <typename T>
  bool operator()(const T* motion0, const T* q0, const T* motion1, const T* q1, T* r) const {
    return evaluate<0>(motion0, q0, motion1, q1, static_cast<const T*>(nullptr), r);
  }
  template <typename T>
  bool operator()(const T* motion0, const T* q0, const T* motion1, const T* q1, const T* imu,
                  T* r) const {
    return evaluate<kImuIntrinsicsSize>(motion0, q0, motion1, q1, imu, r);
  }

  // With the imu block (intrinsics) or without.
  static ceres::CostFunction* create(std::vector<ImuPiece> pieces, const Eigen::Vector3d& gravity_n,
                                     const ImuSqrtInformation& sqrt_information, bool intrinsics) {
    auto* f = new ImuFactor(std::move(pieces), gravity_n, sqrt_information);
    if (intrinsics)
      return new ceres::AutoDiffCostFunction<ImuFactor, kImuResiduals, kMotionSize, kQuatSize,
                                             kMotionSize, kQuatSize, kImuIntrinsicsSize>(f);
    return new ceres::AutoDiffCostFunction<ImuFactor, kImuResiduals, kMotionSize, kQuatSize,
                                           kMotionSize, kQuatSize>(f);
  }

 private:
  template <int NI, typename T>
  bool evaluate(const T* motion0, const T* q0, const T* motion1, const T* q1, const T* imu,
                T* r) const {
    MirrorState<T, 1, 0, NI> s = motion_state<NI>(motion0, q0, imu);
    const MirrorState<T, 1, 0> next = motion_state(motion1, q1);  // its motion alone
    const Vec3<T> gravity = gravity_n_.cast<T>();
    for (const ImuPiece& piece : pieces_)
      propagate_imu(s, piece.s0, piece.s1, gravity, piece.has_before ? &piece.before : nullptr);
    Eigen::Matrix<T, kImuResiduals, 1> e;
    e << next.v - s.v, next.b_a - s.b_a, next.b_g - s.b_g, next.p - s.p,
        so3::boxminus<T>(next.q_n_b, s.q_n_b);
    Eigen::Map<Eigen::Matrix<T, kImuResiduals, 1>> out(r);
    out = sqrt_information_.cast<T>() * e;
    return true;
  }

  std::vector<ImuPiece> pieces_;
  Eigen::Vector3d gravity_n_;
  ImuSqrtInformation sqrt_information_;
};

// A frame's exposure against its state's time (mirror_model.hpp's Exposure, in doubles): the
// stamp's offset from the state's time when t_d is at the value the state's time assumed, and
// the IMU signal there.
struct FrameExposure {
  double stamp_minus_state_s = 0.0;
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero(), gyro_rate = Eigen::Vector3d::Zero(),
                  accel = Eigen::Vector3d::Zero();
};

// One marker's reflection in one frame: its pixel against the model's, in pixel sigmas.
class ReprojectionFactor {
 public:
  // camera: the lens model and shutter (and every parameter the camera block holds fixed);
  // readout_s: when the marker's row was read after the frame's stamp (a rolling shutter).
  ReprojectionFactor(const FrameExposure& exposure, const Eigen::Vector2d& uv, double readout_s,
                     const Pinhole<double>& camera, const Eigen::Vector3d& gravity_n,
                     double pixel_sigma)
      : exposure_(exposure),
        uv_(uv),
        readout_s_(readout_s),
        camera_(camera),
        gravity_n_(gravity_n),
        inv_sigma_(1.0 / pixel_sigma) {}

  template <typename T>
  bool operator()(const T* motion, const T* q_n_b, const T* p_b_c, const T* q_b_c, const T* marker,
                  const T* t_d, const T* camera, T* r) const {
    return evaluate<0>(motion, q_n_b, p_b_c, q_b_c, marker, t_d, camera,
                       static_cast<const T*>(nullptr), r);
  }
  template <typename T>
  bool operator()(const T* motion, const T* q_n_b, const T* p_b_c, const T* q_b_c, const T* marker,
                  const T* t_d, const T* camera, const T* imu, T* r) const {
    return evaluate<kImuIntrinsicsSize>(motion, q_n_b, p_b_c, q_b_c, marker, t_d, camera, imu, r);
  }

  // With the imu block (intrinsics) or without.
  static ceres::CostFunction* create(const FrameExposure& exposure, const Eigen::Vector2d& uv,
                                     double readout_s, const Pinhole<double>& camera,
                                     const Eigen::Vector3d& gravity_n, double pixel_sigma,
                                     bool intrinsics) {
    auto* f = new ReprojectionFactor(exposure, uv, readout_s, camera, gravity_n, pixel_sigma);
    if (intrinsics)
      return new ceres::AutoDiffCostFunction<ReprojectionFactor, 2, kMotionSize, kQuatSize, 3,
                                             kQuatSize, 3, 1, kCameraSize, kImuIntrinsicsSize>(f);
    return new ceres::AutoDiffCostFunction<ReprojectionFactor, 2, kMotionSize, kQuatSize, 3,
                                           kQuatSize, 3, 1, kCameraSize>(f);
  }

 private:
  template <int NI, typename T>
  bool evaluate(const T* motion, const T* q_n_b, const T* p_b_c, const T* q_b_c, const T* marker,
                const T* t_d, const T* camera, const T* imu, T* r) const {
    MirrorState<T, 1, 0, NI> s = motion_state<NI>(motion, q_n_b, imu);
    s.p_b_c = Eigen::Map<const Vec3<T>>(p_b_c);
    s.q_b_c = Eigen::Map<const Eigen::Quaternion<T>>(q_b_c);
    s.t_d = t_d[0];
    Exposure<T> e;
    e.stamp_minus_filter_s = T(exposure_.stamp_minus_state_s + readout_s_);
    e.gyro = exposure_.gyro.cast<T>();
    e.gyro_rate = exposure_.gyro_rate.cast<T>();
    e.accel = exposure_.accel.cast<T>();
    e.gravity_n = gravity_n_.cast<T>();
    const Pinhole<T> k = camera_of(camera_, camera);
    Vec2<T> uv;
    const ExposedMirror<T> mirror(s, e, k.exposure_s);
    if (!mirror.project_image(k, Eigen::Map<const Vec3<T>>(marker), uv))
      return false;  // behind the camera: the step that put it there is rejected
    r[0] = (uv.x() - uv_.x()) * inv_sigma_;
    r[1] = (uv.y() - uv_.y()) * inv_sigma_;
    return true;
  }

  FrameExposure exposure_;
  Eigen::Vector2d uv_;
  double readout_s_;
  Pinhole<double> camera_;
  Eigen::Vector3d gravity_n_;
  double inv_sigma_;
};

// The priors' guess of the first state, in its 1-sigmas: [p, v, b_a, b_g, theta].
class StartPrior {
 public:
  StartPrior(const double* motion, const Eigen::Quaterniond& q_n_b,
             const Eigen::Matrix<double, kImuResiduals, 1>& sigma)
      : q_n_b_(q_n_b), inv_sigma_(sigma.cwiseInverse()) {
    for (int j = 0; j < kMotionSize; ++j) motion_[j] = motion[j];
  }
  template <typename T>
  bool operator()(const T* motion, const T* q_n_b, T* r) const {
    for (int j = 0; j < kMotionSize; ++j) r[j] = (motion[j] - T(motion_[j])) * T(inv_sigma_(j));
    const Vec3<T> theta =
        so3::boxminus<T>(Eigen::Map<const Eigen::Quaternion<T>>(q_n_b), q_n_b_.cast<T>());
    for (int j = 0; j < 3; ++j) r[kMotionSize + j] = theta(j) * T(inv_sigma_(kMotionSize + j));
    return true;
  }
  static ceres::CostFunction* create(const double* motion, const Eigen::Quaterniond& q_n_b,
                                     const Eigen::Matrix<double, kImuResiduals, 1>& sigma) {
    return new ceres::AutoDiffCostFunction<StartPrior, kImuResiduals, kMotionSize, kQuatSize>(
        new StartPrior(motion, q_n_b, sigma));
  }

 private:
  double motion_[kMotionSize];
  Eigen::Quaterniond q_n_b_;
  Eigen::Matrix<double, kImuResiduals, 1> inv_sigma_;
};

// A rotation's prior: its error vector against the guess, in the guess's 1-sigmas.
class RotationPrior {
 public:
  RotationPrior(const Eigen::Quaterniond& guess, const Eigen::Vector3d& sigma)
      : guess_(guess), inv_sigma_(sigma.cwiseInverse()) {}
  template <typename T>
  bool operator()(const T* q, T* r) const {
    const Vec3<T> theta =
        so3::boxminus<T>(Eigen::Map<const Eigen::Quaternion<T>>(q), guess_.cast<T>());
    for (int j = 0; j < 3; ++j) r[j] = theta(j) * T(inv_sigma_(j));
    return true;
  }
  static ceres::CostFunction* create(const Eigen::Quaterniond& guess,
                                     const Eigen::Vector3d& sigma) {
    return new ceres::AutoDiffCostFunction<RotationPrior, 3, kQuatSize>(
        new RotationPrior(guess, sigma));
  }

 private:
  Eigen::Quaterniond guess_;
  Eigen::Vector3d inv_sigma_;
};

// A vector's prior, each component in its own 1-sigma; a sigma of 0 leaves its component out
// (a parameter held fixed).
inline ceres::CostFunction* vector_prior(const double* guess, const double* sigma, int size) {
  ceres::Vector mean(size);
  ceres::Matrix whitening = ceres::Matrix::Zero(size, size);
  for (int j = 0; j < size; ++j) {
    mean(j) = guess[j];
    if (sigma[j] > 0.0) whitening(j, j) = 1.0 / sigma[j];
  }
  return new ceres::NormalPrior(whitening, mean);
}

}  // namespace mirrorcal::evaluation::batch
