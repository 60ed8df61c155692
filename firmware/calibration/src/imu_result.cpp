#include "mirrorcal/calibration/imu_result.hpp"

#include "mirrorcal/calibration/result.hpp"

#include <Eigen/QR>

namespace mirrorcal::calibration {

namespace {

constexpr const char* kAxes = "xyz";

std::string axis_pair(const char* sensor, int row, int col) {
  return std::string(sensor) + "_" + kAxes[row] + kAxes[col];
}

// T = D^-1 of the model's matrix m (T_s is held as it is).
Eigen::Matrix3d sensor_matrix(const ImuIntrinsics<double>& k, ImuIntrinsics<double>::Matrix m) {
  if (m == ImuIntrinsics<double>::kDa) return k.d_a.inverse();
  if (m == ImuIntrinsics<double>::kDg) return k.d_g.inverse();
  return k.t_s;
}

template <class F>
void for_each_model_entry(ImuModel model, F&& f) {
  using K = ImuIntrinsics<double>;
  switch (imu_intrinsics_dim(model)) {
    case 12:
      K::for_each_entry<12>(f);
      break;
    case 15:
      K::for_each_entry<15>(f);
      break;
    case 24:
      K::for_each_entry<24>(f);
      break;
    default:
      break;
  }
}

void write_matrix(std::FILE* o, const char* indent, const char* key, const Eigen::Matrix3d& m) {
  std::fprintf(o, "%s%s:\n", indent, key);
  // + 0.0: no "-0.0" where an inverse left a negative zero.
  write_matrix_rows(o, (m.array() + 0.0).matrix(), (std::string(indent) + "  ").c_str());
}

}  // namespace

std::vector<std::string> imu_intrinsic_names(ImuModel model) {
  using K = ImuIntrinsics<double>;
  std::vector<std::string> names;
  for_each_model_entry(model, [&](K::Matrix m, int row, int col, int) {
    const char* sensor = m == K::kDa ? "accel" : m == K::kDg ? "gyro" : "g_sensitivity";
    if (m != K::kTs && row == col)
      names.push_back(std::string(sensor) + "_scale_" + kAxes[row]);
    else
      names.push_back(axis_pair(sensor, row, col));
  });
  return names;
}

std::vector<double> imu_intrinsic_values(const ImuResult& r) {
  using K = ImuIntrinsics<double>;
  std::vector<double> values;
  for_each_model_entry(r.model, [&](K::Matrix m, int row, int col, int) {
    const double t = sensor_matrix(r.intrinsics, m)(row, col);
    values.push_back(m != K::kTs && row == col ? t - 1.0 : t);
  });
  return values;
}

KalibrImuMatrices kalibr_imu_matrices(const ImuIntrinsics<double>& k) {
  KalibrImuMatrices out;
  out.m_accel = k.d_a.inverse();
  out.a = k.t_s;
  // T_g = M_gyro C with M_gyro lower triangular: from T_g^T = Q R, M_gyro = R^T and C = Q^T, the
  // signs chosen so that M_gyro's diagonal is positive (and then C is a rotation for any T_g near
  // the identity).
  const Eigen::Matrix3d t_g = k.d_g.inverse();
  const Eigen::HouseholderQR<Eigen::Matrix3d> qr(t_g.transpose());
  Eigen::Matrix3d q = qr.householderQ();
  Eigen::Matrix3d r = qr.matrixQR().triangularView<Eigen::Upper>();
  for (int i = 0; i < 3; ++i)
    if (r(i, i) < 0.0) {
      r.row(i) *= -1.0;
      q.col(i) *= -1.0;
    }
  out.m_gyro = r.transpose();
  out.c_gyro_i = q.transpose();
  return out;
}

void write_imu_result_yaml(std::FILE* o, const ImuResult& r) {
  std::fprintf(o,
               "imu:  # the IMU's intrinsics; its frame is the accelerometer's (x on its x axis, "
               "y in its x-y plane)\n"
               "  model: %s\n",
               to_string(r.model));
  const auto vector = [&](const char* key, const Eigen::Vector3d& v, const char* comment) {
    std::fprintf(o, "  %s: [%.9g, %.9g, %.9g]%s\n", key, v(0), v(1), v(2), comment);
  };
  std::fprintf(o, "  # the biases at the end of the data (they walk), each with its 1-sigma\n");
  vector("accel_bias", r.accel_bias, "  # m/s^2");
  vector("accel_bias_sigma", r.accel_bias_sigma, "");
  vector("gyro_bias", r.gyro_bias, "  # rad/s");
  vector("gyro_bias_sigma", r.gyro_bias_sigma, "");
  vector("gravity_n", r.gravity_n,
         "  # m/s^2 in the mirror's frame (z along its normal): given (mirrorcal.yaml), not "
         "estimated");
  if (!r.estimated()) {
    std::fprintf(o, "  # an ideal IMU assumed: bias and white noise only\n");
    const IdealImuCheck& c = r.ideal_check;
    if (c.made)
      std::fprintf(o,
                   "  # the check: one pass with the scale factors and axes estimated; their "
                   "chi-square from an ideal IMU's over the dof the motion sees (the self-check: "
                   "at most the bound), and the furthest [value, sigma]\n"
                   "  ideal_imu_check: {statistic: %.3f, dof: %d, bound: %.3f, %s: [%.6g, %.3g]}\n",
                   c.statistic, c.dof, c.bound, c.largest_name.c_str(), c.largest_value,
                   c.largest_sigma);
    return;
  }
  std::fprintf(o, "  # measured = T true + bias: f_m = T_a a + b_a, w_m = T_g w + T_s a + b_g\n");
  write_matrix(o, "  ", "T_a", r.intrinsics.d_a.inverse());
  write_matrix(o, "  ", "T_g", r.intrinsics.d_g.inverse());
  write_matrix(o, "  ", "T_s", r.intrinsics.t_s);
  std::fprintf(
      o, "  # Kalibr's matrices: w_m = M_gyro C_gyro_i w + A a + b_g, f_m = M_accel a + b_a\n");
  const KalibrImuMatrices kalibr = kalibr_imu_matrices(r.intrinsics);
  write_matrix(o, "  ", "M_accel", kalibr.m_accel);
  write_matrix(o, "  ", "M_gyro", kalibr.m_gyro);
  write_matrix(o, "  ", "C_gyro_i", kalibr.c_gyro_i);
  write_matrix(o, "  ", "A", kalibr.a);
  std::fprintf(o,
               "  prior_offset: %.2f  # tolerance sigmas from the ideal IMU, at the furthest: "
               "%s (the self-check: at most 5)\n",
               r.prior_offset_sigmas, r.prior_offset_name.c_str());
  const std::vector<std::string> names = imu_intrinsic_names(r.model);
  const std::vector<double> values = imu_intrinsic_values(r);
  std::fprintf(
      o,
      "  # each scale factor's error T(i, i) - 1 and each off-diagonal entry of T (rad for "
      "the axes' angles, (rad/s)/(m/s^2) for T_s), with its 1-sigma and the prior's\n"
      "  estimate:\n");
  for (std::size_t j = 0; j < names.size(); ++j)
    std::fprintf(o, "    %s: [%.9g, %.3g, %.3g]  # value, sigma, prior sigma\n", names[j].c_str(),
                 values[j], j < r.sigma.size() ? r.sigma[j] : 0.0,
                 j < r.prior_sigma.size() ? r.prior_sigma[j] : 0.0);
  if (r.covariance.rows() == 0) return;
  // A later calibration (--from) starts from them jointly with the camera's pose: the gyro's axes
  // and the camera's rotation are seen together.
  std::fprintf(
      o,
      "  # the joint covariance's rows of the error state's entries (D = T^-1: D_a's lower "
      "triangle, D_g's, ...; estimate's order): columns the calibration states (the "
      "covariance below), then the same entries\n"
      "  covariance:\n");
  write_matrix_rows(o, r.covariance, "    ", true);
}

bool write_openvins_imu_chain(io::OutputSet& out, const std::string& path, const ImuResult& r,
                              std::string& error) {
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  const KalibrImuMatrices k = kalibr_imu_matrices(r.intrinsics);
  write_yaml_header(o, "mirrorcal calibration: OpenVINS's kalibr_imu_chain.yaml");
  std::fprintf(o,
               "# The IMU frame is the accelerometer's (R_IMUtoACC the identity):\n"
               "# w_m = Tw R_IMUtoGYRO w + Tg a + b_g, f_m = Ta a + b_a (IMU model %s)\n"
               "imu0:\n  T_i_b:\n",
               to_string(r.model));
  write_matrix_rows(o, Eigen::Matrix4d::Identity(), "    ");
  std::fprintf(o,
               "  accelerometer_noise_density: %.9g\n  accelerometer_random_walk: %.9g\n"
               "  gyroscope_noise_density: %.9g\n  gyroscope_random_walk: %.9g\n"
               "  rostopic: %s\n  time_offset: 0.0\n  update_rate: %.9g\n"
               "  model: kalibr\n",
               r.noise.accel_noise_density, r.noise.accel_random_walk, r.noise.gyro_noise_density,
               r.noise.gyro_random_walk, r.rostopic.c_str(), r.rate_hz);
  write_matrix(o, "  ", "Tw", k.m_gyro);
  write_matrix(o, "  ", "R_IMUtoGYRO", k.c_gyro_i);
  write_matrix(o, "  ", "Ta", k.m_accel);
  write_matrix(o, "  ", "R_IMUtoACC", Eigen::Matrix3d::Identity());
  write_matrix(o, "  ", "Tg", k.a);
  return true;
}

}  // namespace mirrorcal::calibration
