// The loop's timing budget: every stage of the loop timed on a monotonic clock into fixed
// histograms of 1-microsecond bins (no allocation, two clock reads and a few adds per stage), with
// per-path totals checked against a deadline: the IMU path (one IMU sample: read and propagation,
// not the wait for the sample, which is timed on its own) against the IMU period, the frame path
// (one frame: dequeue, detection, propagation to its time, update, output) against the frame
// period. Reported as count, min, median, p99, p99.9, max and deadline misses, and written in
// cyclictest's histogram format (one column per stage and path), which the tools people already use
// for latency plots read.
#pragma once

#include <array>
#include <cstdint>
#include <cstdio>
#include <string>

#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::loop {

enum class Stage : std::uint8_t {
  kImuWait,          // ImuSource::next waiting for the sample (its wait_ns): not a cost
  kImuRead,          // ImuSource::next less its wait: reading and decoding the sample
  kPropagation,      // filter predicts (to a frame's time and to the sample's)
  kFrameWait,        // MarkerSource::poll less the detection it reports
  kMarkerDetection,  // MarkerSource::detection_ns of a delivered frame
  kUpdate,           // the filter's measurement update
  kOutput,           // publishing the estimate
  kImuPath,          // total of one IMU sample, frames excluded
  kFramePath,        // total of one frame
  kCount,
};

const char* stage_name(Stage s);

// A histogram of durations in 1-us bins up to kBins us; longer ones are counted as overflows
// (their exact maximum is still kept). Durations over the budget (if one is set) are counted
// exactly as they arrive: a bin does not resolve the budget.
class DurationHistogram {
 public:
  static constexpr int kBins = 20000;  // 20 ms: four IMU periods at 200 Hz, 0.4 frame periods

  void set_budget(std::int64_t ns) { budget_ns_ = ns; }
  void add(std::int64_t ns);
  std::uint64_t count() const { return count_; }
  std::uint64_t overflows() const { return overflows_; }
  std::uint64_t bin(int us) const { return bins_[static_cast<std::size_t>(us)]; }
  std::int64_t min_ns() const { return count_ == 0 ? 0 : min_ns_; }
  std::int64_t max_ns() const { return max_ns_; }
  double mean_ns() const { return count_ == 0 ? 0.0 : double(sum_ns_) / double(count_); }
  // The upper edge (us) of the bin holding quantile q in (0, 1]; max_ns/1000 if in the overflow.
  double quantile_us(double q) const;
  std::int64_t budget_ns() const { return budget_ns_; }  // 0: none
  std::uint64_t misses() const { return misses_; }

 private:
  std::array<std::uint32_t, kBins> bins_{};
  std::uint64_t count_ = 0, overflows_ = 0, misses_ = 0;
  std::int64_t min_ns_ = 0, max_ns_ = 0, sum_ns_ = 0, budget_ns_ = 0;
};

struct StageReport {
  Stage stage;
  std::uint64_t count;
  double min_us, median_us, p99_us, p999_us, max_us, mean_us;
  std::int64_t budget_ns;  // 0: no deadline for this stage
  std::uint64_t misses;
};

// Times the loop's stages. Start-up only: construct it before the loop runs (it is large, about
// 720 KiB: hold it statically or allocate it once), then pass it in LoopConfig::profiler.
class LoopProfiler {
 public:
  LoopProfiler(hal::Clock& clock, std::int64_t imu_budget_ns, std::int64_t frame_budget_ns);

  std::int64_t now_ns() { return clock_.now_ns(); }
  // Adds a stage's duration to its histogram and to the running total of the current path.
  void record(Stage s, std::int64_t ns);
  // An IMU read that took ns, wait_ns of it waiting for the sample (ImuSource::wait_ns). The wait
  // is timed as kImuWait and left out of the IMU path, so that path's deadline misses count cost,
  // not samples that came late.
  void imu_read(std::int64_t ns, std::int64_t wait_ns);
  // A marker poll that took ns, detection_ns of it in detection, or -1 if it delivered no frame.
  // A delivered frame's poll starts the total of its frame path (it may wait for the IMU to reach
  // its time before it is processed); a poll that delivered nothing belongs to the IMU path.
  void marker_polled(std::int64_t ns, std::int64_t detection_ns);
  // The stages recorded between begin_frame() and end_frame() belong to the frame path; all others
  // to the IMU path, which end_imu_sample() closes.
  void begin_frame() { in_frame_ = true; }
  void end_frame();
  void end_imu_sample();

  const DurationHistogram& histogram(Stage s) const { return hist_[index(s)]; }
  StageReport report(Stage s) const;
  // The table of every stage that ran, one line each, with a title line.
  std::string table() const;
  // Writes every stage and path as one column of a cyclictest histogram to f (the caller's file:
  // the loop itself writes no file).
  void write_histogram(std::FILE* f) const;

 private:
  static std::size_t index(Stage s) { return static_cast<std::size_t>(s); }
  void close_path(Stage path, std::int64_t& total);

  hal::Clock& clock_;
  std::array<DurationHistogram, static_cast<std::size_t>(Stage::kCount)> hist_{};
  bool in_frame_ = false;
  std::int64_t imu_total_ns_ = 0, frame_total_ns_ = 0;
};

// Times one stage from construction to destruction; does nothing without a profiler.
class StageTimer {
 public:
  StageTimer(LoopProfiler* p, Stage s) : p_(p), s_(s), t0_(p == nullptr ? 0 : p->now_ns()) {}
  ~StageTimer() {
    if (p_ != nullptr) p_->record(s_, p_->now_ns() - t0_);
  }
  StageTimer(const StageTimer&) = delete;
  StageTimer& operator=(const StageTimer&) = delete;

 private:
  LoopProfiler* p_;
  Stage s_;
  std::int64_t t0_;
};

// Closes the current IMU sample's path when it goes out of scope; does nothing without a profiler.
class ImuSampleScope {
 public:
  explicit ImuSampleScope(LoopProfiler* p) : p_(p) {}
  ~ImuSampleScope() {
    if (p_ != nullptr) p_->end_imu_sample();
  }
  ImuSampleScope(const ImuSampleScope&) = delete;
  ImuSampleScope& operator=(const ImuSampleScope&) = delete;

 private:
  LoopProfiler* p_;
};

// The host's std::chrono::steady_clock (CLOCK_MONOTONIC on Linux) as a hal::Clock: what the
// profiler times a simulated run by, whose own clock is simulated time. It only reads the time;
// the board's drivers pace, sleep and wait on drivers::MonotonicClock (a drivers::Timebase), which
// firmware does not depend on.
class SteadyClock final : public hal::Clock {
 public:
  std::int64_t now_ns() override;
};

}  // namespace mirrorcal::loop
