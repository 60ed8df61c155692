// No heap on the hot path: predict and update of every filter configuration the product compiles
// must not allocate (counted by tests/support/alloc_counter).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <vector>

#include "alloc_counter.hpp"
#include "mirrorcal/estimator/calibration_filter.hpp"
#include "test_support.hpp"

namespace mirrorcal {
namespace {

using test::AllocCounter;
using test::AllocCounts;

TEST(NoHeap, CounterSeesAllocations) {
  ASSERT_TRUE(test::alloc_counter_installed()) << "sanitizer allocation hook not installed";
  AllocCounter counting;
  int* a = new int(3);
  test::escape(a);
  delete a;
  void* b = std::malloc(64);
  test::escape(b);
  std::free(b);
  std::vector<double> v(100);
  test::escape(v.data());
  const AllocCounts c = counting.stop();
  EXPECT_GE(c.news, 2);
  EXPECT_GE(c.mallocs, 2);
}

// Drives one configuration through predicts and every kind of update.
template <typename S, int NK>
AllocCounts exercise() {
  using Filter = CalibrationFilter<S, 3, NK>;
  using State = typename Filter::State;
  const test::SineTrajectory traj = test::wall_mirror_trajectory();
  const test::Rig rig;
  std::vector<ImuSample> imu;
  std::vector<MarkerFrame<3>> frames;
  for (int k = 0; k <= 400; ++k) {
    imu.push_back(traj.imu(k * 5000000LL));
    if (k % 10 == 0) {
      MarkerFrame<3> f;
      f.t_ns = imu.back().t_ns;
      const bool visible = test::render_markers(traj, rig, f.t_ns * 1e-9, f.uv);
      f.seen = {visible, visible, visible};
      frames.push_back(f);
    }
  }
  const State x0 = test::truth_state<S, 3, NK>(traj, rig, 0.0);
  typename Filter::Covariance p0 = Filter::Covariance::Identity() * S(1e-4);
  if constexpr (NK > 0) p0.diagonal().template tail<NK>().setConstant(S(100.0));

  CalibrationConfig cfg;
  cfg.gravity_n = traj.gravity_n;
  cfg.intrinsics = rig.pinhole();
  cfg.gate_after_frames = 0;  // gate from the first frame, so the outliers take that path too
  Filter warm(cfg);
  warm.reset(x0, p0);
  warm.predict(imu[0], imu[1]);
  warm.update(frames[0]);

  AllocCounter counting;
  Filter f(cfg);
  f.reset(x0, p0);
  int kind = 0;
  for (std::size_t k = 1; k < imu.size(); ++k) {
    f.predict(imu[k - 1], imu[k]);
    if (k % 10 != 0) continue;
    MarkerFrame<3> frame = frames[k / 10];
    switch (kind++ % 5) {
      case 0:
        break;  // full frame
      case 1:
        frame.seen[1] = false;
        break;  // partial
      case 2:
        frame.uv[0] += Eigen::Vector2d(300, 300);
        break;  // outlier: gated
      case 3:
        frame.seen = {false, false, false};
        break;  // empty
      case 4:
        frame.uv[2].x() = std::nan("");
        break;  // NaN: gated
    }
    f.update(frame);
  }
  // A refused predict (non-finite sample) goes through the failure path.
  ImuSample bad = imu[1];
  bad.gyro.x() = std::nan("");
  f.predict(imu[0], bad);
  const AllocCounts c = counting.stop();
  // The run did what it was meant to: updates used, gated and refused.
  EXPECT_GT(f.counters().markers_used, 50u);
  EXPECT_GE(f.counters().markers_gated, 10u);
  EXPECT_EQ(f.counters().failures, 1u);
  return c;
}

TEST(NoHeap, DoubleStage1) {
  const AllocCounts c = exercise<double, 0>();
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

TEST(NoHeap, DoubleStage2) {
  const AllocCounts c = exercise<double, 5>();
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

TEST(NoHeap, FloatStage1) {
  const AllocCounts c = exercise<float, 0>();
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

}  // namespace
}  // namespace mirrorcal
