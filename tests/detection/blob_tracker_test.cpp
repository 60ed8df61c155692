// The blob tracker on blobs placed by hand: reflections moving together as a rig turns, one hidden
// for a quarter of a second behind a lamp, two passing close by while the turn changes pace, two
// close together where the rig turns back, and one seen first mid-sweep. Each case is one the
// tracker met in rendered rooms, where losing a track lost its name (sim --frames --room
// --identical-leds). Then the shape's snapshots of the tracks, which wait for a reflection a lamp
// crowds, and the names tracks carry: a room light's track that took a marker's name as the two
// passed gives it back to a sharp prediction.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "marker_prediction.hpp"
#include "mirrorcal/detection/blob_tracker.hpp"
#include "mirrorcal/detection/marker_identifier.hpp"
#include "mirrorcal/detection/shape_bootstrap.hpp"

namespace mc = mirrorcal;
using marker_prediction::prediction_at;
using mc::detection::Blob;
using mc::detection::BlobTracker;

namespace {

constexpr std::int64_t kFrameNs = 21'000'000;  // a 47 Hz camera
constexpr double kMaxSpread = 4.0;

Blob spot(const Eigen::Vector2d& uv) {
  Blob b;
  b.u = uv.x();
  b.v = uv.y();
  b.flux = 1700.0;
  b.spread = 1.5;
  b.area = 16;
  b.peak = 120;
  return b;
}

// A lamp's blob: wider than a spot in every direction (never a track's).
Blob lamp(const Eigen::Vector2d& uv) {
  Blob b = spot(uv);
  b.spread = 3.3;
  b.width = 6.3;
  b.wide = true;
  b.area = 140;
  return b;
}

// The id of the track that took the blob at uv in the last frame (-1: none).
int track_at(const BlobTracker& tracker, const std::vector<Blob>& blobs,
             const Eigen::Vector2d& uv) {
  for (std::size_t b = 0; b < blobs.size(); ++b)
    if ((Eigen::Vector2d(blobs[b].u, blobs[b].v) - uv).norm() < 1e-9) {
      const int t = tracker.track_of_blob(static_cast<int>(b));
      return t < 0 ? -1 : tracker.tracks()[std::size_t(t)].id;
    }
  return -1;
}

// A brisk sweep from rest: the rig's reflections all moved by this much at frame k (px), changing
// pace and direction, up to some 20 px a frame.
Eigen::Vector2d sweep(int k) {
  const double t = k * 1e-9 * static_cast<double>(kFrameNs);
  return Eigen::Vector2d(150.0 * (1.0 - std::cos(2.0 * M_PI * 1.1 * t)),
                         90.0 * (1.0 - std::cos(2.0 * M_PI * 1.7 * t)));
}

// Along x from rest, 4 px a frame faster each frame up to 20 (px moved by frame k).
double ramp(int k) {
  double x = 0.0;
  for (int i = 1; i <= k; ++i) x += std::min(20.0, 4.0 * i);
  return x;
}

constexpr int M = 3;

mc::detection::IdentifierConfig<M> identical_leds() {
  mc::detection::IdentifierConfig<M> c;
  c.brightness = {1.0, 1.0, 1.0};
  return c;
}

}  // namespace

TEST(BlobTracker, AReflectionHiddenByALampForAQuarterSecondKeepsItsTrack) {
  const std::array<Eigen::Vector2d, 3> rig{Eigen::Vector2d(300, 200), Eigen::Vector2d(360, 230),
                                           Eigen::Vector2d(320, 280)};
  BlobTracker tracker(kMaxSpread);
  std::array<int, 3> id{-1, -1, -1};
  constexpr int kHiddenFrom = 30, kHiddenTo = 42;  // 12 frames, 0.25 s
  for (int k = 0; k < 80; ++k) {
    std::vector<Blob> blobs;
    for (int j = 0; j < 3; ++j)
      if (j != 2 || k < kHiddenFrom || k >= kHiddenTo) blobs.push_back(spot(rig[j] + sweep(k)));
    // The lamp, fixed in the room, lies over marker 2's reflection while it is hidden.
    if (k >= kHiddenFrom && k < kHiddenTo) blobs.push_back(lamp(rig[2] + sweep(k)));
    tracker.track(k * kFrameNs, blobs.data(), static_cast<int>(blobs.size()),
                  [](int) { return -1; });
    for (int j = 0; j < 3; ++j) {
      if (j == 2 && k >= kHiddenFrom && k < kHiddenTo) continue;
      const int now = track_at(tracker, blobs, rig[j] + sweep(k));
      ASSERT_GE(now, 0) << "frame " << k << ", reflection " << j;
      if (id[j] < 0) id[j] = now;
      EXPECT_EQ(now, id[j]) << "frame " << k << ", reflection " << j;
    }
  }
}

TEST(BlobTracker, TwoReflectionsPassingCloseKeepTheirTracksWhenTheTurnChangesPace) {
  // Two reflections 9 px apart, moving together at 20 px a frame, then at 6: the step after the
  // change misses both predictions by 14 px, and the trailing track's prediction lies 5 px from
  // the leading reflection (the closest pair, which the greedy choice alone would take).
  BlobTracker tracker(kMaxSpread);
  const Eigen::Vector2d offset(9, 0);
  int ida = -1, idb = -1;
  for (int k = 0; k < 20; ++k) {
    const Eigen::Vector2d at(100.0 + (k < 10 ? ramp(k) : ramp(9) + 6.0 * (k - 9)), 240.0);
    std::vector<Blob> blobs{spot(at), spot(at + offset)};
    tracker.track(k * kFrameNs, blobs.data(), 2, [](int) { return -1; });
    const int a = track_at(tracker, blobs, at), b = track_at(tracker, blobs, at + offset);
    ASSERT_GE(a, 0);
    ASSERT_GE(b, 0);
    if (ida < 0) {
      ida = a;
      idb = b;
    }
    EXPECT_EQ(a, ida) << "frame " << k;
    EXPECT_EQ(b, idb) << "frame " << k;
  }
}

TEST(BlobTracker, ReflectionsCloseTogetherKeepTheirTracksWhereTheRigTurnsBack) {
  // A rendered room's rig (identical-LED run 12) turning back within a few frames: its reflections
  // slow from 33 px a frame to a standstill and back to -40, so each constant-velocity prediction
  // misses by up to 11 px a frame, alike for all. Two of them lie 13 px apart: matched nearest
  // first, the trailing track took the leading reflection and the leading one's lost its own,
  // every frame of the turn, and no window of the rig's shape ever held three tracks.
  const std::array<Eigen::Vector2d, 17> path{Eigen::Vector2d(270, 285),
                                             {295, 294},
                                             {324, 303},
                                             {355, 310},
                                             {388, 317},
                                             {416, 322},
                                             {439, 327},
                                             {454, 330},
                                             {458, 333},
                                             {451, 334},
                                             {433, 333},
                                             {406, 333},
                                             {372, 330},
                                             {334, 327},
                                             {294, 321},
                                             {256, 316},
                                             {221, 308}};
  const std::array<Eigen::Vector2d, 3> rig{Eigen::Vector2d(0, 0), Eigen::Vector2d(12, -6),
                                           Eigen::Vector2d(20, 53)};
  BlobTracker tracker(kMaxSpread);
  std::array<int, 3> id{-1, -1, -1};
  for (std::size_t k = 0; k < path.size(); ++k) {
    std::vector<Blob> blobs;
    for (const Eigen::Vector2d& r : rig) blobs.push_back(spot(path[k] + r));
    tracker.track(static_cast<std::int64_t>(k) * kFrameNs, blobs.data(),
                  static_cast<int>(blobs.size()), [](int) { return -1; });
    for (std::size_t j = 0; j < rig.size(); ++j) {
      const int now = track_at(tracker, blobs, path[k] + rig[j]);
      if (id[j] < 0) id[j] = now;
      EXPECT_EQ(now, id[j]) << "frame " << k << ", reflection " << j;
    }
  }
}

TEST(BlobTracker, AReflectionSeenFirstMidSweepIsFollowedFromItsSecondFrame) {
  // Two tracks sweep at 20 px a frame; a third reflection enters the image: it moves as they do,
  // beyond a still track's gate (15 px) from its second frame on.
  BlobTracker tracker(kMaxSpread);
  int first = -1;
  for (int k = 0; k < 12; ++k) {
    const Eigen::Vector2d step(ramp(k), 0.25 * ramp(k));
    std::vector<Blob> blobs{spot(Eigen::Vector2d(100, 100) + step),
                            spot(Eigen::Vector2d(150, 120) + step)};
    if (k >= 4) blobs.push_back(spot(Eigen::Vector2d(60, 300) + step));
    tracker.track(k * kFrameNs, blobs.data(), static_cast<int>(blobs.size()),
                  [](int) { return -1; });
    if (k < 4) continue;
    const int now = track_at(tracker, blobs, Eigen::Vector2d(60, 300) + step);
    if (first < 0) first = now;
    EXPECT_EQ(now, first) << "frame " << k;
  }
}

TEST(TrackNames, ASharpPredictionOverrulesTheNameOfALightsTrack) {
  // Marker 0's reflection sits on its prediction, but its track is named 2 (the names of two
  // tracks swapped where they passed), and a room light 9 px away carries name 0. Marker 2's
  // reflection, unnamed, is far off.
  const std::array<Eigen::Vector2d, M> truth = {
      Eigen::Vector2d(300, 200), Eigen::Vector2d(100, 400), Eigen::Vector2d(500, 100)};
  const std::vector<Blob> blobs{spot(truth[0]), spot(truth[0] + Eigen::Vector2d(9, 0)),
                                spot(truth[1]), spot(truth[2])};
  const std::array<int, 4> track_labels{2, 0, 1, -1};
  mc::detection::MarkerIdentifier<M> identifier(identical_leds());
  mc::MarkerFrame<M> frame;
  // A vague prediction (4 px) leaves the names to the tracks: the light is labelled 0.
  auto vague = prediction_at(truth, 4.0);
  identifier.identify(blobs.data(), 4, &vague, frame, track_labels.data());
  EXPECT_EQ(identifier.blob_of(0), 1);
  // A sharp one (1 px, a settled filter's) labels by itself: marker 0's own reflection.
  auto sharp = prediction_at(truth, 1.0);
  identifier.identify(blobs.data(), 4, &sharp, frame, track_labels.data());
  EXPECT_EQ(identifier.blob_of(0), 0);
  ASSERT_TRUE(frame.seen[0]);
  EXPECT_LT((frame.uv[0] - truth[0]).norm(), 1e-9);
  EXPECT_EQ(identifier.blob_of(2), 3);
}

TEST(TrackNames, AVaguePredictionLabelsTheNamedTracksNotALightBesideThem) {
  // A filter that has had no marker: every marker predicted at one pixel, 150 px off, with a
  // sigma of 150 px (identical-LED room run 11, which then labelled nothing in 60 s). Each
  // reflection's track is named; a room light's spot, unnamed, lies among them.
  const std::array<Eigen::Vector2d, M> lost = {Eigen::Vector2d(560, 300), Eigen::Vector2d(560, 300),
                                               Eigen::Vector2d(560, 300)};
  const std::vector<Blob> blobs{spot(Eigen::Vector2d(368, 297)), spot(Eigen::Vector2d(336, 310)),
                                spot(Eigen::Vector2d(436, 310)), spot(Eigen::Vector2d(361, 367))};
  const std::array<int, 4> track_labels{2, 1, -1, 0};
  mc::detection::MarkerIdentifier<M> identifier(identical_leds());
  mc::MarkerFrame<M> frame;
  auto vague = prediction_at(lost, 150.0);
  identifier.identify(blobs.data(), 4, &vague, frame, track_labels.data());
  EXPECT_EQ(identifier.blob_of(0), 3);
  EXPECT_EQ(identifier.blob_of(1), 1);
  EXPECT_EQ(identifier.blob_of(2), 0);
  EXPECT_TRUE(frame.seen[0] && frame.seen[1] && frame.seen[2]);
}

TEST(TrackNames, ASharpPredictionTakesANameBackFromTheTrackThatHeldIt) {
  // The tracks started in the blobs' order: a light (track 0) holds name 0; marker 0's reflection
  // (track 1) is unnamed, and no prediction alone renames it while the light's track lives.
  const mc::detection::RigGeometry<M> prior{};
  const std::vector<Blob> blobs{spot(Eigen::Vector2d(320, 200)), spot(Eigen::Vector2d(300, 200)),
                                spot(Eigen::Vector2d(100, 400)), spot(Eigen::Vector2d(500, 100))};
  const auto labels_after = [&](bool sharp) {
    mc::detection::ShapeBootstrap<M> boot(prior, identical_leds());
    boot.name_ahead(mc::detection::names_throughout<M>({0, 2, 3}));
    std::int64_t t_ns = 0;
    boot.feed(t_ns, blobs.data(), 4);
    for (int k = 0; k < 3; ++k) {
      // The identifier, with the prediction, labelled marker 0 on blob 1 (its own reflection).
      boot.confirm({1, 2, 3}, {sharp, sharp, sharp});
      t_ns += kFrameNs;
      boot.feed(t_ns, blobs.data(), 4);
    }
    return std::vector<int>(boot.blob_labels(), boot.blob_labels() + 4);
  };
  EXPECT_EQ(labels_after(false), (std::vector<int>{0, -1, 1, 2}));
  EXPECT_EQ(labels_after(true), (std::vector<int>{-1, 0, 1, 2}));
}

TEST(ShapeBootstrap, ASnapshotWaitsForAReflectionALampCrowds) {
  // Three reflections sweep together; a lamp's tail crowds the second for the first three frames
  // of every half second (the snapshots' spacing), where a snapshot taken on time would leave it
  // out, and no window would hold three tracks throughout.
  const mc::detection::RigGeometry<M> prior{};
  mc::detection::ShapeBootstrap<M> boot(prior, identical_leds(), 0.5);
  const std::int64_t half_second = 500'000'000;
  for (int k = 0; k * kFrameNs < 12 * 1'000'000'000LL; ++k) {
    const std::int64_t t_ns = k * kFrameNs;
    const Eigen::Vector2d at = Eigen::Vector2d(200, 150) + 0.5 * sweep(k);
    std::vector<Blob> blobs{spot(at), spot(at + Eigen::Vector2d(40, 10)),
                            spot(at + Eigen::Vector2d(10, 60))};
    blobs[1].crowded = t_ns % half_second < 3 * kFrameNs;
    boot.feed(t_ns, blobs.data(), 3);
  }
  // Windows of the three tracks were tried (these places fit no rig: only that they were tried).
  EXPECT_GT(boot.counters().windows_tried, 0u);
}
