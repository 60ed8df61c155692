#include "mirrorcal/sim_host/scenario.hpp"

#include <cmath>

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
  k.q_n_b = Eigen::Quaterniond(m.q0.toRotationMatrix() * rz * ry * rx).normalized();
  // Body rate of R0 Rz(c) Ry(b) Rx(a): each Euler rate seen through the rotations after it.
  k.omega_b = rx.transpose() * ry.transpose() * Eigen::Vector3d(0, 0, c.rate) +
              rx.transpose() * Eigen::Vector3d(0, b.rate, 0) + Eigen::Vector3d(a.rate, 0, 0);
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
  return s;
}

bool scenario_by_name(const std::string& name, Scenario& out) {
  if (name == "paper") {
    out = paper_scenario();
    return true;
  }
  return false;
}

}  // namespace mirrorcal::sim
