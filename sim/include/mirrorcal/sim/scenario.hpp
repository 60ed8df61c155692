// A simulated rig in front of a plane mirror: what is true (rig geometry, sensors, motion) and what
// the user claims to know beforehand (priors with 1-sigma).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal::sim {

// The rig: camera pose in the IMU frame, markers in the camera frame, and the camera.
struct Rig {
  Eigen::Vector3d p_b_c = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_b_c = Eigen::Quaterniond::Identity();
  std::vector<Eigen::Vector3d> markers;  // pi_i^c (m)
  Pinhole<double> intrinsics{};
  // The camera-IMU time offset (s), Kalibr's timeshift_cam_imu: a frame stamped t_cam shows the
  // rig as it was at IMU time t_cam + t_d.
  double t_d = 0.0;
  // The image: u in [0, width), v in [0, height), origin at the top-left pixel's centre
  // (docs/design.md, "Frames and conventions").
  int width = 640, height = 480;
};

// 1-sigma of what the user knows before calibrating (SI units, radians).
struct Priors {
  double p_b_c = 0.01;
  double rot_b_c = 2.0 * M_PI / 180.0;  // per axis of the rotation error vector
  double marker = 0.10;
  double time_offset = 0.02;                                            // s
  std::array<double, 5> intrinsics{100.0, 100.0, 100.0, 100.0, 100.0};  // fu fv cu cv skew (px)
  // The lens's distortion coefficients (Pinhole::coeffs order), when stage 2 estimates them;
  // set_lens sets the model's default_sigma_distortion.
  std::array<double, 4> distortion = default_sigma_distortion(Distortion::kRadtan);
  double position = 0.02;                // IMU position in n (m)
  double velocity = 0.05;                // m/s
  double attitude = 1.0 * M_PI / 180.0;  // per axis (rad)
  double accel_bias = 0.03;  // m/s^2; the true bias of each run is drawn with this sigma too
  double gyro_bias = 0.002;  // rad/s; likewise
  // The IMU's intrinsics (when the calibration estimates them): the datasheet's tolerances.
  ImuIntrinsicsSigma imu_intrinsics{};
};

// One sine term A sin(2 pi f t + phase).
struct Sine {
  double amplitude = 0.0;
  double freq_hz = 0.0;
  double phase = 0.0;
};

// Smooth motion in front of the mirror: IMU position p0 + sum of sines per axis of n, attitude
// R_n_b = Rz_n(psi(t)) R0 Rz(c(t)) Ry(b(t)) Rx(a(t)) R_tail with the angles a, b, c (about the
// axes of the frame R_tail leads to: the body's in the paper scenario, the camera's in the random
// family) and psi (about the mirror normal) sums of sines. Everything is analytic, so the IMU
// synthesised from it is exact.
struct Motion {
  Eigen::Vector3d p0 = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q0 = Eigen::Quaterniond::Identity();
  std::array<std::vector<Sine>, 3> position;  // x, y, z of n (m)
  std::array<std::vector<Sine>, 3> angles;    // about the x, y, z axes of R0 R_abc (rad)
  std::vector<Sine> about_normal;             // psi, about z of n (rad)
  Eigen::Quaterniond q_tail = Eigen::Quaterniond::Identity();  // R_tail, constant
};

struct Scenario {
  std::string name;
  // What the random family drew, for campaigns that group runs by it.
  std::string mirror = "wall";        // "wall": gravity along the mirror; "floor": along its normal
  std::string motion_kind = "paper";  // "slow" hand-held sweeps or "fast" (the paper's pace)
  double imu_noise_scale = 1.0;       // the IMU noise densities against the ADIS16448's
  Eigen::Vector3d gravity_n{0.0, -9.81, 0.0};
  ImuNoise imu{};  // the true noise; the filter is told told_imu if set, else the same
  // The IMU noise and pixel noise the filter is told (imu.yaml's, mirrorcal.yaml's), when not the
  // true ones: a datasheet's figures copied for the part's (add_told_noise).
  std::optional<ImuNoise> told_imu;
  std::optional<double> told_pixel_sigma;
  // The IMU's true intrinsics (imu_intrinsics.hpp: its samples read T_a a + b_a and
  // T_g w + T_s a + b_g); the identity, an ideal IMU, but in the mems family.
  ImuIntrinsics<double> imu_intrinsics{};
  double imu_rate_hz = 200.0;
  double camera_rate_hz = 20.0;
  double camera_offset_s = 0.0025;  // frames fall between IMU samples
  double duration_s = 60.0;
  double pixel_sigma = 1.0;
  // The share of frames in which the detector mistook something else for one of the markers it
  // saw (a room light, a reflection): that marker's pixel is anywhere in the image instead.
  double outlier_share = 0.0;
  // The share of frames in which the detector swapped markers 0's and 1's labels.
  double label_swap_share = 0.0;
  Rig truth;
  // The rolling shutter's line delay the filter is told (camchain.yaml's), when not the true one:
  // what an unmodelled or mis-measured shutter does to a calibration.
  std::optional<double> told_line_delay_s;
  Priors priors;
  Motion motion;
};

// The paper's Tables I-III set-up: p_b_c = (1, -5, 10) cm, R_b_c = Rz(-90) Ry(0) Rx(-90) deg
// (the paper's three angles, in its column order, read as rotations about x, y and z composed
// z-y-x), markers (2,-3,-3), (5,4,-3), (-8,6,1) cm, fu = fv = 833.33, cu = 2, cv = 8, skew = 3 in
// the paper's centred image coordinates, i.e. cu = 322, cv = 248 in a 640 x 480 image whose origin
// is the top-left pixel (docs/design.md's convention, which Kalibr and OpenCV use),
// a wall mirror with y up, ADIS16448 noise (EuRoC imu0), 1 px, 200 Hz IMU, 60 Hz camera, 60 s.
Scenario paper_scenario();

// A rig a user could build, in front of a wall or floor mirror, moved by hand or at the paper's
// pace, with the priors such a user has: every draw of the family docs/scenarios.md's "The `random`
// family" describes, with `markers` markers (the draws after the markers' differ with their
// number). Deterministic in seed and markers.
constexpr int kPaperMarkers = 3;  // the paper's rig, and the random family's by default
Scenario random_scenario(std::uint64_t seed, int markers = kPaperMarkers);

// The random family's rig with a MEMS IMU's own errors (docs/scenarios.md, "The mems family"):
// every axis's scale factor off by up to 0-3 % and every non-orthogonality angle of both triads
// by up to 0-1 deg (the gyro's x axis on the accelerometer's), each rig's levels drawn first; a
// gyro g-sensitivity up to 0.05 deg/s per g. Drawn from a stream of their own, so that the rig is
// random_scenario(seed, markers)'s.
Scenario mems_scenario(std::uint64_t seed, int markers = kPaperMarkers);
// The same draws, on any scenario.
void add_mems_imperfections(Scenario& s, std::uint64_t seed);
// The noise a user states for the rig (docs/scenarios.md, "The mems family"): each of the gyro's
// and accelerometer's white-noise densities (with its random walk) and the pixel noise told
// 0.5-5 times the truth, log-uniform and independently. Drawn from a stream of their own, so that
// the rig and its MEMS errors are those without it.
void add_told_noise(Scenario& s, std::uint64_t seed);
// Whether the scenario's IMU has intrinsics other than the identity.
bool has_imu_intrinsics(const Scenario& s);

// Gives the scenario's camera a lens: radtan with EuRoC cam0's coefficients (k1 = -0.283, barrel),
// equidistant with a fisheye's (the issue tracker's), or none.
void set_lens(Scenario& s, Distortion model);

// Scenario by name: "paper" (seed and markers ignored: three markers), "random" or "mems" (drawn
// from seed, with `markers` markers); false if unknown.
bool scenario_by_name(const std::string& name, std::uint64_t seed, Scenario& out,
                      int markers = kPaperMarkers);

// The true IMU state at time t, with its derivatives, from the analytic motion.
struct Kinematics {
  Eigen::Vector3d p, v, a;  // in n
  Eigen::Quaterniond q_n_b;
  Eigen::Vector3d omega_b;  // body rate
};
Kinematics kinematics(const Motion& m, double t);

// Rotation about a coordinate axis (0 = x, 1 = y, 2 = z) by angle rad.
Eigen::Matrix3d axis_rotation(int axis, double angle);

// The scenario with a camera that has no skew (most cameras), for --hold-skew.
Scenario without_skew(Scenario s);

}  // namespace mirrorcal::sim
