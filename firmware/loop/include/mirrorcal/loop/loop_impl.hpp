// Definitions of CalibrationLoop; included only where a configuration is instantiated.
#pragma once

#include <algorithm>
#include <cmath>

#include "mirrorcal/loop/loop.hpp"
#include "mirrorcal/loop/marker_prediction.hpp"

namespace mirrorcal::loop {

template <typename S, int M, int NK, int NI>
void CalibrationLoop<S, M, NK, NI>::propagate_to(const ImuSample& next) {
  const StageTimer timer(config_.profiler, Stage::kPropagation);
  if (next.t_ns <= last_.t_ns) return;
  if (gap_s_ > 0.0) {
    // Step across the gap one nominal period at a time so the integration stays second order.
    while (next.t_ns - last_.t_ns > config_.imu_period_ns) {
      const ImuSample mid = interpolate(last_, next, last_.t_ns + config_.imu_period_ns);
      if (filter_.predict(last_, mid, nullptr, gap_s_) != FilterStatus::kOk)
        ++counters_.filter_failures;
      last_ = mid;
    }
  }
  // The third node of the signal's parabola: the measured sample before the interval's start.
  const ImuSample* node =
      !has_before_ ? nullptr : (last_.t_ns == measured_.t_ns ? &before_ : &measured_);
  if (filter_.predict(last_, next, node, gap_s_) != FilterStatus::kOk) ++counters_.filter_failures;
  last_ = next;
}

template <typename S, int M, int NK, int NI>
bool CalibrationLoop<S, M, NK, NI>::cross_gap(const ImuSample& sample) {
  const std::int64_t silent_ns = sample.t_ns - measured_.t_ns;
  gap_s_ = 0.0;
  if (static_cast<double>(silent_ns) <=
      config_.gap_periods * static_cast<double>(config_.imu_period_ns))
    return false;
  ++counters_.imu_gaps;
  gap_s_ = static_cast<double>(silent_ns) * 1e-9;
  if (gap_s_ > config_.restart_gap_s) {
    ++counters_.imu_restarts;
    filter_.restart_motion(sample);
    last_ = sample;
    gap_s_ = 0.0;
  }
  return true;
}

template <typename S, int M, int NK, int NI>
void CalibrationLoop<S, M, NK, NI>::apply_frame(const MarkerFrame<M>& frame) {
  ++counters_.frames;
  UpdateResult r;
  {
    const StageTimer timer(config_.profiler, Stage::kUpdate);
    r = filter_.update(frame);
  }
  if (r.status == FilterStatus::kNoMeasurement) {
    ++counters_.frames_without_markers;
  } else if (r.status != FilterStatus::kOk) {
    ++counters_.filter_failures;
  }
  if (sink_ != nullptr) {
    const StageTimer timer(config_.profiler, Stage::kOutput);
    sink_->publish(frame.t_ns, filter_);
  }
  if (config_.profiler != nullptr) config_.profiler->end_frame();
}

template <typename S, int M, int NK, int NI>
hal::SourceStatus CalibrationLoop<S, M, NK, NI>::poll_markers() {
  LoopProfiler* const p = config_.profiler;
  if (p == nullptr) return markers_.poll(pending_);
  const std::int64_t t0 = p->now_ns();
  const hal::SourceStatus st = markers_.poll(pending_);
  p->marker_polled(p->now_ns() - t0, st == hal::SourceStatus::kOk ? markers_.detection_ns() : -1);
  return st;
}

template <typename S, int M, int NK, int NI>
hal::SourceStatus CalibrationLoop<S, M, NK, NI>::read_imu(ImuSample& sample) {
  LoopProfiler* const p = config_.profiler;
  if (p == nullptr) return imu_.next(sample);
  const std::int64_t t0 = p->now_ns();
  const hal::SourceStatus st = imu_.next(sample);
  p->imu_read(p->now_ns() - t0, imu_.wait_ns());
  return st;
}

template <typename S, int M, int NK, int NI>
bool CalibrationLoop<S, M, NK, NI>::step() {
  ImuSample sample;
  const hal::SourceStatus st = read_imu(sample);
  if (st != hal::SourceStatus::kOk) {
    end_ = st == hal::SourceStatus::kEndOfStream ? LoopEnd::kEndOfStream : LoopEnd::kImuError;
    return false;
  }
  const ImuSampleScope sample_scope(config_.profiler);
  ++counters_.imu_samples;
  if (!started_) {  // the filter's prior holds at the first sample's time
    started_ = true;
    last_ = measured_ = sample;
    start_ns_ = sample.t_ns;
    filter_.start_at(sample);
    return true;
  }
  if (sample.t_ns <= last_.t_ns) {
    ++counters_.imu_out_of_order;
    return true;
  }
  // Across a gap the signal is the straight line (propagate_to steps through it).
  const bool gap = cross_gap(sample);
  if (gap) has_before_ = false;
  // Every frame up to this sample's time: propagate to the frame, update, go on.
  for (;;) {
    if (!pending_valid_) {
      if (markers_ended_) break;
      const hal::SourceStatus ms = poll_markers();
      if (ms == hal::SourceStatus::kEndOfStream) {
        markers_ended_ = true;
        break;
      }
      if (ms == hal::SourceStatus::kError) {
        end_ = LoopEnd::kMarkerError;
        return false;
      }
      if (ms != hal::SourceStatus::kOk) break;
      pending_valid_ = true;
    }
    // The frame shows the rig at IMU time t_cam + t_d (a rolling shutter's rows later by their
    // line delays): the filter goes to that time at the time offset's estimate and the mean row
    // of the frame's markers, and the update's Exposure covers the rest.
    const std::int64_t exposed_ns = pending_.t_ns + time_offset_ns() + readout_ns(pending_);
    if (exposed_ns > sample.t_ns) break;  // the IMU has not reached it yet
    pending_valid_ = false;
    if (config_.profiler != nullptr) config_.profiler->begin_frame();
    // Before the filter's time by a little (the offset's estimate moved back past it): the
    // Exposure extrapolates back; by more, the frame is out of order or older than the first IMU
    // sample.
    if (exposed_ns < start_ns_ ||
        exposed_ns < last_.t_ns - kMaxBackwardPeriods * config_.imu_period_ns) {
      ++counters_.frames_before_filter;
      if (config_.profiler != nullptr) config_.profiler->end_frame();
      continue;
    }
    propagate_to(imu_signal_at(has_before_ ? &before_ : nullptr, measured_, sample,
                               std::max(exposed_ns, last_.t_ns)));
    if (identifier_ != nullptr && predict_marker_pixels(filter_, pending_, prediction_))
      identifier_->relabel(prediction_, pending_);
    const bool gate_open = filter_.counters().updates < filter_.config().gate_after_frames;
    screen_.screen(pending_, gate_open);  // its counts per marker: screen()
    apply_frame(pending_);
  }
  propagate_to(sample);
  before_ = measured_;
  measured_ = sample;
  has_before_ = !gap;
  return true;
}

template <typename S, int M, int NK, int NI>
std::int64_t CalibrationLoop<S, M, NK, NI>::time_offset_ns() const {
  const double t_d = static_cast<double>(filter_.state().t_d);
  if (!(std::abs(t_d) < kMaxTimeOffsetS)) return 0;  // NaN or beyond any camera: not trusted
  return std::llround(t_d * 1e9);
}

template <typename S, int M, int NK, int NI>
std::int64_t CalibrationLoop<S, M, NK, NI>::readout_ns(const MarkerFrame<M>& frame) const {
  const double line_delay_s = filter_.config().intrinsics.line_delay_s;
  if (line_delay_s == 0.0) return 0;
  return std::llround(line_delay_s * readout_anchor_row(frame) * 1e9);
}

template <typename S, int M, int NK, int NI>
void CalibrationLoop<S, M, NK, NI>::finish() {
  if (pending_valid_) ++counters_.frames_after_imu;
  pending_valid_ = false;
  if (sink_ != nullptr) sink_->publish(last_.t_ns, filter_);
}

template <typename S, int M, int NK, int NI>
LoopEnd CalibrationLoop<S, M, NK, NI>::run() {
  while (step()) {
  }
  finish();
  return end_;
}

}  // namespace mirrorcal::loop
