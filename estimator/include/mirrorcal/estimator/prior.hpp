// What is known before calibrating (guesses with 1-sigma), turned into the filter's initial state
// and covariance. Also the hand-over from stage 1 to stage 2.
#pragma once

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal {

template <int M>
struct Prior {
  // Guesses.
  Eigen::Vector3d p = Eigen::Vector3d::Zero();  // IMU position in n (m)
  Eigen::Vector3d v = Eigen::Vector3d::Zero();  // IMU velocity in n (m/s)
  Eigen::Quaterniond q_n_b = Eigen::Quaterniond::Identity();
  Eigen::Vector3d b_a = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_g = Eigen::Vector3d::Zero();
  Eigen::Vector3d p_b_c = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_b_c = Eigen::Quaterniond::Identity();
  std::array<Eigen::Vector3d, M> markers{};
  double t_d = 0.0;  // camera-IMU time offset, timeshift_cam_imu (s)
  Pinhole<double> intrinsics{};
  // 1-sigma per axis (SI units; rotations in rad about the perturbation's axes).
  Eigen::Vector3d sigma_p = Eigen::Vector3d::Constant(0.02);
  Eigen::Vector3d sigma_v = Eigen::Vector3d::Constant(0.05);
  Eigen::Vector3d sigma_theta = Eigen::Vector3d::Constant(0.02);
  Eigen::Vector3d sigma_b_a = Eigen::Vector3d::Constant(0.03);
  Eigen::Vector3d sigma_b_g = Eigen::Vector3d::Constant(0.002);
  Eigen::Vector3d sigma_p_b_c = Eigen::Vector3d::Constant(0.01);
  Eigen::Vector3d sigma_rot_b_c = Eigen::Vector3d::Constant(0.035);
  std::array<Eigen::Vector3d, M> sigma_markers{};
  double sigma_t_d = 0.02;  // a camera stamping its frames somewhere in the exposure and readout
  std::array<double, 5> sigma_intrinsics{100, 100, 100, 100, 100};  // fu fv cu cv skew (px)
  // The distortion coefficients' 1-sigma (Pinhole::coeffs order), when stage 2 estimates them
  // (NK = 8); their guess is intrinsics.coeffs.
  std::array<double, 4> sigma_distortion = default_sigma_distortion(Distortion::kRadtan);
  // The IMU's intrinsics, when the state estimates them (NI > 0): guess and 1-sigma.
  ImuIntrinsics<double> imu_intrinsics{};
  ImuIntrinsicsSigma sigma_imu_intrinsics{};
};

// The camera parameters a stage-2 state of NK intrinsics estimates, in the state's order (fu fv
// cu cv, then skew for NK = 5 or the lens's four coefficients for NK = 8), and their 1-sigma.
template <int NK>
std::array<double, NK> camera_parameters(const Pinhole<double>& k) {
  static_assert(NK == 4 || NK == 5 || NK == 8, "stage 2's camera parameters");
  std::array<double, NK> a{};
  a[0] = k.fu;
  a[1] = k.fv;
  a[2] = k.cu;
  a[3] = k.cv;
  if constexpr (NK == 5) a[4] = k.skew;
  if constexpr (NK == 8)
    for (std::size_t j = 0; j < 4; ++j) a[4 + j] = k.coeffs[j];
  return a;
}
template <int NK>
std::array<double, NK> camera_parameter_sigmas(const std::array<double, 5>& sigma_intrinsics,
                                               const std::array<double, 4>& sigma_distortion) {
  static_assert(NK == 4 || NK == 5 || NK == 8, "stage 2's camera parameters");
  std::array<double, NK> a{};
  for (std::size_t j = 0; j < 4; ++j) a[j] = sigma_intrinsics[j];
  if constexpr (NK == 5) a[4] = sigma_intrinsics[4];
  if constexpr (NK == 8)
    for (std::size_t j = 0; j < 4; ++j) a[4 + j] = sigma_distortion[j];
  return a;
}

// The initial state and (diagonal) covariance a prior implies.
template <typename S, int M, int NK, int NI>
void initialise(
    const Prior<M>& pr, MirrorState<S, M, NK, NI>& x,
    Eigen::Matrix<S, MirrorState<S, M, NK, NI>::kDim, MirrorState<S, M, NK, NI>::kDim>& p) {
  using X = MirrorState<S, M, NK, NI>;
  x.p = pr.p.template cast<S>();
  x.v = pr.v.template cast<S>();
  x.q_n_b = pr.q_n_b.normalized().template cast<S>();
  x.b_a = pr.b_a.template cast<S>();
  x.b_g = pr.b_g.template cast<S>();
  x.p_b_c = pr.p_b_c.template cast<S>();
  x.q_b_c = pr.q_b_c.normalized().template cast<S>();
  Eigen::Matrix<S, X::kDim, 1> sigma;
  sigma.template segment<3>(X::kP) = pr.sigma_p.template cast<S>();
  sigma.template segment<3>(X::kV) = pr.sigma_v.template cast<S>();
  sigma.template segment<3>(X::kTheta) = pr.sigma_theta.template cast<S>();
  sigma.template segment<3>(X::kBa) = pr.sigma_b_a.template cast<S>();
  sigma.template segment<3>(X::kBg) = pr.sigma_b_g.template cast<S>();
  sigma.template segment<3>(X::kPbc) = pr.sigma_p_b_c.template cast<S>();
  sigma.template segment<3>(X::kPhi) = pr.sigma_rot_b_c.template cast<S>();
  for (int i = 0; i < M; ++i) {
    x.markers.template segment<3>(3 * i) =
        pr.markers[static_cast<std::size_t>(i)].template cast<S>();
    sigma.template segment<3>(X::kPi + 3 * i) =
        pr.sigma_markers[static_cast<std::size_t>(i)].template cast<S>();
  }
  x.t_d = S(pr.t_d);
  sigma(X::kTd) = S(pr.sigma_t_d);
  if constexpr (NK > 0) {
    const std::array<double, NK> k = camera_parameters<NK>(pr.intrinsics);
    const std::array<double, NK> sk =
        camera_parameter_sigmas<NK>(pr.sigma_intrinsics, pr.sigma_distortion);
    for (int j = 0; j < NK; ++j) {
      x.intrinsics(j) = S(k[static_cast<std::size_t>(j)]);
      sigma(X::kK + j) = S(sk[static_cast<std::size_t>(j)]);
    }
  }
  if constexpr (NI > 0) {
    x.imu = pr.imu_intrinsics.template cast<S>();
    const std::array<double, NI> si = imu_intrinsics_sigmas<NI>(pr.sigma_imu_intrinsics);
    for (int j = 0; j < NI; ++j) sigma(X::kImu + j) = S(si[static_cast<std::size_t>(j)]);
  }
  p = sigma.array().square().matrix().asDiagonal();
}

// Stage 2 starts from stage 1's estimate and covariance, with the intrinsics' own prior: the
// common states keep their values and correlations, the intrinsics enter uncorrelated.
template <typename S, int M, int NK>
void extend_with_intrinsics(
    const MirrorState<S, M, 0>& x1,
    const Eigen::Matrix<S, MirrorState<S, M, 0>::kDim, MirrorState<S, M, 0>::kDim>& p1,
    const Pinhole<double>& guess, const std::array<double, 5>& sigma, MirrorState<S, M, NK>& x2,
    Eigen::Matrix<S, MirrorState<S, M, NK>::kDim, MirrorState<S, M, NK>::kDim>& p2) {
  static_assert(NK == 4 || NK == 5, "stage 2 estimates intrinsics (the lens: initialise)");
  constexpr int N1 = MirrorState<S, M, 0>::kDim;
  x2.v = x1.v;
  x2.b_a = x1.b_a;
  x2.b_g = x1.b_g;
  x2.p = x1.p;
  x2.q_n_b = x1.q_n_b;
  x2.p_b_c = x1.p_b_c;
  x2.q_b_c = x1.q_b_c;
  x2.markers = x1.markers;
  x2.t_d = x1.t_d;
  const double k[5] = {guess.fu, guess.fv, guess.cu, guess.cv, guess.skew};
  p2.setZero();
  p2.template topLeftCorner<N1, N1>() = p1;
  for (int j = 0; j < NK; ++j) {
    x2.intrinsics(j) = S(k[j]);
    p2(N1 + j, N1 + j) = S(sigma[static_cast<std::size_t>(j)] * sigma[static_cast<std::size_t>(j)]);
  }
}

}  // namespace mirrorcal
