// Google Benchmark of the filter's operations and of the whole loop:
//   predict/<float|double>/M, update/<float|double>/M  one operation, timed alone (manual time:
//                                                       the filter is restored between them)
//   textbook_predict/double/M, textbook_update/double/M the same operations of the textbook
//                                                       full-state UKF of the same model
//                                                       (textbook_ukf.hpp), on the same inputs
//   imu_predict/double/3, imu_update/double/3           the same with the IMU's intrinsics
//                                                       (scale-misalignment), if built
//   recording_60s                                       the whole loop over the 60 s recording
//   recording_60s_shipped                               its calibration as mirrorcal makes it
//   recording_60s_shipped_imu                           the same with the IMU's intrinsics
// The counters report the error-state dimension and sizeof the filter.
#include <benchmark/benchmark.h>

#include <chrono>
#include <memory>
#include <string>

#include "filter_ops.hpp"
#include "recording.hpp"

namespace mb = mirrorcal::bench;

namespace {

template <bool kUpdate>
void time_operation(benchmark::State& state, mb::FilterOps* ops) {
  bool ok = true;
  for (auto _ : state) {
    ops->restore();
    const auto t0 = std::chrono::steady_clock::now();
    ok &= kUpdate ? ops->update() : ops->predict();
    const auto t1 = std::chrono::steady_clock::now();
    state.SetIterationTime(std::chrono::duration<double>(t1 - t0).count());
  }
  if (!ok) state.SkipWithError("the operation failed");
  state.counters["dim"] = ops->dim();
  state.counters["filter_bytes"] = double(ops->filter_bytes());
}

void recording(benchmark::State& state, const mb::Recording* r,
               std::uint64_t (*calibrate)(const mb::Recording&)) {
  std::uint64_t used = 0;
  for (auto _ : state) used = calibrate(*r);
  if (used == 0) state.SkipWithError("no marker used");
  state.counters["markers_used"] = double(used);
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  std::vector<std::unique_ptr<mb::FilterOps>> keep;
  for (const bool single : {false, true}) {
    for (const int m : mb::built_marker_counts()) {
      keep.push_back(mb::make_filter_ops(m, single));
      mb::FilterOps* ops = keep.back().get();
      const std::string suffix = std::string(single ? "float/" : "double/") + std::to_string(m);
      benchmark::RegisterBenchmark(("predict/" + suffix).c_str(), time_operation<false>, ops)
          ->UseManualTime();
      benchmark::RegisterBenchmark(("update/" + suffix).c_str(), time_operation<true>, ops)
          ->UseManualTime();
    }
  }
  for (const int m : mb::built_marker_counts()) {
    keep.push_back(mb::make_textbook_ops(m));
    mb::FilterOps* ops = keep.back().get();
    if (ops == nullptr) continue;
    const std::string suffix = "double/" + std::to_string(m);
    benchmark::RegisterBenchmark(("textbook_predict/" + suffix).c_str(), time_operation<false>, ops)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("textbook_update/" + suffix).c_str(), time_operation<true>, ops)
        ->UseManualTime();
  }
  keep.push_back(mb::make_imu_filter_ops(12));
  const bool imu_model_built = keep.back() != nullptr;
  if (mb::FilterOps* ops = keep.back().get()) {
    benchmark::RegisterBenchmark("imu_predict/double/3", time_operation<false>, ops)
        ->UseManualTime();
    benchmark::RegisterBenchmark("imu_update/double/3", time_operation<true>, ops)->UseManualTime();
  }
  const mb::Recording rec = mb::paper_recording();
  benchmark::RegisterBenchmark("recording_60s", recording, &rec, mb::calibrate)
      ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("recording_60s_shipped", recording, &rec, mb::calibrate_as_shipped)
      ->Unit(benchmark::kMillisecond);
  if (imu_model_built)
    benchmark::RegisterBenchmark("recording_60s_shipped_imu", recording, &rec,
                                 mb::calibrate_as_shipped_with_imu_intrinsics)
        ->Unit(benchmark::kMillisecond);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
