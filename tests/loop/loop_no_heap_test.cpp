// No heap in the whole loop after start-up: a 60 s simulated calibration, with the timing budget
// on, the estimate published after every frame with its residuals (the report's), and two IMU gaps
// (one crossed, one restarting the motion states), must not allocate once the loop runs.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <memory>
#include <vector>

#include "alloc_counter.hpp"
#include "mirrorcal/calibration/history.hpp"
#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/loop/loop.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mc = mirrorcal;

TEST(LoopNoHeap, CounterSeesAllocations) {
  ASSERT_TRUE(mc::test::alloc_counter_installed());
  mc::test::AllocCounter counting;
  auto v = std::make_unique<std::vector<double>>(10);
  mc::test::escape(v.get());
  v.reset();
  void* p = std::malloc(32);
  mc::test::escape(p);
  std::free(p);
  const auto c = counting.stop();
  EXPECT_GE(c.news, 2);
  EXPECT_GE(c.mallocs, 1);
}

TEST(LoopNoHeap, LoopDoesNotAllocateAfterStartUp) {
  using Filter = mc::CalibrationFilter<double, 3, 0>;
  const mc::sim::Scenario s = mc::sim::paper_scenario();
  mc::sim::SimData data = mc::sim::simulate(s, 21);
  constexpr std::int64_t kMs = 1'000'000;
  for (const std::int64_t from : {20'000 * kMs, 40'000 * kMs}) {  // 200 ms, then 1 s, silent
    const std::int64_t to = from + (from == 20'000 * kMs ? 200 : 1000) * kMs;
    data.imu.erase(
        std::remove_if(data.imu.begin(), data.imu.end(),
                       [&](const mc::ImuSample& x) { return x.t_ns >= from && x.t_ns < to; }),
        data.imu.end());
  }
  const auto prior = mc::sim::draw_prior<3>(s, data, 21);
  // Start-up: everything the loop needs is made here.
  Filter filter(mc::evaluation::scenario_config(s));
  Filter::State x0;
  Filter::Covariance p0;
  mc::initialise(prior, x0, p0);
  filter.reset(x0, p0);
  mc::io::VectorImuSource imu(data.imu);
  mc::io::VectorMarkerSource<3> listed(data.frames);
  mc::calibration::FrameTap<3> markers(listed, nullptr);
  mc::calibration::HistorySink<Filter> sink(data.frames.size() + 1, nullptr, &markers);
  mc::loop::SteadyClock clock;
  const auto profiler = std::make_unique<mc::loop::LoopProfiler>(clock, 5'000'000, 50'000'000);
  mc::loop::LoopConfig lc;
  lc.profiler = profiler.get();
  mc::loop::CalibrationLoop<double, 3, 0> loop(filter, imu, markers, lc, &sink);
  markers.watch(&loop.screen());

  mc::test::AllocCounter counting;
  const auto end = loop.run();
  const auto c = counting.stop();
  EXPECT_EQ(end, mc::loop::LoopEnd::kEndOfStream);
  EXPECT_EQ(loop.counters().imu_samples, data.imu.size());
  EXPECT_EQ(loop.counters().imu_gaps, 2u);
  EXPECT_EQ(loop.counters().imu_restarts, 1u);
  EXPECT_GT(filter.counters().markers_used, 2000u);
  EXPECT_EQ(sink.rows().size(), loop.counters().frames + 1);
  // Each marker the filter took (not withheld by the loop's screen) has its residual, and the
  // updates' NIS add up to the filter's.
  std::uint64_t residuals = 0;
  double nis = 0.0;
  for (const auto& row : sink.rows()) {
    for (std::size_t i = 0; i < row.residual_valid.size(); ++i)
      residuals += row.residual_valid[i] && !row.withheld[i] ? 1 : 0;
    nis += row.nis;
  }
  EXPECT_EQ(residuals, filter.counters().markers_used + filter.counters().markers_gated);
  EXPECT_NEAR(nis, filter.counters().nis_sum, 1e-6 * filter.counters().nis_sum);
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

// The same with the IMU's intrinsics estimated (scale-misalignment) on a MEMS rig: their
// propagation and the exposure's reading of the samples allocate nothing either.
template <int NI>
void expect_intrinsics_loop_allocates_nothing() {
  using Filter = mc::CalibrationFilter<double, 3, 0, NI>;
  const mc::sim::Scenario s = mc::sim::mems_scenario(4);
  const mc::sim::SimData data = mc::sim::simulate(s, 4);
  Filter filter(mc::evaluation::scenario_config(s));
  typename Filter::State x0;
  typename Filter::Covariance p0;
  mc::initialise(mc::sim::draw_prior<3>(s, data, 4), x0, p0);
  filter.reset(x0, p0);
  mc::io::VectorImuSource imu(data.imu);
  mc::io::VectorMarkerSource<3> listed(data.frames);
  mc::calibration::FrameTap<3> markers(listed, nullptr);
  mc::calibration::HistorySink<Filter> sink(data.frames.size() + 1, nullptr, &markers);
  filter.keep_motion_steps(true);  // the smoother's steps too
  sink.keep_motion();
  mc::loop::CalibrationLoop<double, 3, 0, NI> loop(filter, imu, markers, {}, &sink);

  mc::test::AllocCounter counting;
  const auto end = loop.run();
  const auto c = counting.stop();
  EXPECT_EQ(end, mc::loop::LoopEnd::kEndOfStream);
  EXPECT_GT(filter.counters().markers_used, 2000u);
  EXPECT_EQ(filter.counters().failures, 0u);
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

TEST(LoopNoHeap, LoopWithTheImuIntrinsicsDoesNotAllocate) {
  constexpr int kModel = mc::imu_intrinsics_dim(mc::ImuModel::kScaleMisalignment);
  // Instantiated for a build with the model only (the board's cross-test has the ideal IMU's).
  if (!mc::imu_model_built(kModel)) GTEST_SKIP() << "built without the scale-misalignment model";
  mc::with_imu_model(kModel, [](auto ni) {
    if constexpr (decltype(ni)::value == kModel) expect_intrinsics_loop_allocates_nothing<kModel>();
  });
}
