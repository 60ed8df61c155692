// Camera frames of the simulated mirror scene: the markers' reflections drawn as small blurred
// bright spots (a Gaussian point spread function integrated over each pixel, so the spot's centre
// is exact to a small fraction of a pixel) on a dim, smoothly lit background, with sensor noise,
// quantised to 8 bits in GREY or YUYV. Deterministic in the seed and the frame index.
#pragma once

#include <array>
#include <cstdint>
#include <random>
#include <vector>

#include "mirrorcal/hal/blink_code.hpp"
#include "mirrorcal/hal/frames.hpp"
#include "mirrorcal/sim/scenario.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mirrorcal::sim {

// A real room (mirrorcal sim --frames --room): what a detector meets besides the LEDs' clean
// spots. Every part is drawn from the scene's geometry, so it moves in the image as it would.
struct RoomConfig {
  bool enabled = false;
  // Two lights of the room seen in the mirror, fixed in the room behind the rig, where the camera
  // looks: a lamp (a wide spot that saturates) and a small light as bright and sharp as an LED (a
  // standby light, a distant bulb). Placed from the renderer's seed about the camera's mean view.
  double lamp_peak = 400.0, lamp_psf_sigma_px = 3.0;
  double point_light_peak = 200.0;
  // A glass mirror's front surface: a faint second image of each LED, this far in front of the
  // silvered plane (the glass's thickness over its index) and this bright against the LED's.
  double ghost_offset_m = 0.004, ghost_ratio = 0.05;
  // An exposure a little too long: every LED drawn this many times brighter than its brightness
  // says, so that the brightest one's spot clips at full scale (the brightness code holds for
  // the light, not for the clipped pixels).
  double exposure_gain = 1.6;
  // The exposure: each spot is smeared along its motion over it (motion blur), centred on the
  // frame's time.
  double exposure_s = 0.004;
};

struct RenderConfig {
  hal::PixelFormat format = hal::PixelFormat::kGrey;
  double psf_sigma_px = 1.2;
  // Peak of each marker's spot above the background (DN), marker i at brightness[i % size]:
  // 1 : 1.5 : 2.25, LEDs of different drive current (the identification's second cue).
  std::vector<double> brightness{80.0, 120.0, 180.0};
  double background_low = 10.0, background_high = 40.0;  // DN, the scene behind the markers
  double noise_sigma = 2.0;                              // DN, read noise per pixel
  // Measurement noise drawn into the frames, px per coordinate: each spot displaced from its true
  // projection by a fresh normal draw per frame (the same whenever that frame is drawn again), as
  // the listed reflections carry the scenario's pixel noise. 0: spots at the true projections.
  double spot_noise_px = 0.0;
  // LEDs that blink their names: marker i is not drawn in the frames the code darkens it in (the
  // frame index is the code's sequence number).
  hal::BlinkCode blink{};
  RoomConfig room{};
};

// What was drawn in one frame: the pixel each marker's spot was drawn at, if it is in the image
// (its true projection, displaced by RenderConfig::spot_noise_px).
struct RenderedTruth {
  std::int64_t t_ns = 0;
  std::vector<bool> visible;
  std::vector<Eigen::Vector2d> uv;
};

class FrameRenderer {
 public:
  FrameRenderer(const Scenario& scenario, const RenderConfig& config, std::uint64_t seed);

  int width() const { return width_; }
  int height() const { return height_; }
  int bytes_per_line() const { return width_ * hal::bytes_per_pixel(config_.format); }
  const RenderConfig& config() const { return config_; }
  // The room's lights (RoomConfig), as points of the room: the lamp, then the small light.
  std::vector<Eigen::Vector3d> room_lights() const;

  // Renders the scene at true time t_ns into image (rows of bytes_per_line() bytes); truth gets
  // the spots drawn. frame_index selects the noise, so a frame is the same whenever drawn.
  void render(std::int64_t t_ns, std::uint64_t frame_index, std::uint8_t* image,
              RenderedTruth& truth);

  // Draws one spot of the given peak (DN above background) at (u, v) into the float canvas;
  // exposed for tests that place spots by hand.
  void add_spot(double u, double v, double peak);
  // Background, spots added since, noise and quantisation into image.
  void finish(std::uint64_t frame_index, std::uint8_t* image);

  // For feeders that must keep up with a real clock on a slow machine: the spots of the scene at
  // t_ns drawn into image over `still`, a frame rendered with no spots in view (the same size and
  // format), touching only the pixels around the spots; those around the previous call's spots
  // are restored from `still` first. The noise is the still frame's, frozen. lit: bit i set for
  // each marker whose LED is on (LED lines read back from the board).
  void update_spots(std::int64_t t_ns, const std::uint8_t* still, std::uint8_t* image,
                    RenderedTruth& truth, std::uint32_t lit = ~std::uint32_t{0});

 private:
  struct Window {
    int x0 = 0, x1 = -1, y0 = 0, y1 = -1;  // inclusive; empty when x0 > x1
  };
  // A reflection the scene draws, and how: its spot's peak and PSF.
  struct Light {
    Reflected what;
    double peak = 0.0, psf_sigma_px = 0.0;
  };
  // The pixels a spot at (u, v) of the given PSF reaches (to 4 sigma), clipped to the image.
  Window spot_window(double u, double v, double psf_sigma_px) const;
  void add_spot(double u, double v, double peak, double psf_sigma_px);
  // How many spots draw a light's smear over an exposure about t_ns.
  int exposure_steps(std::int64_t t_ns, double exposure, const Light& light) const;
  // Draws a light as the camera saw it over the exposure about t_ns (motion blur), its spots
  // displaced by offset; false, and nothing drawn, if it is not in the image at t_ns. uv: where.
  bool draw_light(std::int64_t t_ns, const Light& light, const Eigen::Vector2d& offset,
                  Eigen::Vector2d& uv);
  // Adds the spots of the scene at t_ns of the markers lit (bit i: marker i) to the canvas, says
  // where they are in truth, and keeps their windows in drawn_.
  void draw_scene_spots(std::int64_t t_ns, std::uint32_t lit, RenderedTruth& truth);
  // The room's lights, placed about the camera's mean view of the run (RoomConfig).
  void place_room_lights();

  const Scenario& scenario_;
  RenderConfig config_;
  std::uint64_t seed_;
  int width_, height_;
  std::vector<float> background_;  // the static scene, DN
  std::vector<float> canvas_;      // spots of the frame being drawn, DN
  std::vector<float> noise_;       // a table of standard normal draws, cycled through per frame
  std::vector<Window> drawn_;      // the windows of the spots drawn last
  std::vector<Light> room_lights_;
};

// The rendered frames of a scenario as a hal::FrameSource: frame j at the camera's j-th time
// (camera_offset_s + j / camera_rate_hz, as simulate() lists them), until the run's end.
class RenderedFrameSource final : public hal::FrameSource {
 public:
  RenderedFrameSource(const Scenario& scenario, const RenderConfig& config, std::uint64_t seed);
  hal::SourceStatus poll(hal::FrameView& frame) override;
  hal::FrameCounters counters() const override { return counters_; }
  // What the last frame delivered shows.
  const RenderedTruth& truth() const { return truth_; }

 private:
  const Scenario& scenario_;
  FrameRenderer renderer_;
  std::vector<std::uint8_t> image_;
  std::uint64_t next_ = 0, frames_ = 0;
  RenderedTruth truth_;
  hal::FrameCounters counters_{};
};

// When frame j of a scenario was exposed, in the IMU's clock.
std::int64_t frame_time_ns(const Scenario& s, std::uint64_t j);
// The timestamp the camera gives frame j (the one simulate() gives its marker frames): its
// exposure less the rig's time offset (t_imu = t_cam + t_d).
std::int64_t frame_stamp_ns(const Scenario& s, std::uint64_t j);
// How many frames a scenario's run has.
std::uint64_t frame_count(const Scenario& s);

}  // namespace mirrorcal::sim
