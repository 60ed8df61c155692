// The loop's timing budget: histogram statistics against a direct computation, every stage and
// path counted as often as the loop ran it, path totals as the sum of their stages, and the
// cyclictest file layout.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/loop/loop.hpp"
#include "mirrorcal/loop/timing.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mc = mirrorcal;
using mc::loop::DurationHistogram;
using mc::loop::LoopProfiler;
using mc::loop::Stage;

namespace {

// Advances by a fixed step at every read, so each timed stage lasts exactly one step.
class SteppingClock final : public mc::hal::Clock {
 public:
  explicit SteppingClock(std::int64_t step_ns) : step_ns_(step_ns) {}
  std::int64_t now_ns() override { return t_ += step_ns_; }
  void advance(std::int64_t ns) { t_ += ns; }

 private:
  std::int64_t step_ns_;
  std::int64_t t_ = 0;
};

// A marker source that says each delivered frame took a fixed time to detect.
class DetectingSource final : public mc::hal::MarkerSource<3> {
 public:
  DetectingSource(const std::vector<mc::io::ObservedFrame>& frames, std::int64_t detection_ns)
      : inner_(frames), detection_ns_(detection_ns) {}
  mc::hal::SourceStatus poll(mc::MarkerFrame<3>& f) override { return inner_.poll(f); }
  std::int64_t detection_ns() const override { return detection_ns_; }

 private:
  mc::io::VectorMarkerSource<3> inner_;
  std::int64_t detection_ns_;
};

// An IMU that waits a fixed time for each sample (the clock moves on by it) and says so.
class WaitingImuSource final : public mc::hal::ImuSource {
 public:
  WaitingImuSource(const std::vector<mc::ImuSample>& samples, SteppingClock& clock,
                   std::int64_t wait_ns)
      : inner_(samples), clock_(clock), wait_ns_(wait_ns) {}
  mc::hal::SourceStatus next(mc::ImuSample& s) override {
    clock_.advance(wait_ns_);
    return inner_.next(s);
  }
  std::int64_t wait_ns() const override { return wait_ns_; }

 private:
  mc::io::VectorImuSource inner_;
  SteppingClock& clock_;
  std::int64_t wait_ns_;
};

}  // namespace

TEST(Timing, HistogramQuantilesMatchSortedDurations) {
  std::mt19937 rng(5);
  std::lognormal_distribution<double> dist(std::log(8000.0), 0.8);  // ns, median 8 us
  DurationHistogram h;
  h.set_budget(20'000);
  std::vector<std::int64_t> d;
  for (int i = 0; i < 20000; ++i) {
    d.push_back(static_cast<std::int64_t>(dist(rng)));
    h.add(d.back());
  }
  std::sort(d.begin(), d.end());
  for (double q : {0.5, 0.99, 0.999}) {
    const auto rank = static_cast<std::size_t>(std::ceil(q * double(d.size())));
    const double bin_upper_edge = double(d[rank - 1] / 1000 + 1);
    EXPECT_DOUBLE_EQ(h.quantile_us(q), bin_upper_edge) << "q " << q;
  }
  EXPECT_EQ(h.count(), d.size());
  EXPECT_EQ(h.min_ns(), d.front());
  EXPECT_EQ(h.max_ns(), d.back());
  EXPECT_EQ(h.misses(), static_cast<std::uint64_t>(
                            std::count_if(d.begin(), d.end(), [](auto x) { return x > 20'000; })));
}

TEST(Timing, LongDurationsOverflowButKeepTheirMaximum) {
  DurationHistogram h;
  h.add(3'000);
  h.add(std::int64_t(DurationHistogram::kBins) * 1000 + 5'000'000);
  EXPECT_EQ(h.overflows(), 1u);
  EXPECT_EQ(h.max_ns(), std::int64_t(DurationHistogram::kBins) * 1000 + 5'000'000);
  EXPECT_DOUBLE_EQ(h.quantile_us(1.0), double(h.max_ns()) * 1e-3);
  EXPECT_DOUBLE_EQ(h.quantile_us(0.5), 4.0);
  EXPECT_EQ(h.misses(), 0u);  // no budget set
}

TEST(Timing, EveryStageOfTheLoopIsTimedAndPathsAddUp) {
  const mc::sim::Scenario s = mc::sim::paper_scenario();
  const mc::sim::SimData data = mc::sim::simulate(s, 3);
  auto prior = mc::sim::draw_prior<3>(s, data, 3);
  prior.t_d = 0.0;  // the true offset: no frame's exposure falls before the first IMU sample
  mc::CalibrationFilter<double, 3, 0> filter(mc::evaluation::scenario_config(s));
  mc::CalibrationFilter<double, 3, 0>::State x0;
  mc::CalibrationFilter<double, 3, 0>::Covariance p0;
  mc::initialise(prior, x0, p0);
  filter.reset(x0, p0);

  // Each IMU read waits 7 ticks for its sample, then costs one tick like every other stage.
  constexpr std::int64_t kTick = 1000, kDetect = 400, kWait = 7 * kTick;  // ns
  SteppingClock clock(kTick);
  // Budgets: the IMU path of an ordinary sample (read and propagation), and the frame path.
  const auto profiler = std::make_unique<LoopProfiler>(clock, 2 * kTick, 4 * kTick);
  WaitingImuSource imu(data.imu, clock, kWait);
  DetectingSource markers(data.frames, kDetect);
  struct NullSink final : mc::loop::EstimateSink<mc::CalibrationFilter<double, 3, 0>> {
    void publish(std::int64_t, const mc::CalibrationFilter<double, 3, 0>&) override {}
  } sink;
  mc::loop::LoopConfig lc;
  lc.profiler = profiler.get();
  mc::loop::CalibrationLoop<double, 3, 0> loop(filter, imu, markers, lc, &sink);
  loop.run();
  const auto& c = loop.counters();
  ASSERT_GT(c.frames, 1000u);

  const auto count = [&](Stage st) { return profiler->histogram(st).count(); };
  EXPECT_EQ(count(Stage::kImuRead), c.imu_samples + 1);  // and the read that met the end
  EXPECT_EQ(count(Stage::kImuWait), c.imu_samples + 1);
  EXPECT_EQ(count(Stage::kUpdate), c.frames);
  EXPECT_EQ(count(Stage::kOutput), c.frames);
  EXPECT_EQ(count(Stage::kMarkerDetection), data.frames.size());
  EXPECT_EQ(count(Stage::kFrameWait), data.frames.size() + 1);  // and the poll that met the end
  EXPECT_EQ(count(Stage::kFramePath), c.frames + c.frames_before_filter);
  EXPECT_EQ(count(Stage::kImuPath), c.imu_samples);
  // One propagation per sample after the first, one more per frame.
  EXPECT_EQ(count(Stage::kPropagation), c.imu_samples - 1 + c.frames);
  // A delivered poll lasts one tick, of which kDetect is detection.
  EXPECT_EQ(profiler->histogram(Stage::kMarkerDetection).max_ns(), kDetect);
  EXPECT_EQ(profiler->histogram(Stage::kMarkerDetection).min_ns(), kDetect);
  // Every frame: poll, propagation, update, output, one tick each.
  EXPECT_EQ(profiler->histogram(Stage::kFramePath).min_ns(), 4 * kTick);
  EXPECT_EQ(profiler->histogram(Stage::kFramePath).max_ns(), 4 * kTick);
  EXPECT_EQ(profiler->histogram(Stage::kFramePath).misses(), 0u);
  // The wait for a sample is timed on its own; the read costs its one tick.
  EXPECT_EQ(profiler->histogram(Stage::kImuWait).min_ns(), kWait);
  EXPECT_EQ(profiler->histogram(Stage::kImuWait).max_ns(), kWait);
  EXPECT_EQ(profiler->histogram(Stage::kImuRead).min_ns(), kTick);
  EXPECT_EQ(profiler->histogram(Stage::kImuRead).max_ns(), kTick);
  // A sample: read and propagation, two ticks, its wait not included (a poll that delivers a frame
  // belongs to the frame's path). The first sample only reads; the one sample whose poll meets the
  // end of the marker stream has that poll as a third tick: the only miss of the 2-tick budget.
  const DurationHistogram& path = profiler->histogram(Stage::kImuPath);
  EXPECT_EQ(path.min_ns(), kTick);
  EXPECT_EQ(path.max_ns(), 3 * kTick);
  EXPECT_EQ(path.misses(), 1u);
  EXPECT_DOUBLE_EQ(path.quantile_us(0.5), 3.0);  // the 2-tick bin [2, 3) us
}

TEST(Timing, HistogramFileHasCyclictestLayout) {
  SteppingClock clock(1000);
  LoopProfiler p(clock, 5'000'000, 50'000'000);
  p.imu_read(42'500, 40'000);  // 40 us waiting, 2.5 us reading
  p.imu_read(2'700, 0);
  p.record(Stage::kPropagation, 7'100);
  p.end_imu_sample();
  const std::string path = ::testing::TempDir() + "/timing-histogram.txt";
  std::FILE* f = std::fopen(path.c_str(), "w");
  ASSERT_NE(f, nullptr);
  p.write_histogram(f);
  ASSERT_EQ(std::fclose(f), 0);
  std::ifstream in(path);
  std::string line;
  int bins = 0;
  std::vector<long> column_sums(static_cast<std::size_t>(Stage::kCount), 0);
  std::string total_line, max_line;
  while (std::getline(in, line)) {
    if (line.rfind("# Total:", 0) == 0) total_line = line;
    if (line.rfind("# Max Latencies:", 0) == 0) max_line = line;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    int bin = -1;
    fields >> bin;
    ASSERT_EQ(bin, bins) << line;
    for (auto& sum : column_sums) {
      long v = -1;
      ASSERT_TRUE(fields >> v) << line;
      sum += v * (v > 0 ? 1 : 0);
    }
    ++bins;
  }
  EXPECT_EQ(bins, DurationHistogram::kBins);
  EXPECT_EQ(column_sums[static_cast<std::size_t>(Stage::kImuWait)], 2);
  EXPECT_EQ(column_sums[static_cast<std::size_t>(Stage::kImuRead)], 2);
  EXPECT_EQ(column_sums[static_cast<std::size_t>(Stage::kPropagation)], 1);
  EXPECT_EQ(column_sums[static_cast<std::size_t>(Stage::kImuPath)], 1);
  EXPECT_EQ(total_line,
            "# Total: 000000002 000000002 000000001 000000000 000000000 000000000 000000000 "
            "000000001 000000000");
  EXPECT_EQ(max_line, "# Max Latencies: 00040 00002 00007 00000 00000 00000 00000 00012 00000");
}
