// Sensor data of one simulated run, and HAL sources that replay it to the loop.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

#include "mirrorcal/estimator/prior.hpp"
#include "mirrorcal/hal/sources.hpp"
#include "mirrorcal/io/recording.hpp"
#include "mirrorcal/io/replay.hpp"
#include "mirrorcal/sim/scenario.hpp"

namespace mirrorcal::sim {

struct SimData {
  std::vector<ImuSample> imu;
  std::vector<io::ObservedFrame> frames;
  Eigen::Vector3d b_a0 = Eigen::Vector3d::Zero(), b_g0 = Eigen::Vector3d::Zero();  // true, at t=0
  std::uint64_t markers_out_of_image = 0;  // reflections that fell outside the image or behind
  std::uint64_t outliers = 0;              // markers given a random pixel (outlier_share)
  std::uint64_t label_swaps = 0;           // frames with two labels swapped (label_swap_share)
};

// Synthesises the IMU stream (docs/design.md's model: white noise and bias random walks from the
// Kalibr densities) and the marker reflections (eq. 11 through the true camera, pixel noise,
// dropped when out of the image or not in front of the camera), and the detector's mistakes
// (outlier_share, label_swap_share). Deterministic in seed.
SimData simulate(const Scenario& s, std::uint64_t seed);

// What the camera sees in a plane parallel to the mirror: one of the rig's markers, or (marker < 0)
// a point fixed in the room (point_n, in n), reflected in the plane z = plane_z of n. The mirror's
// silvered plane is z = 0; a glass mirror's front surface lies a few millimetres in front of it
// and shows a faint second image (a ghost).
struct Reflected {
  int marker = -1;
  Eigen::Vector3d point_n = Eigen::Vector3d::Zero();
  double plane_z = 0.0;
};

// The true pixel of a reflection in the frame whose row 0 was exposed at IMU time exposure_ns (a
// rolling shutter reads its row later); false if not visible in the image.
bool reflection_pixel(const Scenario& s, std::int64_t exposure_ns, const Reflected& what,
                      Eigen::Vector2d& uv);
// The same for marker i's reflection in the mirror.
inline bool true_pixel(const Scenario& s, std::int64_t exposure_ns, int marker,
                       Eigen::Vector2d& uv) {
  return reflection_pixel(s, exposure_ns, Reflected{marker}, uv);
}

// A simulated rig's truth as truth.yaml holds it; lens_guessed: camchain.yaml holds a guess of its
// lens's coefficients.
io::RecordingTruth recording_truth(const Scenario& s, bool lens_guessed = false);

// Independent streams for the parts of a run, derived from one seed (SplitMix64).
std::uint64_t derive_seed(std::uint64_t seed, std::uint64_t stream);

// A prior as a user would give it: each guess is the truth plus a draw from its 1-sigma.
template <int M>
Prior<M> draw_prior(const Scenario& s, const SimData& data, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01;
  const auto noise3 = [&](double sigma) {
    const double x = n01(rng), y = n01(rng), z = n01(rng);
    return Eigen::Vector3d(sigma * x, sigma * y, sigma * z);
  };
  const Priors& ps = s.priors;
  const Kinematics k0 = kinematics(s.motion, 0.0);
  Prior<M> pr;
  pr.p = k0.p + noise3(ps.position);
  pr.v = k0.v + noise3(ps.velocity);
  pr.q_n_b = so3::boxplus<double>(k0.q_n_b, noise3(ps.attitude));
  pr.b_a = Eigen::Vector3d::Zero();  // the biases are drawn in the truth; the guess is zero
  pr.b_g = Eigen::Vector3d::Zero();
  pr.p_b_c = s.truth.p_b_c + noise3(ps.p_b_c);
  pr.q_b_c = so3::boxplus<double>(s.truth.q_b_c, noise3(ps.rot_b_c));
  for (int i = 0; i < M; ++i) {
    pr.markers[static_cast<std::size_t>(i)] =
        s.truth.markers[static_cast<std::size_t>(i)] + noise3(ps.marker);
    pr.sigma_markers[static_cast<std::size_t>(i)] = Eigen::Vector3d::Constant(ps.marker);
  }
  const Pinhole<double>& t = s.truth.intrinsics;
  const double guess[5] = {t.fu + ps.intrinsics[0] * n01(rng), t.fv + ps.intrinsics[1] * n01(rng),
                           t.cu + ps.intrinsics[2] * n01(rng), t.cv + ps.intrinsics[3] * n01(rng),
                           t.skew + ps.intrinsics[4] * n01(rng)};
  pr.intrinsics = {guess[0], guess[1], guess[2], guess[3], guess[4]};
  pr.sigma_p.setConstant(ps.position);
  pr.sigma_v.setConstant(ps.velocity);
  pr.sigma_theta.setConstant(ps.attitude);
  pr.sigma_b_a.setConstant(ps.accel_bias);
  pr.sigma_b_g.setConstant(ps.gyro_bias);
  pr.sigma_p_b_c.setConstant(ps.p_b_c);
  pr.sigma_rot_b_c.setConstant(ps.rot_b_c);
  pr.sigma_intrinsics = ps.intrinsics;
  pr.t_d =
      s.truth.t_d + ps.time_offset * n01(rng);  // drawn last: the draws above stay as they were
  pr.sigma_t_d = ps.time_offset;
  // The lens's model is known; its coefficients' guesses (used only when stage 2 estimates them)
  // are drawn after everything else, so that the draws above stay as they were.
  pr.intrinsics.distortion = t.distortion;
  for (std::size_t j = 0; j < 4; ++j)
    pr.intrinsics.coeffs[j] = t.coeffs[j] + ps.distortion[j] * n01(rng);
  pr.sigma_distortion = ps.distortion;
  pr.sigma_imu_intrinsics = ps.imu_intrinsics;  // the guess is the ideal IMU's
  (void)data;
  return pr;
}

// The prior a simulated run with this seed starts from (a user's guesses, drawn around the truth),
// and the seed of a second minute of data (stage 2 of a two-stage run: derive_seed(seed, this)).
template <int M>
Prior<M> simulation_prior(const Scenario& s, const SimData& data, std::uint64_t seed) {
  return draw_prior<M>(s, data, derive_seed(seed, 100));
}
constexpr std::uint64_t kStage2SeedStream = 300;

}  // namespace mirrorcal::sim
