#include "mirrorcal/sim/simulator.hpp"

#include <algorithm>
#include <cmath>

#include "mirrorcal/sim/frame_renderer.hpp"

namespace mirrorcal::sim {

std::uint64_t derive_seed(std::uint64_t seed, std::uint64_t stream) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (stream + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

namespace {

// The true pixel of a reflection with the IMU at (p_n_b, q_n_b), wherever it falls; false if the
// plane shows nothing there. The plane z = h is the mirror z = 0 of n shifted by h.
bool project_reflection(const Scenario& s, const Eigen::Vector3d& p_n_b,
                        const Eigen::Quaterniond& q_n_b, const Reflected& what,
                        Eigen::Vector2d& uv) {
  const Rig& rig = s.truth;
  const Eigen::Matrix3d r_n_b = q_n_b.toRotationMatrix();
  const Eigen::Matrix3d r_n_c = r_n_b * rig.q_b_c.toRotationMatrix();
  Eigen::Vector3d p_n_c = p_n_b + r_n_b * rig.p_b_c;
  const Eigen::Vector3d pi = what.marker >= 0
                                 ? rig.markers[static_cast<std::size_t>(what.marker)]
                                 : Eigen::Vector3d(r_n_c.transpose() * (what.point_n - p_n_c));
  p_n_c.z() -= what.plane_z;
  // The point itself must be on the reflective side, else the plane shows nothing.
  if ((r_n_c * pi + p_n_c).z() <= 0.0 || p_n_c.z() <= 0.0) return false;
  return project<double>(rig.intrinsics, mirror_image<double>(r_n_c, p_n_c, pi), uv);
}

}  // namespace

bool reflection_pixel(const Scenario& s, std::int64_t exposure_ns, const Reflected& what,
                      Eigen::Vector2d& uv) {
  const double t0 = static_cast<double>(exposure_ns) * 1e-9;
  const double line_delay = s.truth.intrinsics.line_delay_s;
  Kinematics kin = kinematics(s.motion, t0);
  if (!project_reflection(s, kin.p, kin.q_n_b, what, uv)) return false;
  // A rolling shutter reads the row the reflection lands on line_delay * row later: the row where
  // the rig's motion by then puts it, a fixed point that three steps find to far below a
  // micropixel (the row moves a fraction line_delay * |dv/dt| < 0.1 of its error per step).
  for (int step = 0; step < 3 && line_delay != 0.0; ++step) {
    kin = kinematics(s.motion, t0 + line_delay * uv.y());
    if (!project_reflection(s, kin.p, kin.q_n_b, what, uv)) return false;
  }
  return uv.x() >= 0.0 && uv.x() < s.truth.width && uv.y() >= 0.0 && uv.y() < s.truth.height;
}

SimData simulate(const Scenario& s, std::uint64_t seed) {
  SimData d;
  std::mt19937_64 rng_imu(derive_seed(seed, 0)), rng_cam(derive_seed(seed, 1)),
      rng_bias(derive_seed(seed, 2));
  std::normal_distribution<double> n01;
  const auto noise3 = [&](std::mt19937_64& rng) {
    const double x = n01(rng), y = n01(rng), z = n01(rng);
    return Eigen::Vector3d(x, y, z);
  };

  // IMU: discrete white noise sigma = density sqrt(rate), bias step sigma = walk / sqrt(rate).
  const double rate = s.imu_rate_hz;
  const double sg = s.imu.gyro_noise_density * std::sqrt(rate);
  const double sa = s.imu.accel_noise_density * std::sqrt(rate);
  const double sbg = s.imu.gyro_random_walk / std::sqrt(rate);
  const double sba = s.imu.accel_random_walk / std::sqrt(rate);
  d.b_a0 = noise3(rng_bias) * s.priors.accel_bias;
  d.b_g0 = noise3(rng_bias) * s.priors.gyro_bias;
  Eigen::Vector3d b_a = d.b_a0, b_g = d.b_g0;
  const auto n_imu = static_cast<std::size_t>(std::llround(s.duration_s * rate)) + 1;
  const bool mems = has_imu_intrinsics(s);
  d.imu.reserve(n_imu);
  for (std::size_t k = 0; k < n_imu; ++k) {
    const std::int64_t t_ns = std::llround(static_cast<double>(k) * 1e9 / rate);
    const Kinematics kin = kinematics(s.motion, static_cast<double>(t_ns) * 1e-9);
    ImuSample smp;
    smp.t_ns = t_ns;
    const Eigen::Vector3d specific_force = kin.q_n_b.conjugate() * (kin.a - s.gravity_n);
    if (mems) {
      smp.gyro = gyro_reading(s.imu_intrinsics, b_g, kin.omega_b, specific_force);
      smp.accel = accel_reading(s.imu_intrinsics, b_a, specific_force);
      smp.gyro += sg * noise3(rng_imu);
      smp.accel += sa * noise3(rng_imu);
    } else {
      smp.gyro = kin.omega_b + b_g + sg * noise3(rng_imu);
      smp.accel = specific_force + b_a + sa * noise3(rng_imu);
    }
    d.imu.push_back(smp);
    b_g += sbg * noise3(rng_bias);
    b_a += sba * noise3(rng_bias);
  }

  // Camera: frames at offset + j / rate, while the IMU covers them.
  const std::uint64_t n_frames = frame_count(s);
  d.frames.reserve(n_frames);
  const int m = static_cast<int>(s.truth.markers.size());
  // The detector's mistakes from a stream of their own: the rest of the data is the same with any
  // outlier_share.
  std::mt19937_64 rng_outlier(derive_seed(seed, 3)), rng_swap(derive_seed(seed, 4));
  std::uniform_real_distribution<double> u01;
  for (std::uint64_t j = 0; j < n_frames; ++j) {
    io::ObservedFrame f;
    f.t_ns = frame_stamp_ns(s, j);
    for (int i = 0; i < m; ++i) {
      Eigen::Vector2d uv;
      const double du = n01(rng_cam), dv = n01(rng_cam);  // drawn always: streams stay aligned
      if (!true_pixel(s, frame_time_ns(s, j), i, uv)) {
        ++d.markers_out_of_image;
        continue;
      }
      f.markers.push_back({i, uv.x() + s.pixel_sigma * du, uv.y() + s.pixel_sigma * dv});
    }
    const double draw = u01(rng_outlier), which = u01(rng_outlier);
    const double u = u01(rng_outlier) * s.truth.width, v = u01(rng_outlier) * s.truth.height;
    if (draw < s.outlier_share && !f.markers.empty()) {
      const auto k = std::min(f.markers.size() - 1, std::size_t(which * double(f.markers.size())));
      f.markers[k].u = u;
      f.markers[k].v = v;
      ++d.outliers;
    }
    // Markers 0 and 1 swapped, as a detection that cannot tell two LEDs apart swaps them.
    const double swap = u01(rng_swap);
    io::ObservedMarker* first = nullptr;
    io::ObservedMarker* second = nullptr;
    for (io::ObservedMarker& m : f.markers) {
      if (m.id == 0) first = &m;
      if (m.id == 1) second = &m;
    }
    if (swap < s.label_swap_share && first != nullptr && second != nullptr) {
      std::swap(first->id, second->id);
      ++d.label_swaps;
    }
    d.frames.push_back(std::move(f));
  }
  return d;
}

io::RecordingTruth recording_truth(const Scenario& s, bool lens_guessed) {
  io::RecordingTruth truth;
  truth.p_b_c = s.truth.p_b_c;
  truth.q_b_c = s.truth.q_b_c;
  truth.features_c = s.truth.markers;
  truth.intrinsics = s.truth.intrinsics;
  truth.t_d = s.truth.t_d;
  truth.has_distortion = lens_guessed;
  return truth;
}

}  // namespace mirrorcal::sim
