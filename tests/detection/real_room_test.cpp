// A real room. What the renderer draws (sim::RoomConfig), checked against independent
// computations: its lights and the LEDs' ghosts where a plane reflection of them projects, the
// brightest LED's spot clipped, and motion blur that smears a spot along its motion about the
// frame's time. And what detection makes of it: a lamp is no spot, and a clipped spot's flux is a
// lower bound on its LED's brightness.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <tuple>
#include <utility>
#include <vector>

#include "mirrorcal/detection/blob_detector.hpp"
#include "mirrorcal/detection/marker_identifier.hpp"
#include "mirrorcal/sim/frame_renderer.hpp"
#include "mirrorcal/sim/scenario.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mc = mirrorcal;

namespace {

// The paper's rig with a global shutter, so that a reflection's pixel is one projection.
mc::sim::Scenario global_shutter_paper() {
  mc::sim::Scenario s = mc::sim::paper_scenario();
  s.truth.intrinsics.line_delay_s = 0.0;
  return s;
}

// Where a point of the room (n) shows in the plane z = h of n, written out: the point mirrored
// in the plane, into the camera's frame, through the pinhole (the paper's lens has no distortion).
bool reflected_by_hand(const mc::sim::Scenario& s, double t, const Eigen::Vector3d& x_n, double h,
                       Eigen::Vector2d& uv) {
  const mc::sim::Kinematics k = mc::sim::kinematics(s.motion, t);
  const Eigen::Matrix3d r_n_c = k.q_n_b.toRotationMatrix() * s.truth.q_b_c.toRotationMatrix();
  const Eigen::Vector3d p_n_c = k.p + k.q_n_b.toRotationMatrix() * s.truth.p_b_c;
  const Eigen::Vector3d mirrored(x_n.x(), x_n.y(), 2.0 * h - x_n.z());
  const Eigen::Vector3d x_c = r_n_c.transpose() * (mirrored - p_n_c);
  if (x_c.z() <= 0.0) return false;
  const mc::Pinhole<double>& c = s.truth.intrinsics;
  uv = {c.fu * x_c.x() / x_c.z() + c.skew * x_c.y() / x_c.z() + c.cu,
        c.fv * x_c.y() / x_c.z() + c.cv};
  return true;
}

struct Frame {
  std::vector<std::uint8_t> pixels;
  mc::sim::RenderedTruth truth;
  mc::hal::FrameView view;
};

Frame render(mc::sim::FrameRenderer& r, std::int64_t t_ns) {
  Frame f;
  f.pixels.resize(static_cast<std::size_t>(r.bytes_per_line() * r.height()));
  r.render(t_ns, 0, f.pixels.data(), f.truth);
  f.view.format = r.config().format;
  f.view.width = r.width();
  f.view.height = r.height();
  f.view.bytes_per_line = r.bytes_per_line();
  f.view.data = f.pixels.data();
  f.view.bytes = f.pixels.size();
  return f;
}

std::vector<mc::detection::Blob> blobs_of(const Frame& f) {
  mc::detection::BlobConfig config;
  config.max_area = 2000;  // the lamp too
  mc::detection::BlobDetector detector(config, f.view.width, f.view.height);
  std::vector<mc::detection::Blob> blobs(64);
  blobs.resize(static_cast<std::size_t>(detector.detect(f.view, blobs.data(), 64)));
  return blobs;
}

mc::sim::RenderConfig room(double exposure_s) {
  mc::sim::RenderConfig rc;
  rc.noise_sigma = 0.0;
  rc.room.enabled = true;
  rc.room.exposure_s = exposure_s;
  return rc;
}

}  // namespace

TEST(RoomRender, ReflectionsInAPlaneAreWhereTheMirroredPointProjects) {
  const mc::sim::Scenario s = global_shutter_paper();
  int compared = 0;
  for (double t : {0.5, 7.0, 21.3, 44.0}) {
    const auto t_ns = static_cast<std::int64_t>(t * 1e9);
    const mc::sim::Kinematics k = mc::sim::kinematics(s.motion, t);
    const Eigen::Vector3d marker_n =
        k.p + k.q_n_b.toRotationMatrix() *
                  (s.truth.p_b_c + s.truth.q_b_c.toRotationMatrix() * s.truth.markers[1]);
    for (double h : {0.0, 0.004}) {
      for (const mc::sim::Reflected& what :
           {mc::sim::Reflected{1, Eigen::Vector3d::Zero(), h},
            mc::sim::Reflected{-1, Eigen::Vector3d(0.2, -0.1, 1.4), h}}) {
        Eigen::Vector2d uv, expected;
        const Eigen::Vector3d x_n = what.marker >= 0 ? marker_n : what.point_n;
        const bool seen = mc::sim::reflection_pixel(s, t_ns, what, uv);
        const bool by_hand = reflected_by_hand(s, t, x_n, h, expected);
        const bool in_image = by_hand && expected.x() >= 0.0 && expected.x() < s.truth.width &&
                              expected.y() >= 0.0 && expected.y() < s.truth.height;
        ASSERT_EQ(seen, in_image) << "t " << t << " h " << h;
        if (!seen) continue;
        EXPECT_LT((uv - expected).norm(), 1e-6) << "t " << t << " h " << h;
        ++compared;
      }
    }
  }
  EXPECT_GE(compared, 8);
}

TEST(RoomRender, TheRoomsLightsAndTheGhostsAreTheBlobsBesideTheLeds) {
  const mc::sim::Scenario s = global_shutter_paper();
  mc::sim::FrameRenderer renderer(s, room(0.0), 5);
  const std::vector<Eigen::Vector3d> lights = renderer.room_lights();
  ASSERT_EQ(lights.size(), 2u);
  int frames_with_a_light = 0, lights_found = 0, saturated = 0, spots = 0;
  const auto inside = [&](const Eigen::Vector2d& uv, double margin) {
    return uv.x() > margin && uv.x() < s.truth.width - margin && uv.y() > margin &&
           uv.y() < s.truth.height - margin;
  };
  for (int j = 0; j < 600; ++j) {
    const double t = 0.05 + 0.1 * j;
    const Frame f = render(renderer, static_cast<std::int64_t>(t * 1e9));
    // Every blob is an LED, a ghost or a light, where the geometry puts it.
    std::vector<Eigen::Vector2d> expected;
    for (std::size_t i = 0; i < s.truth.markers.size(); ++i)
      if (f.truth.visible[i]) expected.push_back(f.truth.uv[i]);
    const std::size_t leds = expected.size();
    bool light_inside = false;
    for (const Eigen::Vector3d& light : lights) {
      Eigen::Vector2d uv;
      if (!reflected_by_hand(s, t, light, 0.0, uv)) continue;
      expected.push_back(uv);
      light_inside = light_inside || inside(uv, 15.0);
    }
    for (const mc::detection::Blob& b : blobs_of(f)) {
      double nearest = 1e9;
      std::size_t which = 0;
      for (std::size_t e = 0; e < expected.size(); ++e) {
        const double d = (Eigen::Vector2d(b.u, b.v) - expected[e]).norm();
        if (d < nearest) std::tie(nearest, which) = std::make_pair(d, e);
      }
      // A ghost merges with its LED's spot or lies a few pixels from it; a spot the image's edge
      // cuts has its centroid pulled inwards.
      if (!b.truncated) {
        EXPECT_LT(nearest, 6.0) << "frame " << j << " blob at " << b.u << ", " << b.v;
      }
      if (nearest < 0.5 && which >= leds) ++lights_found;
    }
    frames_with_a_light += light_inside ? 1 : 0;
    // The exposure clips the brightest LED's spot (the last's) where its centre falls near a
    // pixel's; the dimmest's nowhere.
    const auto brightest_pixel = [&](std::size_t i) {
      const Eigen::Vector2d& uv = f.truth.uv[i];
      int top = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          top = std::max<int>(
              top, f.pixels[static_cast<std::size_t>((std::lround(uv.y()) + dy) * s.truth.width +
                                                     std::lround(uv.x()) + dx)]);
      return top;
    };
    if (f.truth.visible.back() && inside(f.truth.uv.back(), 3.0)) {
      ++spots;
      saturated += brightest_pixel(f.truth.uv.size() - 1) == 255 ? 1 : 0;
    }
    if (f.truth.visible.front() && inside(f.truth.uv.front(), 3.0)) {
      EXPECT_LT(brightest_pixel(0), 255) << "frame " << j;
    }
  }
  EXPECT_GT(frames_with_a_light, 30) << "the lights are placed where the camera looks";
  EXPECT_GT(lights_found, frames_with_a_light / 2);
  EXPECT_GT(spots, 100);
  EXPECT_GT(saturated, spots / 2);
}

TEST(RoomRender, MotionBlurSmearsASpotAlongItsMotionAboutTheFramesTime) {
  const mc::sim::Scenario s = global_shutter_paper();
  constexpr double kExposure = 0.008;
  constexpr int kMarker = 2;  // the brightest LED: its streak stays above the threshold
  mc::sim::RenderConfig sharp = room(0.0), blurred = room(kExposure);
  sharp.room.ghost_ratio = blurred.room.ghost_ratio = 0.0;
  sharp.room.exposure_gain = blurred.room.exposure_gain = 1.0;
  mc::sim::FrameRenderer a(s, sharp, 5), b(s, blurred, 5);
  int compared = 0;
  double added_spread = 0.0, expected_spread = 0.0;
  for (int j = 0; j < 400; ++j) {
    const auto t_ns = static_cast<std::int64_t>((0.05 + 0.15 * j) * 1e9);
    const Frame fa = render(a, t_ns), fb = render(b, t_ns);
    // The streak: the marker's pixels at the exposure's ends.
    Eigen::Vector2d first, last;
    const auto half = static_cast<std::int64_t>(kExposure / 2 * 1e9);
    if (!fa.truth.visible[kMarker] || !mc::sim::true_pixel(s, t_ns - half, kMarker, first) ||
        !mc::sim::true_pixel(s, t_ns + half, kMarker, last))
      continue;
    const double length = (last - first).norm();
    if (length < 3.0 || length > 8.0) continue;
    const auto spot = [&](const Frame& f) {
      for (const mc::detection::Blob& blob : blobs_of(f))
        if ((Eigen::Vector2d(blob.u, blob.v) - f.truth.uv[kMarker]).norm() < 3.0) return blob;
      return mc::detection::Blob{};
    };
    const mc::detection::Blob sa = spot(fa), sb = spot(fb);
    ASSERT_GT(sa.area, 0) << "frame " << j;
    ASSERT_GT(sb.area, 0) << "frame " << j;
    // The centroid stays at the mid-exposure pixel, to the curvature of the motion and the
    // centroid's disc (an exposure that started at the frame's time would put it L / 2 away).
    EXPECT_LT((Eigen::Vector2d(sb.u, sb.v) - fb.truth.uv[kMarker]).norm(), 0.3) << "frame " << j;
    // Five spots evenly over a streak of length L add L^2 / 8 to the second moment along it.
    added_spread += sb.spread - sa.spread;
    expected_spread += length * length / 8.0;
    ++compared;
  }
  ASSERT_GT(compared, 20);
  // The detector measures the spread on a disc of 3.5 px about the centroid, which holds only a
  // long streak's core; without blur nothing would be added.
  EXPECT_GT(added_spread, 0.3 * expected_spread);
  EXPECT_LT(added_spread, 1.2 * expected_spread);
}

TEST(RoomRender, WithoutTheRoomTheFramesAreThoseOfTheLedsAlone) {
  const mc::sim::Scenario s = mc::sim::paper_scenario();
  mc::sim::RenderConfig plain, off = room(0.004);
  off.room.enabled = false;
  off.noise_sigma = plain.noise_sigma;
  mc::sim::FrameRenderer a(s, plain, 9), b(s, off, 9);
  EXPECT_TRUE(b.room_lights().empty());
  for (int j = 0; j < 5; ++j) {
    const auto t_ns = static_cast<std::int64_t>((1.0 + 3.1 * j) * 1e9);
    EXPECT_EQ(render(a, t_ns).pixels, render(b, t_ns).pixels) << "frame " << j;
  }
}

TEST(RealRoomDetection, ALampIsWiderThanASpotAndAStreakIsNot) {
  // Each alone on the paper scenario's canvas, without noise: a focused LED's spot, one driven
  // far into clipping, one smeared 6 px along a diagonal (motion blur), and a lamp of 3 px PSF.
  const mc::sim::Scenario s = mc::sim::paper_scenario();
  mc::sim::RenderConfig focused, lamp;
  focused.noise_sigma = lamp.noise_sigma = 0.0;
  lamp.psf_sigma_px = 3.0;
  const auto detect = [&](const mc::sim::RenderConfig& rc, auto draw) {
    mc::sim::FrameRenderer r(s, rc, 1);
    draw(r);
    Frame f;
    f.pixels.resize(static_cast<std::size_t>(r.bytes_per_line() * r.height()));
    r.finish(0, f.pixels.data());
    f.view.format = rc.format;
    f.view.width = r.width();
    f.view.height = r.height();
    f.view.bytes_per_line = r.bytes_per_line();
    f.view.data = f.pixels.data();
    f.view.bytes = f.pixels.size();
    const std::vector<mc::detection::Blob> blobs = blobs_of(f);
    EXPECT_EQ(blobs.size(), 1u);
    return blobs.empty() ? mc::detection::Blob{} : blobs.front();
  };
  const mc::detection::Blob spot =
      detect(focused, [](mc::sim::FrameRenderer& r) { r.add_spot(300.2, 200.7, 150.0); });
  const mc::detection::Blob clipped =
      detect(focused, [](mc::sim::FrameRenderer& r) { r.add_spot(300.2, 200.7, 2000.0); });
  const mc::detection::Blob streak = detect(focused, [](mc::sim::FrameRenderer& r) {
    for (int k = 0; k < 7; ++k) r.add_spot(300.0 + 0.7 * k, 200.0 + 0.7 * k, 60.0);
  });
  const mc::detection::Blob wide =
      detect(lamp, [](mc::sim::FrameRenderer& r) { r.add_spot(300.2, 200.7, 400.0); });
  EXPECT_EQ(clipped.peak, 255);
  for (const mc::detection::Blob& b : {spot, clipped, streak})
    EXPECT_FALSE(b.wide) << "width " << b.width;
  EXPECT_TRUE(wide.wide) << "width " << wide.width;
  EXPECT_FALSE(mc::detection::single_spot(wide, 4.0));
  // The streak is long one way only.
  EXPECT_GT(streak.spread, 2.0 * streak.width);
}

namespace {

// Three markers' spots of the given fluxes and peaks, 80 px apart.
std::array<mc::detection::Blob, 3> three_spots(const std::array<double, 3>& flux,
                                               const std::array<int, 3>& peak) {
  std::array<mc::detection::Blob, 3> blobs{};
  for (std::size_t i = 0; i < 3; ++i) {
    blobs[i].u = 100.0 + 80.0 * static_cast<double>(i);
    blobs[i].v = 200.0 + 30.0 * static_cast<double>(i % 2);
    blobs[i].flux = flux[i];
    blobs[i].peak = peak[i];
    blobs[i].spread = 1.5;
  }
  return blobs;
}

}  // namespace

TEST(RealRoomDetection, AClippedSpotDimmerThanItsShareIsStillItsMarker) {
  // A sharp prediction at each spot; the brightest LED's is clipped, so its flux falls short of
  // its 2.25 share (a brightness cost of about 32 if it were measured: more than leaving it
  // out). As a lower bound it costs nothing, and the prediction names it.
  std::array<mc::detection::Blob, 3> blobs = three_spots({1000.0, 1500.0, 800.0}, {150, 200, 255});
  mc::hal::MarkerPrediction<3> prediction;
  for (std::size_t i = 0; i < 3; ++i) {
    prediction.valid[i] = true;
    prediction.uv[i] = Eigen::Vector2d(blobs[i].u, blobs[i].v);
    prediction.covariance[i] = Eigen::Matrix2d::Identity();
  }
  const mc::detection::IdentifierConfig<3> config;
  mc::MarkerFrame<3> frame;
  mc::detection::MarkerIdentifier<3>(config).identify(blobs.data(), 3, &prediction, frame);
  EXPECT_TRUE(frame.seen[0] && frame.seen[1] && frame.seen[2]);
  // Unclipped, the same spot is left out: its flux does not fit its share.
  blobs[2].peak = 200;
  mc::detection::MarkerIdentifier<3>(config).identify(blobs.data(), 3, &prediction, frame);
  EXPECT_FALSE(frame.seen[2]);
  EXPECT_TRUE(frame.seen[0] && frame.seen[1]);
}

TEST(RealRoomDetection, AClippedSpotIsNeverNamedByItsClippedFlux) {
  // No prediction: the dimmest and middle LEDs' spots and the brightest's, clipped to about half
  // its share. Taken as measured, that flux fits marker 1 and pushes the middle spot to marker 2:
  // two wrong labels. As a lower bound it names nothing wrongly (in doubt, 1 and 2 are withheld).
  std::array<mc::detection::Blob, 3> blobs = three_spots({1000.0, 1500.0, 1200.0}, {150, 200, 255});
  mc::MarkerFrame<3> frame;
  const mc::detection::IdentifierConfig<3> config;
  mc::detection::MarkerIdentifier<3>(config).identify(blobs.data(), 3, nullptr, frame);
  ASSERT_TRUE(frame.seen[0]);
  for (std::size_t i = 0; i < 3; ++i) {
    if (frame.seen[i]) {
      EXPECT_EQ(frame.uv[i].x(), blobs[i].u) << "marker " << i;
    }
  }
  blobs[2].peak = 200;
  mc::detection::MarkerIdentifier<3>(config).identify(blobs.data(), 3, nullptr, frame);
  ASSERT_TRUE(frame.seen[1]);
  EXPECT_EQ(frame.uv[1].x(), blobs[2].u) << "the measured flux's wrong label";
}
