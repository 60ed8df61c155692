// The plane mirror's fit (mirror_fit.hpp), which tells identical LEDs apart: on the random
// family's frames the true labelling fits as well as its chi-square says, and with the markers
// known to a few millimetres a wrong labelling fits worse.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <random>

#include "mirrorcal/detection/mirror_fit.hpp"
#include "mirrorcal/sim/scenario.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mc = mirrorcal;

namespace {

constexpr int M = 3;

struct Tally {
  int frames = 0;
  int told_apart = 0;  // every wrong labelling costs more than the margin above the true one
  int misled = 0;      // a wrong labelling costs less than the true one by the margin
  double true_cost = 0.0;
};

// Every tenth frame of a rig's minute in which all markers are seen: the true labelling's cost
// and every other permutation's, with the markers known to marker_sigma (each coordinate drawn
// off the truth by that much).
void tally_rig(const mc::sim::Scenario& s, std::uint64_t seed, double marker_sigma, double margin,
               Tally& t) {
  const mc::sim::SimData data = mc::sim::simulate(s, seed);
  mc::detection::RigGeometry<M> g;
  g.camera = s.truth.intrinsics;
  g.pixel_sigma = s.pixel_sigma;
  g.marker_sigma_m = std::max(marker_sigma, 1e-6);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> off(0.0, marker_sigma);
  for (int i = 0; i < M; ++i)
    g.markers_c[std::size_t(i)] =
        s.truth.markers[std::size_t(i)] + Eigen::Vector3d(off(rng), off(rng), off(rng));
  for (std::size_t f = 0; f < data.frames.size(); f += 10) {
    const auto& markers = data.frames[f].markers;
    if (markers.size() != std::size_t(M)) continue;
    std::array<Eigen::Vector2d, M> blob;
    for (const auto& m : markers) blob[std::size_t(m.id)] = Eigen::Vector2d(m.u, m.v);
    const std::array<bool, M> all{true, true, true};
    std::array<int, M> order{0, 1, 2};
    const mc::detection::MirrorFit truth = mc::detection::fit_mirror<M>(g, all, blob);
    ASSERT_TRUE(truth.made);
    double wrong = std::numeric_limits<double>::infinity();
    while (std::next_permutation(order.begin(), order.end())) {
      std::array<Eigen::Vector2d, M> labelled;
      for (int i = 0; i < M; ++i)
        labelled[std::size_t(i)] = blob[std::size_t(order[std::size_t(i)])];
      wrong = std::min(wrong, mc::detection::fit_mirror<M>(g, all, labelled).cost);
    }
    ++t.frames;
    t.true_cost += truth.cost;
    if (wrong > truth.cost + margin) ++t.told_apart;
    if (wrong + margin < truth.cost) ++t.misled;
  }
}

}  // namespace

// At the true markers the true labelling's cost is chi-square with 2 M - 3 = 3 degrees of freedom
// (the pixel noise alone): its average over some 600 frames of 10 rigs within 2.7..3.3 (99.9 %).
TEST(MirrorFit, AtTheTrueMarkersTheTrueLabellingCostsItsChiSquare) {
  Tally t;
  for (std::uint64_t seed = 1; seed <= 10; ++seed)
    tally_rig(mc::sim::random_scenario(seed), seed, 0.0, 6.0, t);
  ASSERT_GT(t.frames, 300);
  const double average = t.true_cost / t.frames;
  std::printf("%d frames: the true labelling's average cost %.2f, told apart in %d, misled in %d\n",
              t.frames, average, t.told_apart, t.misled);
  EXPECT_GT(average, 2.7);
  EXPECT_LT(average, 3.3);
  EXPECT_EQ(t.misled, 0);
}

// With the markers measured to 5 mm (a ruler's), over 30 rigs: the true labelling is told apart
// from every other in at least 95 % of the frames, and a wrong one fits better by the margin in
// at most 0.1 %. (Measured: 100 % at 2 and 5 mm, 99.0 % at 1 cm, 69 % at 2 cm; the random family's
// priors, 10 cm, leave a single frame ambiguous: labels are then bootstrapped over frames.)
TEST(MirrorFit, FromMarkersMeasuredToFiveMillimetresIdenticalLedsAreToldApart) {
  Tally t;
  for (std::uint64_t seed = 1; seed <= 30; ++seed)
    tally_rig(mc::sim::random_scenario(seed), seed, 0.005, 6.0, t);
  ASSERT_GT(t.frames, 1000);
  std::printf(
      "%d frames: the true labelling's average cost %.2f, told apart in %d (%.1f %%), "
      "misled in %d\n",
      t.frames, t.true_cost / t.frames, t.told_apart, 100.0 * t.told_apart / t.frames, t.misled);
  EXPECT_GE(t.told_apart, 0.95 * t.frames);
  EXPECT_LE(t.misled, 0.001 * t.frames);
}
