// The deterministic calibration loop, the same code on the board and on the host: it takes IMU
// samples and marker frames in timestamp order from the HAL, propagates the filter to each frame's
// time, updates, and publishes the estimate. Nothing here allocates after construction.
#pragma once

#include <cstdint>

#include "mirrorcal/estimator/calibration_filter.hpp"
#include "mirrorcal/hal/frames.hpp"
#include "mirrorcal/hal/sources.hpp"
#include "mirrorcal/loop/marker_screen.hpp"
#include "mirrorcal/loop/timing.hpp"

namespace mirrorcal::loop {

struct LoopConfig {
  std::int64_t imu_period_ns = 5'000'000;  // nominal IMU period (200 Hz)
  // An interval longer than gap_periods nominal periods is an IMU gap: counted, and propagated
  // across in steps of one nominal period on linearly interpolated samples, with the process noise
  // of the signal the IMU did not give (CalibrationConfig::gap).
  double gap_periods = 2.5;
  // A gap longer than this (s) is not propagated across: the filter restarts its motion states at
  // the sample after it (CalibrationFilter::restart_motion), keeping the calibration, and the
  // frames inside it are skipped (frames_before_filter). The default GapMotion's attitude sigma
  // is 0.3 rad after 0.2 s, 1 rad after 0.3 s and 2 after 0.4 s: crossings of 100-200 ms stay
  // consistent, while 400 ms cost the paper scenario its self-check (sigma_ratio 0.65).
  double restart_gap_s = 0.3;
  // Times every stage of the loop when set (see timing.hpp).
  LoopProfiler* profiler = nullptr;
  // Each frame's markers judged against each other before the update (marker_screen.hpp).
  MarkerScreenConfig screen{};
};

// What the loop met on its streams; nothing is dropped without being counted here.
struct LoopCounters {
  std::uint64_t imu_samples = 0;
  std::uint64_t imu_out_of_order = 0;  // samples not after the previous one: dropped
  std::uint64_t imu_gaps = 0;          // each gap once, however many frames fall in it
  std::uint64_t imu_restarts = 0;      // gaps longer than restart_gap_s: motion states restarted
  std::uint64_t frames = 0;            // frames used in an update attempt
  std::uint64_t frames_without_markers = 0;
  // frames exposed before the first IMU sample, or more than kMaxBackwardPeriods IMU periods
  // before the filter's time: skipped
  std::uint64_t frames_before_filter = 0;
  std::uint64_t frames_after_imu = 0;  // frames still pending when the IMU stream ended
  std::uint64_t filter_failures = 0;   // predicts or updates refused with a numerical status
};

enum class LoopEnd : std::uint8_t { kEndOfStream, kImuError, kMarkerError };

// Receives the estimate after every frame and at the end of the run.
template <class Filter>
class EstimateSink {
 public:
  virtual ~EstimateSink() = default;
  virtual void publish(std::int64_t t_ns, const Filter& filter) = 0;
};

template <typename S, int M, int NK, int NI = 0>
class CalibrationLoop {
 public:
  using Filter = CalibrationFilter<S, M, NK, NI>;

  CalibrationLoop(Filter& filter, hal::ImuSource& imu, hal::MarkerSource<M>& markers,
                  const LoopConfig& config, EstimateSink<Filter>* sink = nullptr)
      : filter_(filter),
        imu_(imu),
        markers_(markers),
        config_(config),
        sink_(sink),
        screen_(config.screen, filter.config().pixel_sigma) {}

  // Processes one IMU sample and every frame it completes. False once the IMU stream has ended
  // or a source failed (end() says which).
  bool step();
  // Counts what is left pending and publishes the final estimate.
  void finish();
  // Steps until the end of the IMU stream, then finishes.
  LoopEnd run();

  // Marker identification that wants the filter's prediction at each frame's time (a camera
  // source that detects markers in frames): relabel() is called on every frame before its update.
  void set_identifier(hal::MarkerRelabeler<M>* identifier) { identifier_ = identifier; }

  const LoopCounters& counters() const { return counters_; }
  const MarkerScreen<M>& screen() const { return screen_; }
  LoopEnd end() const { return end_; }
  std::int64_t time_ns() const { return last_.t_ns; }

 private:
  // How far back of the filter's time a frame's exposure may lie and still be used (IMU periods),
  // and the largest time offset the loop believes (s).
  static constexpr std::int64_t kMaxBackwardPeriods = 2;
  static constexpr double kMaxTimeOffsetS = 1.0;

  // The time offset's estimate, the frame's exposure minus its stamp (ns).
  std::int64_t time_offset_ns() const;
  // A rolling shutter's readout of the frame's mean marker row after its stamp (ns; 0 global).
  std::int64_t readout_ns(const MarkerFrame<M>& frame) const;
  void propagate_to(const ImuSample& next);
  // Whether the IMU was silent from measured_ to sample: counts the gap, and restarts the motion
  // states across one too long to propagate.
  bool cross_gap(const ImuSample& sample);
  void apply_frame(const MarkerFrame<M>& frame);
  hal::SourceStatus poll_markers();
  hal::SourceStatus read_imu(ImuSample& sample);

  Filter& filter_;
  hal::ImuSource& imu_;
  hal::MarkerSource<M>& markers_;
  LoopConfig config_;
  EstimateSink<Filter>* sink_;
  hal::MarkerRelabeler<M>* identifier_ = nullptr;
  hal::MarkerPrediction<M> prediction_{};
  MarkerScreen<M> screen_;

  LoopCounters counters_{};
  LoopEnd end_ = LoopEnd::kEndOfStream;
  bool started_ = false;
  bool markers_ended_ = false;
  std::int64_t start_ns_ = 0;  // the first IMU sample's time, where the filter's prior holds
  ImuSample last_{};  // the IMU sample at the filter's current time (possibly interpolated)
  // The IMU signal between measured samples is the parabola through the last three (estimator's
  // imu_signal_at): measured_ is the newest measured sample at or before last_, before_ the one
  // before it, valid unless a gap lies between them.
  ImuSample measured_{};
  ImuSample before_{};
  bool has_before_ = false;
  double gap_s_ = 0.0;  // the IMU gap the filter is propagating across (s), 0 outside gaps
  MarkerFrame<M> pending_{};
  bool pending_valid_ = false;
};

// The sample at time t on the straight line between a and b (a.t_ns <= t <= b.t_ns).
ImuSample interpolate(const ImuSample& a, const ImuSample& b, std::int64_t t_ns);

// Compiled in loop.cpp for every filter the product uses (marker_counts.hpp).
#define MIRRORCAL_EXTERN_LOOP_(M, NK, NI) extern template class CalibrationLoop<double, M, NK, NI>;
MIRRORCAL_FOR_EACH_FILTER(MIRRORCAL_EXTERN_LOOP_)
#undef MIRRORCAL_EXTERN_LOOP_

}  // namespace mirrorcal::loop
