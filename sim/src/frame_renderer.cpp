#include "mirrorcal/sim/frame_renderer.hpp"

#include <algorithm>
#include <cmath>
#include <random>

#include "mirrorcal/sim/simulator.hpp"

namespace mirrorcal::sim {

namespace {

constexpr std::size_t kNoiseTable = std::size_t{1} << 18;
constexpr std::uint64_t kNoiseStream = 0x4652414d45ull;  // "FRAME": seeds apart from simulate()'s
constexpr std::uint64_t kSpotStream = 0x53504f54ull << 32;  // "SPOT", xor the frame's time
constexpr std::uint64_t kRoomStream = 0x524f4f4dull;        // "ROOM"
// Motion blur: a spot drawn as this many spots at least, and at most (exposure_steps).
constexpr int kMinExposureSteps = 5, kMaxExposureSteps = 64;

}  // namespace

// Frames are exposed from camera_offset_s on, and both their exposures (every row's) and their
// stamps lie within the IMU's [0, duration_s] (the stamps are t_d earlier than the exposures).
std::int64_t frame_time_ns(const Scenario& s, std::uint64_t j) {
  const double first = s.camera_offset_s + std::max(0.0, s.truth.t_d);
  return std::llround((first + static_cast<double>(j) / s.camera_rate_hz) * 1e9);
}

std::int64_t frame_stamp_ns(const Scenario& s, std::uint64_t j) {
  return frame_time_ns(s, j) - std::llround(s.truth.t_d * 1e9);
}

std::uint64_t frame_count(const Scenario& s) {
  const double first = s.camera_offset_s + std::max(0.0, s.truth.t_d);
  const double readout = s.truth.intrinsics.line_delay_s * s.truth.height;  // rolling shutter
  const double last = s.duration_s - std::max(0.0, -s.truth.t_d) - readout;
  return static_cast<std::uint64_t>(std::floor((last - first) * s.camera_rate_hz)) + 1;
}

FrameRenderer::FrameRenderer(const Scenario& scenario, const RenderConfig& config,
                             std::uint64_t seed)
    : scenario_(scenario),
      config_(config),
      seed_(seed),
      width_(scenario.truth.width),
      height_(scenario.truth.height) {
  const auto n = static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  background_.resize(n);
  canvas_.assign(n, 0.0f);
  // A dim room seen in the mirror: light falling off from the upper left with a soft ripple of
  // furniture and walls, always well below the markers.
  const double lo = config_.background_low, hi = config_.background_high;
  for (int y = 0; y < height_; ++y)
    for (int x = 0; x < width_; ++x) {
      const double fx = static_cast<double>(x) / width_, fy = static_cast<double>(y) / height_;
      const double light =
          0.55 - 0.3 * (0.6 * fx + 0.4 * fy) +
          0.15 * std::sin(2.0 * M_PI * (1.3 * fx + 0.2)) * std::cos(2.0 * M_PI * 0.8 * fy) +
          0.1 * std::sin(2.0 * M_PI * (3.1 * fx - 2.3 * fy));
      background_[static_cast<std::size_t>(y * width_ + x)] =
          static_cast<float>(lo + (hi - lo) * std::clamp(light, 0.0, 1.0));
    }
  std::mt19937_64 rng(derive_seed(seed, kNoiseStream));
  std::normal_distribution<float> n01;
  noise_.resize(kNoiseTable);
  for (float& v : noise_) v = n01(rng);
  if (config_.room.enabled) place_room_lights();
}

// Each light is put on a ray from the camera's mean position within 4-16 deg of its mean optical
// axis, as the mirror image of a point 0.5-2 m further into the room than the camera: the camera
// then sees it in the mirror now and then as the rig turns, as it would a lamp behind its user.
void FrameRenderer::place_room_lights() {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero(), axis = Eigen::Vector3d::Zero();
  constexpr int kSamples = 64;
  for (int k = 0; k < kSamples; ++k) {
    const Kinematics kin = kinematics(scenario_.motion, scenario_.duration_s * k / (kSamples - 1));
    const Eigen::Matrix3d r_n_b = kin.q_n_b.toRotationMatrix();
    centre += (kin.p + r_n_b * scenario_.truth.p_b_c) / kSamples;
    axis += r_n_b * scenario_.truth.q_b_c.toRotationMatrix().col(2);
  }
  axis.normalize();
  if (axis.z() > -0.2) axis = -Eigen::Vector3d::UnitZ();  // a camera that hardly faces the mirror
  std::mt19937_64 rng(derive_seed(seed_, kRoomStream));
  std::uniform_real_distribution<double> u01;
  const RoomConfig& room = config_.room;
  for (int i = 0; i < 2; ++i) {
    const double off_axis = (4.0 + 12.0 * u01(rng)) * M_PI / 180.0, azimuth = 2.0 * M_PI * u01(rng);
    const Eigen::Vector3d across = axis.unitOrthogonal();
    const Eigen::Vector3d ray =
        Eigen::AngleAxisd(off_axis, Eigen::AngleAxisd(azimuth, axis) * across) * axis;
    const double depth = centre.z() + 0.5 + 1.5 * u01(rng);  // the light's height above the mirror
    const Eigen::Vector3d image = centre + ((centre.z() + depth) / -ray.z()) * ray;
    Light light;
    light.what.point_n = Eigen::Vector3d(image.x(), image.y(), depth);
    light.peak = i == 0 ? room.lamp_peak : room.point_light_peak;
    light.psf_sigma_px = i == 0 ? room.lamp_psf_sigma_px : config_.psf_sigma_px;
    room_lights_.push_back(light);
  }
}

std::vector<Eigen::Vector3d> FrameRenderer::room_lights() const {
  std::vector<Eigen::Vector3d> points;
  for (const Light& light : room_lights_) points.push_back(light.what.point_n);
  return points;
}

FrameRenderer::Window FrameRenderer::spot_window(double u, double v, double psf_sigma_px) const {
  const int r = static_cast<int>(std::ceil(4.0 * psf_sigma_px)) + 1;
  Window w;
  w.x0 = std::max(0, static_cast<int>(std::floor(u)) - r);
  w.x1 = std::min(width_ - 1, static_cast<int>(std::ceil(u)) + r);
  w.y0 = std::max(0, static_cast<int>(std::floor(v)) - r);
  w.y1 = std::min(height_ - 1, static_cast<int>(std::ceil(v)) + r);
  return w;
}

void FrameRenderer::add_spot(double u, double v, double peak) {
  add_spot(u, v, peak, config_.psf_sigma_px);
}

void FrameRenderer::add_spot(double u, double v, double peak, double psf_sigma_px) {
  const double s = psf_sigma_px;
  const double flux = peak * 2.0 * M_PI * s * s;
  const auto [x0, x1, y0, y1] = spot_window(u, v, s);
  if (x0 > x1 || y0 > y1) return;
  // The Gaussian integrated over pixel [x - 0.5, x + 0.5] x [y - 0.5, y + 0.5]: separable.
  const double k = 1.0 / (s * std::sqrt(2.0));
  std::array<double, 64> wx{}, wy{};
  for (int x = x0; x <= x1 && x - x0 < 64; ++x)
    wx[static_cast<std::size_t>(x - x0)] =
        0.5 * (std::erf((x + 0.5 - u) * k) - std::erf((x - 0.5 - u) * k));
  for (int y = y0; y <= y1 && y - y0 < 64; ++y)
    wy[static_cast<std::size_t>(y - y0)] =
        0.5 * (std::erf((y + 0.5 - v) * k) - std::erf((y - 0.5 - v) * k));
  for (int y = y0; y <= y1 && y - y0 < 64; ++y)
    for (int x = x0; x <= x1 && x - x0 < 64; ++x)
      canvas_[static_cast<std::size_t>(y * width_ + x)] += static_cast<float>(
          flux * wx[static_cast<std::size_t>(x - x0)] * wy[static_cast<std::size_t>(y - y0)]);
}

void FrameRenderer::finish(std::uint64_t frame_index, std::uint8_t* image) {
  std::mt19937_64 rng(derive_seed(seed_, kNoiseStream + 1 + frame_index));
  std::size_t at = static_cast<std::size_t>(rng()) & (kNoiseTable - 1);
  const auto sigma = static_cast<float>(config_.noise_sigma);
  const bool yuyv = hal::bytes_per_pixel(config_.format) == 2;
  const auto stride = static_cast<std::size_t>(bytes_per_line());
  const auto width = static_cast<std::size_t>(width_);
  // Rounded half up in float, in runs of contiguous noise that the compiler vectorises: this loop
  // over every pixel is most of a rendered run (std::lround's library call was two thirds of it).
  const auto pixel = [sigma](float background, float spots, float noise) {
    return static_cast<std::uint8_t>(std::clamp(background + spots + sigma * noise, 0.0f, 255.0f) +
                                     0.5f);
  };
  for (std::size_t y = 0; y < static_cast<std::size_t>(height_); ++y) {
    std::uint8_t* row = image + y * stride;
    const float* background = background_.data() + y * width;
    const float* spots = canvas_.data() + y * width;
    for (std::size_t x = 0; x < width;) {
      const std::size_t run = std::min(width - x, kNoiseTable - at);
      const float* noise = noise_.data() + at;
      if (yuyv) {
        for (std::size_t i = 0; i < run; ++i) {
          row[2 * (x + i)] = pixel(background[x + i], spots[x + i], noise[i]);
          row[2 * (x + i) + 1] = 128;  // chroma: grey
        }
      } else {
        for (std::size_t i = 0; i < run; ++i)
          row[x + i] = pixel(background[x + i], spots[x + i], noise[i]);
      }
      x += run;
      at = (at + run) & (kNoiseTable - 1);
    }
  }
  std::fill(canvas_.begin(), canvas_.end(), 0.0f);
}

void FrameRenderer::render(std::int64_t t_ns, std::uint64_t frame_index, std::uint8_t* image,
                           RenderedTruth& truth) {
  std::uint32_t lit = ~std::uint32_t{0};
  const int m = static_cast<int>(scenario_.truth.markers.size());
  const int dark = config_.blink.dark_marker(static_cast<std::uint32_t>(frame_index), m);
  if (dark >= 0) lit &= ~(std::uint32_t{1} << dark);
  draw_scene_spots(t_ns, lit, truth);
  finish(frame_index, image);
}

// Motion blur: the spot drawn at the middles of `steps` equal parts of the exposure (its mean
// over the exposure, as a continuous smear's centroid is, to 1 / steps^2), half a PSF sigma apart
// along the smear at most, so that a long smear is a streak and not a row of separate spots.
int FrameRenderer::exposure_steps(std::int64_t t_ns, double exposure, const Light& light) const {
  Eigen::Vector2d first, last;
  const auto half = std::llround(0.5 * exposure * 1e9);
  if (!reflection_pixel(scenario_, t_ns - half, light.what, first) ||
      !reflection_pixel(scenario_, t_ns + half, light.what, last))
    return kMinExposureSteps;
  const double length = (last - first).norm();
  return std::clamp(static_cast<int>(std::ceil(length / (0.5 * light.psf_sigma_px))),
                    kMinExposureSteps, kMaxExposureSteps);
}

bool FrameRenderer::draw_light(std::int64_t t_ns, const Light& light, const Eigen::Vector2d& offset,
                               Eigen::Vector2d& uv) {
  if (!reflection_pixel(scenario_, t_ns, light.what, uv)) return false;
  uv += offset;
  const double exposure = config_.room.enabled ? config_.room.exposure_s : 0.0;
  const int steps = exposure > 0.0 ? exposure_steps(t_ns, exposure, light) : 1;
  Window drawn = spot_window(uv.x(), uv.y(), light.psf_sigma_px);
  for (int k = 0; k < steps; ++k) {
    Eigen::Vector2d at = uv;
    if (steps > 1) {
      const double dt = exposure * ((k + 0.5) / steps - 0.5);
      if (!reflection_pixel(scenario_, t_ns + std::llround(dt * 1e9), light.what, at)) continue;
      at += offset;
    }
    add_spot(at.x(), at.y(), light.peak / steps, light.psf_sigma_px);
    const Window w = spot_window(at.x(), at.y(), light.psf_sigma_px);
    drawn = {std::min(drawn.x0, w.x0), std::max(drawn.x1, w.x1), std::min(drawn.y0, w.y0),
             std::max(drawn.y1, w.y1)};
  }
  drawn_.push_back(drawn);
  return true;
}

void FrameRenderer::draw_scene_spots(std::int64_t t_ns, std::uint32_t lit, RenderedTruth& truth) {
  drawn_.clear();
  const auto m = scenario_.truth.markers.size();
  truth.t_ns = t_ns;
  truth.visible.assign(m, false);
  truth.uv.assign(m, Eigen::Vector2d::Zero());
  // The spots' displacements of this frame, drawn for every marker in view or not, so that the
  // same frame gets the same ones whenever drawn.
  std::mt19937_64 rng(derive_seed(seed_, kSpotStream ^ static_cast<std::uint64_t>(t_ns)));
  std::normal_distribution<double> n01;
  const RoomConfig& room = config_.room;
  for (std::size_t i = 0; i < m; ++i) {
    const double du = n01(rng), dv = n01(rng);
    if ((lit >> i & 1u) == 0) continue;
    const Eigen::Vector2d offset = config_.spot_noise_px * Eigen::Vector2d(du, dv);
    Light led{Reflected{static_cast<int>(i)}, config_.brightness[i % config_.brightness.size()],
              config_.psf_sigma_px};
    if (room.enabled) led.peak *= room.exposure_gain;
    Eigen::Vector2d uv;
    if (!draw_light(t_ns, led, offset, uv)) continue;
    truth.visible[i] = true;
    truth.uv[i] = uv;
    if (!room.enabled) continue;
    Light ghost = led;
    ghost.what.plane_z = room.ghost_offset_m;
    ghost.peak *= room.ghost_ratio;
    Eigen::Vector2d unused;
    draw_light(t_ns, ghost, offset, unused);
  }
  for (const Light& light : room_lights_) {
    Eigen::Vector2d unused;
    draw_light(t_ns, light, Eigen::Vector2d::Zero(), unused);
  }
}

void FrameRenderer::update_spots(std::int64_t t_ns, const std::uint8_t* still, std::uint8_t* image,
                                 RenderedTruth& truth, std::uint32_t lit) {
  const int step = hal::bytes_per_pixel(config_.format);
  const auto stride = static_cast<std::size_t>(bytes_per_line());
  for (const Window& w : drawn_)
    for (int y = w.y0; y <= w.y1; ++y) {
      const std::size_t at =
          static_cast<std::size_t>(y) * stride + static_cast<std::size_t>(w.x0 * step);
      std::copy(still + at, still + at + static_cast<std::size_t>((w.x1 - w.x0 + 1) * step),
                image + at);
    }
  draw_scene_spots(t_ns, lit, truth);
  // Spots that overlap are summed in the canvas: write each window once, then clear them all.
  for (const Window& w : drawn_)
    for (int y = w.y0; y <= w.y1; ++y)
      for (int x = w.x0; x <= w.x1; ++x) {
        const auto p = static_cast<std::size_t>(y * width_ + x);
        const std::size_t at =
            static_cast<std::size_t>(y) * stride + static_cast<std::size_t>(x * step);
        image[at] =
            static_cast<std::uint8_t>(std::clamp(std::lround(still[at] + canvas_[p]), 0L, 255L));
      }
  for (const Window& w : drawn_)
    for (int y = w.y0; y <= w.y1; ++y)
      std::fill(canvas_.begin() + y * width_ + w.x0, canvas_.begin() + y * width_ + w.x1 + 1, 0.0f);
}

RenderedFrameSource::RenderedFrameSource(const Scenario& scenario, const RenderConfig& config,
                                         std::uint64_t seed)
    : scenario_(scenario),
      renderer_(scenario, config, seed),
      image_(static_cast<std::size_t>(renderer_.bytes_per_line()) *
             static_cast<std::size_t>(renderer_.height())),
      frames_(frame_count(scenario)) {}

hal::SourceStatus RenderedFrameSource::poll(hal::FrameView& frame) {
  if (next_ >= frames_) return hal::SourceStatus::kEndOfStream;
  renderer_.render(frame_time_ns(scenario_, next_), next_, image_.data(), truth_);
  frame.format = renderer_.config().format;
  frame.width = renderer_.width();
  frame.height = renderer_.height();
  frame.bytes_per_line = renderer_.bytes_per_line();
  frame.data = image_.data();
  frame.bytes = image_.size();
  frame.t_ns = frame_stamp_ns(scenario_, next_);
  frame.sequence = static_cast<std::uint32_t>(next_);
  frame.flags = 0;
  ++next_;
  ++counters_.frames;
  return hal::SourceStatus::kOk;
}

}  // namespace mirrorcal::sim
