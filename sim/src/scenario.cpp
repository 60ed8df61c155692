#include "mirrorcal/sim/scenario.hpp"

#include <cmath>
#include <random>

namespace mirrorcal::sim {

Eigen::Matrix3d axis_rotation(int axis, double angle) {
  return Eigen::AngleAxisd(angle, Eigen::Vector3d::Unit(axis)).toRotationMatrix();
}

namespace {

struct SineSum {
  double value = 0, rate = 0, accel = 0;
};

SineSum evaluate(const std::vector<Sine>& terms, double t) {
  SineSum s;
  for (const Sine& k : terms) {
    const double w = 2.0 * M_PI * k.freq_hz;
    const double arg = w * t + k.phase;
    s.value += k.amplitude * std::sin(arg);
    s.rate += k.amplitude * w * std::cos(arg);
    s.accel -= k.amplitude * w * w * std::sin(arg);
  }
  return s;
}

}  // namespace

Kinematics kinematics(const Motion& m, double t) {
  Kinematics k;
  for (int i = 0; i < 3; ++i) {
    const SineSum s = evaluate(m.position[static_cast<std::size_t>(i)], t);
    k.p(i) = m.p0(i) + s.value;
    k.v(i) = s.rate;
    k.a(i) = s.accel;
  }
  const SineSum a = evaluate(m.angles[0], t), b = evaluate(m.angles[1], t),
                c = evaluate(m.angles[2], t);
  const Eigen::Matrix3d rx = axis_rotation(0, a.value), ry = axis_rotation(1, b.value),
                        rz = axis_rotation(2, c.value);
  const Eigen::Matrix3d inner = m.q0.toRotationMatrix() * rz * ry * rx;
  // Body rate of R0 Rz(c) Ry(b) Rx(a): each Euler rate seen through the rotations after it.
  k.omega_b = rx.transpose() * ry.transpose() * Eigen::Vector3d(0, 0, c.rate) +
              rx.transpose() * Eigen::Vector3d(0, b.rate, 0) + Eigen::Vector3d(a.rate, 0, 0);
  if (m.about_normal.empty() && m.q_tail.w() == 1.0) {  // the paper scenario, bit for bit
    k.q_n_b = Eigen::Quaterniond(inner).normalized();
    return k;
  }
  // R = Rz_n(psi) inner R_tail: the rate about n's z seen in the body, the inner rate through the
  // constant tail.
  const SineSum psi = evaluate(m.about_normal, t);
  const Eigen::Matrix3d tail = m.q_tail.toRotationMatrix();
  const Eigen::Matrix3d r = axis_rotation(2, psi.value) * inner * tail;
  k.q_n_b = Eigen::Quaterniond(r).normalized();
  k.omega_b = tail.transpose() * k.omega_b + r.transpose() * Eigen::Vector3d(0, 0, psi.rate);
  return k;
}

Scenario paper_scenario() {
  Scenario s;
  s.name = "paper";
  s.gravity_n = Eigen::Vector3d(0.0, -9.81, 0.0);
  constexpr double deg = M_PI / 180.0;

  Rig& r = s.truth;
  r.p_b_c = Eigen::Vector3d(0.01, -0.05, 0.10);
  r.q_b_c = Eigen::Quaterniond(axis_rotation(2, -90 * deg) * axis_rotation(1, 0.0) *
                               axis_rotation(0, -90 * deg));
  r.markers = {Eigen::Vector3d(0.02, -0.03, -0.03), Eigen::Vector3d(0.05, 0.04, -0.03),
               Eigen::Vector3d(-0.08, 0.06, 0.01)};
  r.width = 640;
  r.height = 480;
  // The paper's cu = 2, cv = 8 are centred coordinates; ours start at the top-left pixel.
  r.intrinsics = {833.33, 833.33, 320.0 + 2.0, 240.0 + 8.0, 3.0};

  // Body x forward (the camera looks along it), z up; the rig faces the wall mirror, so body x
  // points along -z of n and body z along +y of n.
  Eigen::Matrix3d r0;
  r0.col(0) = Eigen::Vector3d(0, 0, -1);
  r0.col(1) = Eigen::Vector3d(-1, 0, 0);
  r0.col(2) = Eigen::Vector3d(0, 1, 0);
  Motion& m = s.motion;
  m.q0 = Eigen::Quaterniond(r0);
  m.p0 = Eigen::Vector3d(0.0, 1.3, 0.30);  // 30 cm in front of the mirror
  // Translation on all axes, toward the mirror the most; incommensurate frequencies so the
  // motion does not repeat within the minute.
  m.position[0] = {{0.10, 0.21, 0.3}, {0.04, 0.53, 1.1}};
  m.position[1] = {{0.08, 0.27, 2.0}, {0.03, 0.61, 0.4}};
  m.position[2] = {{0.12, 0.17, 0.0}, {0.04, 0.47, 2.5}};
  // Rotation about all three body axes. The camera position along its optical axis and the
  // markers' depths show only through the tilts (their centripetal accelerations and the parallax
  // they cause), so the tilts are wide and quick (up to 2 Hz); about a fifth of the reflections
  // leave the image at the widest tilts.
  m.angles[0] = {{25 * deg, 0.285, 0.0}, {8 * deg, 0.855, 1.0}};  // about the optical axis
  m.angles[1] = {{10.5 * deg, 0.345, 0.5}, {6 * deg, 1.65, 2.2}};
  m.angles[2] = {{12 * deg, 0.435, 1.7}, {6 * deg, 1.95, 0.3}};
  s.camera_rate_hz = 60.0;
  // The paper's IMU, an ADIS16448, is factory-calibrated over temperature: if its intrinsics are
  // estimated, its tolerances are a trimmed part's (0.3 % scale, 0.09 deg between axes, 1-sigma),
  // not the MEMS default's.
  ImuIntrinsicsSigma& tolerances = s.priors.imu_intrinsics;
  tolerances.accel_scale = tolerances.gyro_scale = 0.003;
  tolerances.accel_misalignment = tolerances.gyro_misalignment = 0.09 * deg;
  return s;
}

namespace {

// Uniform draws for the random family.
class Draw {
 public:
  explicit Draw(std::uint64_t seed) : rng_(seed) {}
  double uniform(double lo, double hi) {
    return std::uniform_real_distribution<double>(lo, hi)(rng_);
  }
  double normal(double sigma) { return sigma * std::normal_distribution<double>()(rng_); }
  bool chance(double p) { return uniform(0.0, 1.0) < p; }
  double phase() { return uniform(0.0, 2.0 * M_PI); }
  // The draws of a vector or quaternion are sequenced, last coordinate first: a function's
  // arguments are evaluated in an unspecified order (GCC's last first, clang's first first), and
  // the random family's rigs must not depend on the compiler. Last first keeps the rigs every
  // committed figure was measured on.
  // A rotation uniform over SO(3): a unit quaternion from four normal draws.
  Eigen::Quaterniond rotation() {
    const double z = normal(1.0), y = normal(1.0), x = normal(1.0), w = normal(1.0);
    return Eigen::Quaterniond(w, x, y, z).normalized();
  }
  Eigen::Vector3d uniform3(double lo, double hi) {
    const double z = uniform(lo, hi), y = uniform(lo, hi), x = uniform(lo, hi);
    return {x, y, z};
  }

 private:
  std::mt19937_64 rng_;
};

// A sum of `terms` sines of total amplitude `amplitude` at frequencies in [f_lo, f_hi]; starting at
// rest puts every term at a crest (zero rate at t = 0).
std::vector<Sine> sweep(Draw& d, double amplitude, double f_lo, double f_hi, int terms,
                        bool at_rest) {
  std::vector<double> share(static_cast<std::size_t>(terms));
  double total = 0.0;
  for (double& w : share) total += (w = d.uniform(0.3, 1.0));
  std::vector<Sine> out;
  for (double w : share) {
    const double phase = at_rest ? (d.chance(0.5) ? 0.5 : -0.5) * M_PI : d.phase();
    out.push_back({amplitude * w / total, d.uniform(f_lo, f_hi), phase});
  }
  return out;
}

// Markers within 10 cm of the optical axis (at least 1.5 cm from it: the lens), 5 cm behind to
// 1 cm in front of the optical centre, at least 3 cm apart.
std::vector<Eigen::Vector3d> draw_markers(Draw& d, int count) {
  std::vector<Eigen::Vector3d> markers;
  while (static_cast<int>(markers.size()) < count) {
    const double radius = std::sqrt(d.uniform(0.015 * 0.015, 0.10 * 0.10)), angle = d.phase();
    const Eigen::Vector3d m(radius * std::cos(angle), radius * std::sin(angle),
                            d.uniform(-0.05, 0.01));
    bool apart = true;
    for (const Eigen::Vector3d& other : markers) apart = apart && (m - other).norm() >= 0.03;
    if (apart) markers.push_back(m);
  }
  return markers;
}

}  // namespace

Scenario random_scenario(std::uint64_t seed, int markers) {
  constexpr double deg = M_PI / 180.0;
  Draw d(seed);
  Scenario s;
  s.name = "random";

  Rig& r = s.truth;
  r.q_b_c = d.rotation();
  r.p_b_c = d.uniform3(-0.08, 0.08);
  r.markers = draw_markers(d, markers);
  r.width = 640;
  r.height = 480;
  const double fu = d.uniform(450.0, 900.0);
  r.intrinsics = {fu, fu * (1.0 + d.uniform(-0.02, 0.02)), 319.5 + d.uniform(-15.0, 15.0),
                  239.5 + d.uniform(-15.0, 15.0), 0.0};

  // Both mirrors are the plane z = 0 of n with the rig above it looking down its normal; they
  // differ in where gravity points.
  s.mirror = d.chance(0.5) ? "wall" : "floor";
  s.gravity_n =
      s.mirror == "wall" ? Eigen::Vector3d(0.0, -9.81, 0.0) : Eigen::Vector3d(0.0, 0.0, -9.81);
  const double distance = d.uniform(0.4, 0.8);

  // The camera faces the mirror (optical axis along -z of n, image y along -y); its attitude moves
  // by tilts about its own x and y axes and by rotation about the mirror normal. The body follows
  // through R_b_c: R_n_b = R_n_c R_b_c^T.
  Motion& m = s.motion;
  Eigen::Matrix3d face;
  face.col(0) = Eigen::Vector3d(1, 0, 0);
  face.col(1) = Eigen::Vector3d(0, -1, 0);
  face.col(2) = Eigen::Vector3d(0, 0, -1);
  m.q0 = Eigen::Quaterniond(face);
  m.q_tail = r.q_b_c.conjugate();
  m.p0 = Eigen::Vector3d(0.0, 0.0, distance) - face * (m.q_tail * r.p_b_c);
  const bool fast = d.chance(1.0 / 3.0), at_rest = d.chance(0.5);
  s.motion_kind = fast ? "fast" : "slow";
  for (int axis = 0; axis < 3; ++axis) {
    m.position[static_cast<std::size_t>(axis)] =
        fast ? sweep(d, 0.12, 0.15, 1.1, 2, at_rest) : sweep(d, 0.10, 0.05, 0.5, 2, at_rest);
  }
  for (int axis = 0; axis < 2; ++axis) {  // tilts
    m.angles[static_cast<std::size_t>(axis)] = fast ? sweep(d, 16.0 * deg, 0.3, 2.0, 2, at_rest)
                                                    : sweep(d, 12.0 * deg, 0.05, 0.5, 2, at_rest);
  }
  m.about_normal = fast ? sweep(d, 33.0 * deg, 0.25, 0.9, 2, at_rest)
                        : sweep(d, 45.0 * deg, 0.05, 0.5, 2, at_rest);

  s.camera_rate_hz = d.uniform(20.0, 60.0);
  s.camera_offset_s = d.uniform(0.0, 1.0 / s.imu_rate_hz);
  s.pixel_sigma = d.uniform(0.25, 1.0);
  s.imu_noise_scale = d.uniform(1.0, 5.0);
  s.imu.gyro_noise_density *= s.imu_noise_scale;
  s.imu.gyro_random_walk *= s.imu_noise_scale;
  s.imu.accel_noise_density *= s.imu_noise_scale;
  s.imu.accel_random_walk *= s.imu_noise_scale;

  Priors& p = s.priors;
  p.marker = d.uniform(0.03, 0.10);
  p.p_b_c = d.uniform(0.01, 0.03);
  p.rot_b_c = d.uniform(2.0, 5.0) * deg;
  p.position = 0.10;
  p.attitude = 5.0 * deg;
  p.velocity = 0.2;
  // Drawn last, so that the draws above are those of the family before it had a time offset.
  r.t_d = d.uniform(-0.03, 0.03);
  // The camera's prior (stage 2): one 1-sigma for fu, fv, cu, cv and skew, from a focal length
  // known from the lens's datasheet and a principal point guessed at the image centre (20 px) to
  // the paper's 100 px. Drawn after the time offset, so that stage 1's draws stay as they were.
  p.intrinsics.fill(d.uniform(20.0, 100.0));
  return s;
}

void add_mems_imperfections(Scenario& s, std::uint64_t seed) {
  constexpr double deg = M_PI / 180.0;
  Draw d(seed ^ 0x4D454D53ull);  // "MEMS": a stream of its own, the rig's draws unchanged
  const double scale = d.uniform(0.0, 0.03), angle = d.uniform(0.0, 1.0 * deg);
  const double g_sensitivity = d.uniform(0.0, 0.05 * deg / 9.81);
  Eigen::Matrix3d t_a = Eigen::Matrix3d::Identity(), t_g = Eigen::Matrix3d::Identity();
  for (int i = 0; i < 3; ++i) {
    t_a(i, i) += d.uniform(-scale, scale);
    t_g(i, i) += d.uniform(-scale, scale);
    for (int j = 0; j < 3; ++j) {
      if (j >= i) continue;  // lower: the accelerometer's axes are the frame's, the gyro's x
      t_a(i, j) = d.uniform(-angle, angle);  // axis is the accelerometer's
      t_g(i, j) = d.uniform(-angle, angle);
    }
  }
  ImuIntrinsics<double>& k = s.imu_intrinsics;
  k.d_a = t_a.inverse();
  k.d_g = t_g.inverse();
  for (int i = 0; i < 9; ++i) k.t_s.data()[i] = d.uniform(-g_sensitivity, g_sensitivity);
}

void add_told_noise(Scenario& s, std::uint64_t seed) {
  Draw d(seed ^ 0x544F4C44ull);  // "TOLD": a stream of its own
  const auto factor = [&d] { return std::exp(d.uniform(std::log(0.5), std::log(5.0))); };
  const double gyro = factor(), accel = factor(), pixel = factor();
  ImuNoise told = s.imu;
  told.gyro_noise_density *= gyro;
  told.gyro_random_walk *= gyro;
  told.accel_noise_density *= accel;
  told.accel_random_walk *= accel;
  s.told_imu = told;
  s.told_pixel_sigma = s.pixel_sigma * pixel;
}

Scenario mems_scenario(std::uint64_t seed, int markers) {
  Scenario s = random_scenario(seed, markers);
  s.name = "mems";
  add_mems_imperfections(s, seed);
  add_told_noise(s, seed);
  return s;
}

bool has_imu_intrinsics(const Scenario& s) {
  const ImuIntrinsics<double>& k = s.imu_intrinsics;
  return k.d_a != Eigen::Matrix3d::Identity() || k.d_g != Eigen::Matrix3d::Identity() ||
         k.t_s != Eigen::Matrix3d::Zero();
}

void set_lens(Scenario& s, Distortion model) {
  Pinhole<double>& k = s.truth.intrinsics;
  k.distortion = model;
  s.priors.distortion = default_sigma_distortion(model);
  switch (model) {
    case Distortion::kRadtan:
      k.coeffs = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05};  // EuRoC cam0
      break;
    case Distortion::kEquidistant:
      k.coeffs = {0.00348238, 0.000715034, -0.00205323, 0.000202936};
      break;
    case Distortion::kNone:
      k.coeffs = {0.0, 0.0, 0.0, 0.0};
      break;
  }
}

bool scenario_by_name(const std::string& name, std::uint64_t seed, Scenario& out, int markers) {
  if (name == "paper") {
    out = paper_scenario();
    return true;
  }
  if (name == "random") {
    out = random_scenario(seed, markers);
    return true;
  }
  if (name == "mems") {
    out = mems_scenario(seed, markers);
    return true;
  }
  return false;
}

Scenario without_skew(Scenario s) {
  s.truth.intrinsics.skew = 0.0;
  return s;
}

}  // namespace mirrorcal::sim
