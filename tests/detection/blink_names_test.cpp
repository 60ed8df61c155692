// LEDs that blink their names (hal/blink_code.hpp, detection/blink_names.hpp): identical LEDs
// told apart by the frames each goes dark in, with no prediction and no brightness code.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>

#include "mirrorcal/detection/blink_names.hpp"
#include "mirrorcal/detection/detecting_marker_source.hpp"
#include "mirrorcal/sim/frame_renderer.hpp"
#include "mirrorcal/sim/scenario.hpp"

namespace mc = mirrorcal;
using mc::detection::Blob;

namespace {

constexpr int M = 3;

Blob spot(double u, double v, double flux) {
  Blob b;
  b.u = u;
  b.v = v;
  b.flux = flux;
  return b;
}

}  // namespace

TEST(BlinkCode, EachMarkerIsDarkInOneFrameOfEachPeriodAndFrameZeroShowsAll) {
  const mc::hal::BlinkCode code{8};
  for (std::uint32_t k = 0; k < 32; ++k) {
    int dark = 0;
    for (int i = 0; i < M; ++i) dark += code.lit(i, M, k) ? 0 : 1;
    EXPECT_EQ(dark, k % 8 >= 1 && k % 8 <= 3 ? 1 : 0) << "frame " << k;
    if (dark == 1) {
      EXPECT_FALSE(code.lit(int(k % 8) - 1, M, k));
    }
  }
  const mc::hal::BlinkCode off{};
  for (std::uint32_t k = 0; k < 16; ++k) EXPECT_EQ(off.dark_marker(k, M), -1);
}

// Three identical LEDs moving across the image, a room light that never blinks and a blob that
// flickers at random: the LEDs' tracks are named within two periods, each as its own marker; the
// room light and the flicker never are, and no blob is ever labelled as another's marker.
TEST(BlinkNames, TracksAreNamedByTheFramesTheyGoDarkInAndSteadyLightsNever) {
  const mc::hal::BlinkCode code{6};
  mc::detection::BlinkNames<M> names(code, 4.0);
  std::uint32_t flicker_state = 12345;
  int first_all_named = -1;
  for (std::uint32_t k = 0; k < 60; ++k) {
    std::array<Blob, 8> b{};
    std::array<int, 8> truth{};
    int n = 0;
    for (int i = 0; i < M; ++i) {
      if (!code.lit(i, M, k)) continue;
      truth[std::size_t(n)] = i;
      b[std::size_t(n++)] = spot(100.0 + 150.0 * i + 2.0 * k, 200.0 + 1.5 * k, 500.0);
    }
    truth[std::size_t(n)] = -1;
    b[std::size_t(n++)] = spot(600.0, 40.0, 500.0);  // the room light
    flicker_state = flicker_state * 1103515245u + 12345u;
    if ((flicker_state >> 16) & 1u) {
      truth[std::size_t(n)] = -1;
      b[std::size_t(n++)] = spot(50.0, 420.0, 500.0);
    }
    names.feed(std::int64_t(k) * 33'000'000, k, b.data(), n);
    for (int j = 0; j < n; ++j) {
      const int label = names.blob_labels()[j];
      if (label >= 0) {
        EXPECT_EQ(label, truth[std::size_t(j)]) << "frame " << k << " blob " << j;
      }
    }
    EXPECT_EQ(names.dark_marker(), code.dark_marker(k, M));
    if (first_all_named < 0 && names.named(0) && names.named(1) && names.named(2))
      first_all_named = int(k);
  }
  // Each marker is named in its first dark frame after it was seen lit in every other marker's:
  // marker 2 in frame 3, marker 0 in frame 7, marker 1 in frame 8.
  EXPECT_EQ(first_all_named, 8);
  EXPECT_EQ(names.counters().named, 3u);
  EXPECT_EQ(names.counters().unnamed, 0u);
}

// A named track that shows a light in its marker's dark frame was carried onto another
// reflection: it gives its name back.
TEST(BlinkNames, ANamedTrackLitInItsMarkersDarkFrameLosesItsName) {
  const mc::hal::BlinkCode code{4};
  mc::detection::BlinkNames<M> names(code, 4.0);
  auto frame = [&](std::uint32_t k, bool marker0_lit_anyway) {
    std::array<Blob, 4> b{};
    int n = 0;
    for (int i = 0; i < M; ++i)
      if (code.lit(i, M, k) || (i == 0 && marker0_lit_anyway))
        b[std::size_t(n++)] = spot(100.0 + 150.0 * i, 200.0, 500.0);
    names.feed(std::int64_t(k) * 33'000'000, k, b.data(), n);
  };
  std::uint32_t k = 0;
  for (; k < 12; ++k) frame(k, false);
  ASSERT_TRUE(names.named(0));
  for (; k % 4 != 1; ++k) frame(k, false);
  frame(k++, true);  // marker 0's dark frame, yet its track is seen
  EXPECT_FALSE(names.named(0));
  EXPECT_EQ(names.counters().unnamed, 1u);
  for (int periods = 0; periods < 3; ++periods)
    for (int j = 0; j < 4; ++j, ++k) frame(k, false);
  EXPECT_TRUE(names.named(0));  // named again by the code
}

// Rendered frames of a random rig whose identical LEDs blink their names: with no filter and no
// brightness code, every reflection labelled is the LED of its marker, none is labelled in its
// dark frame, and once named nearly all reflections drawn are labelled.
TEST(BlinkNames, RenderedIdenticalLedsOfARandomRigAreLabelledByTheirCode) {
  mc::sim::Scenario s = mc::sim::random_scenario(2);
  s.duration_s = 10.0;
  mc::sim::RenderConfig render;
  render.spot_noise_px = s.pixel_sigma;
  render.brightness = {120.0};
  render.blink.period = 8;
  mc::sim::RenderedFrameSource frames(s, render, 3);
  mc::detection::DetectionConfig<M> c;
  c.identify.brightness = {1.0, 1.0, 1.0};
  c.blink = render.blink;
  mc::detection::DetectingMarkerSource<M> detect(frames, c, s.truth.width, s.truth.height);
  int drawn = 0, labelled = 0, wrong = 0, labelled_dark = 0, frame = 0, all_named_at = -1;
  mc::MarkerFrame<M> f;
  while (detect.poll(f) == mc::hal::SourceStatus::kOk) {
    const mc::sim::RenderedTruth& truth = frames.truth();
    const bool named = detect.blink_names().named(0) && detect.blink_names().named(1) &&
                       detect.blink_names().named(2);
    if (named && all_named_at < 0) all_named_at = frame;
    for (int i = 0; i < M; ++i) {
      const auto ii = std::size_t(i);
      if (named) drawn += truth.visible[ii] ? 1 : 0;
      if (!f.seen[ii]) continue;
      labelled_dark += truth.visible[ii] ? 0 : 1;
      if (!truth.visible[ii] || (f.uv[ii] - truth.uv[ii]).norm() > 1.0) {
        ++wrong;
        continue;
      }
      if (named) ++labelled;
    }
    ++frame;
  }
  std::printf("named after %d frames; then %d of %d reflections labelled, %d wrong\n", all_named_at,
              labelled, drawn, wrong);
  ASSERT_GE(all_named_at, 0);
  EXPECT_LE(all_named_at, 4 * render.blink.period);
  EXPECT_EQ(wrong, 0);
  EXPECT_EQ(labelled_dark, 0);
  EXPECT_GE(labelled, drawn * 95 / 100);
}
