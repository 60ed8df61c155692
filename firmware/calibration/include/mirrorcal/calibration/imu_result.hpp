// The IMU's intrinsics a calibration estimated (estimator/imu_intrinsics.hpp), as users read them:
// in the sensor model's own convention (T: measured = T true + bias), in Kalibr's matrices and in
// the file OpenVINS reads (kalibr_imu_chain.yaml).
#pragma once

#include <cstdio>
#include <string>
#include <vector>

#include "mirrorcal/estimator/imu_intrinsics.hpp"
#include "mirrorcal/estimator/mirror_model.hpp"
#include "mirrorcal/io/files.hpp"

namespace mirrorcal::calibration {

// The ideal-IMU check of a calibration that assumed an ideal IMU (run.hpp, Passes::check_imu): one
// more pass from its final estimate with the scale factors and axes estimated as well
// (scale-misalignment), and how far those lie from an ideal IMU's. An ideal IMU's estimate d
// scatters about them with covariance C = P - P P0^-1 P (P0 the prior's, P the posterior), so over
// the directions the motion sees (where the data took at least kImuCheckMinInformation of the
// prior's variance) the statistic d^T C^-1 d is chi-square with that many degrees of freedom.
struct IdealImuCheck {
  bool made = false;
  double statistic = 0.0;
  int dof = 0;
  double bound = 0.0;  // its 99.9 % quantile (kImuCheckQuantile)
  // The intrinsic furthest from the ideal IMU in its own sigmas, as imu_intrinsic_names and
  // imu_intrinsic_values give it.
  std::string largest_name;
  double largest_value = 0.0, largest_sigma = 0.0;

  bool failed() const { return made && statistic > bound; }
};

// A calibration's IMU: the model, the intrinsics and their 1-sigma (the error state's order,
// imu_intrinsic_names), with what the calibration was told of the sensor.
struct ImuResult {
  ImuModel model = ImuModel::kCalibrated;
  ImuIntrinsics<double> intrinsics{};
  std::vector<double> sigma;  // of D_a's, D_g's (and T_s's) entries; T's to first order
  std::vector<double> prior_sigma;
  // The intrinsics' rows of the joint covariance: columns the calibration block (the result's
  // covariance), then the intrinsics; a later stage starts from it (run.hpp, start_from).
  Eigen::MatrixXd covariance;
  ImuNoise noise{};  // imu.yaml's, or the simulation's
  double rate_hz = 200.0;
  std::string rostopic = "/imu0";
  // The intrinsic the estimate lies furthest from the ideal IMU in its tolerance's sigmas: for
  // the self-check (result.hpp, imu_contradicted).
  double prior_offset_sigmas = 0.0;
  std::string prior_offset_name;
  IdealImuCheck ideal_check;  // made for the calibrated model only
  // The biases at the end of the data (they walk: imu.yaml's random walks), m/s^2 and rad/s, with
  // their 1-sigma; and gravity in the mirror's frame, which the calibration is given
  // (mirrorcal.yaml's gravity_n: the mirror on a wall or the floor), not estimates.
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero(), accel_bias_sigma = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero(), gyro_bias_sigma = Eigen::Vector3d::Zero();
  Eigen::Vector3d gravity_n = Eigen::Vector3d::Zero();

  bool estimated() const { return model != ImuModel::kCalibrated; }
};

// An intrinsic whose sigma is above this share of its prior's is weak: the motion barely saw it.
constexpr double kWeakImuIntrinsic = 0.7;

// The names of a model's intrinsics, in the error state's order: accel_scale_x.., accel_yx (the
// accelerometer's y axis towards x: T_a(1, 0)), accel_zx, accel_zy, the same for gyro_, then
// gyro_xy, gyro_xz, gyro_yz (the gyro's rotation share) and g_sensitivity_xx..zz.
std::vector<std::string> imu_intrinsic_names(ImuModel model);

// The model's parameters of T = D^-1 (measured = T true + bias): each scale factor's error
// T(i, i) - 1 and each off-diagonal entry, in imu_intrinsic_names' order.
std::vector<double> imu_intrinsic_values(const ImuResult& r);

// Kalibr's and OpenVINS's matrices of the same sensor: f_m = M_accel a + b_a and
// w_m = M_gyro C_gyro_i w + A a + b_g, M lower triangular with a positive diagonal and C_gyro_i a
// rotation (Kalibr's ScaledMisalignedImu; OpenVINS's Ta, Tw, R_IMUtoGYRO, Tg).
struct KalibrImuMatrices {
  Eigen::Matrix3d m_accel, m_gyro, c_gyro_i, a;
};
KalibrImuMatrices kalibr_imu_matrices(const ImuIntrinsics<double>& k);

// The result's `imu:` section (mirrorcal-result.yaml).
void write_imu_result_yaml(std::FILE* o, const ImuResult& r);
// OpenVINS's kalibr_imu_chain.yaml (read with OpenCV's FileStorage), added to out.
bool write_openvins_imu_chain(io::OutputSet& out, const std::string& path, const ImuResult& r,
                              std::string& error);

}  // namespace mirrorcal::calibration
