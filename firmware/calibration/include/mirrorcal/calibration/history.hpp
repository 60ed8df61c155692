// The estimate over time, as the loop publishes it: a sink that keeps every published estimate in
// a temporary file (record_store.hpp: one page of it in memory, whatever the recording's length;
// with each frame's residuals and normalised innovation squared, for the report), and the
// calibration parameters' names and units.
#pragma once

#include <array>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "mirrorcal/calibration/record_store.hpp"
#include "mirrorcal/hal/frames.hpp"
#include "mirrorcal/loop/loop.hpp"

namespace mirrorcal::calibration {

// A calibration parameter as printed and written: rows of the paper's tables.
struct ParamInfo {
  std::string name;        // p_x, rot_y, f2_z, fu ...
  std::string unit;        // cm, deg, px (display units)
  double scale;            // SI -> display
  CalibrationGroup group;  // what it belongs to (plots draw each group together)
};

// The calibration block of the error state, [p_b_c, phi, markers, t_d, intrinsics], in order
// (calibration_layout(markers, intrinsics)). With 8 intrinsics the last four are the lens's
// coefficients, named after its model (k1 k2 p1 p2, or k1..k4), shown in thousandths (unit "1e-3";
// SI: unitless).
std::vector<ParamInfo> calibration_params(int markers, int intrinsics,
                                          Distortion lens = Distortion::kNone);
// The names of a lens's four distortion coefficients (Pinhole::coeffs order).
std::array<const char*, 4> distortion_coeff_names(Distortion lens);

template <class Filter>
struct HistoryRow {
  using State = typename Filter::State;
  static constexpr int kCalib = State::kCalibrationDim;
  std::int64_t t_ns = 0;
  State state{};
  State predicted{};  // the estimate before this frame's update (CalibrationFilter::predicted)
  Eigen::Matrix<double, kCalib, 1> sigma = Eigen::Matrix<double, kCalib, 1>::Zero();
  Eigen::Matrix<double, kCalib, 1> error = Eigen::Matrix<double, kCalib, 1>::Zero();  // if truth
  double nees = 0.0;                                                                  // if truth
  // The frame this estimate followed, against the estimate after its update (a posteriori
  // residuals, measured minus predicted, px), for the markers the frame held and the estimate
  // predicts; none in the final row. Needs the sink's FrameTap.
  std::array<bool, State::kMarkers> residual_valid{};
  std::array<Eigen::Vector2d, State::kMarkers> residual{};
  // The frame's markers as the loop took them (detected and labelled, from images), px.
  std::array<bool, State::kMarkers> seen{};
  std::array<Eigen::Vector2d, State::kMarkers> measured{};
  // Of those, the ones the loop withheld from the update (loop::MarkerScreen).
  std::array<bool, State::kMarkers> withheld{};
  int markers_seen = 0;
  // This update's markers rejected by the gate, and their normalised innovation squared with its
  // degrees of freedom (2 per marker used; 0 until the gate is on: see CalibrationConfig).
  int markers_gated = 0;
  double nis = 0.0;
  int nis_dof = 0;
};

// The calibration block's error of an estimate against the truth (boxminus: the rotation error
// is log(R_true^T R_est)) and its NEES under the estimate's covariance.
template <class Filter>
void calibration_error(const Filter& f, const typename Filter::State& truth,
                       HistoryRow<Filter>& row) {
  using State = typename Filter::State;
  constexpr int B = State::kCalibrationBegin, L = State::kCalibrationDim;
  const auto e = f.state().template boxminus_block<B, L>(truth);
  row.error = e.template cast<double>();
  const Eigen::Matrix<double, L, L> p =
      f.covariance().template block<L, L>(B, B).template cast<double>();
  row.nees = row.error.dot(p.ldlt().solve(row.error));
}

// A frame's markers to be dropped (FrameTap::veto): those the refinement found to be outliers at
// its converged solution (run.cpp, find_outliers).
template <int M>
struct VetoedFrame {
  std::int64_t t_ns = 0;
  std::array<bool, M> markers{};
};
template <int M>
using OutlierVeto = std::vector<VetoedFrame<M>>;

// Passes a marker source's frames to the loop and keeps the last one as the loop updates with it
// (after relabelling, when the loop identifies markers), so that the estimate published after the
// update can be compared with it. Keeps one frame: no allocation.
template <int M>
class FrameTap final : public hal::MarkerSource<M>, public hal::MarkerRelabeler<M> {
 public:
  FrameTap(hal::MarkerSource<M>& source, hal::MarkerRelabeler<M>* relabeler)
      : source_(source), relabeler_(relabeler) {}
  hal::SourceStatus poll(MarkerFrame<M>& frame) override {
    const hal::SourceStatus st = source_.poll(frame);
    if (st == hal::SourceStatus::kOk) {
      if (relabeler_ == nullptr) drop_vetoed(frame);  // labelled as they come
      last_ = frame;
      fresh_ = true;
    }
    return st;
  }
  void relabel(const hal::MarkerPrediction<M>& prediction, MarkerFrame<M>& frame) override {
    if (relabeler_ != nullptr) {
      relabeler_->relabel(prediction, frame);
      drop_vetoed(frame);
    }
    last_ = frame;
  }
  // Markers of given frames to drop as they come (the refinement's outliers at its converged
  // solution, OutlierVeto), sorted by time; how many of marker i it dropped.
  void veto(const OutlierVeto<M>* v) { veto_ = v; }
  std::uint64_t vetoed(int i) const { return vetoed_[static_cast<std::size_t>(i)]; }
  const char* error() const override { return source_.error(); }
  std::int64_t detection_ns() const override { return source_.detection_ns(); }
  // The loop's screen, which withholds some of a frame's markers after the tap saw them.
  void watch(const loop::MarkerScreen<M>* screen) { screen_ = screen; }
  // The frame stamped t_ns the loop took last, once; nullptr if it was taken already or the
  // estimate published at t_ns followed no frame (the final one). withheld: its markers the
  // screen withheld.
  const MarkerFrame<M>* take(std::int64_t t_ns, std::array<bool, M>& withheld) {
    if (!fresh_ || last_.t_ns != t_ns) return nullptr;
    fresh_ = false;
    withheld = screen_ != nullptr ? screen_->withheld_from(t_ns) : std::array<bool, M>{};
    return &last_;
  }

 private:
  hal::MarkerSource<M>& source_;
  hal::MarkerRelabeler<M>* relabeler_;
  void drop_vetoed(MarkerFrame<M>& frame) {
    if (veto_ == nullptr) return;
    while (next_veto_ < veto_->size() && (*veto_)[next_veto_].t_ns < frame.t_ns) ++next_veto_;
    if (next_veto_ == veto_->size() || (*veto_)[next_veto_].t_ns != frame.t_ns) return;
    for (std::size_t i = 0; i < std::size_t(M); ++i)
      if (frame.seen[i] && (*veto_)[next_veto_].markers[i]) {
        frame.seen[i] = false;
        ++vetoed_[i];
      }
  }
  MarkerFrame<M> last_{};
  bool fresh_ = false;
  const loop::MarkerScreen<M>* screen_ = nullptr;
  const OutlierVeto<M>* veto_ = nullptr;
  std::size_t next_veto_ = 0;
  std::array<std::uint64_t, M> vetoed_{};
};

// The frame's markers against the filter's estimate after its update: the filter's own measurement
// model at the frame's exposure.
template <class Filter>
void record_residuals(const Filter& f, const MarkerFrame<Filter::State::kMarkers>& frame,
                      HistoryRow<Filter>& row) {
  using S = typename Filter::State::Scalar;
  constexpr int M = Filter::State::kMarkers;
  const Pinhole<S> fixed = f.config().intrinsics.template cast<S>();
  std::array<bool, M> ok = frame.seen;
  Eigen::Matrix<S, 2 * M, 1> z = Eigen::Matrix<S, 2 * M, 1>::Zero();
  predict_markers(f.state(), fixed, f.exposure(frame.t_ns), marker_readout_s(fixed, frame), z, ok);
  for (int i = 0; i < M; ++i) {
    const auto k = static_cast<std::size_t>(i);
    row.markers_seen += frame.seen[k] ? 1 : 0;
    row.seen[k] = frame.seen[k];
    if (frame.seen[k]) row.measured[k] = frame.uv[k];
    row.residual_valid[k] = frame.seen[k] && ok[k];
    if (row.residual_valid[k])
      row.residual[k] = frame.uv[k] - z.template segment<2>(2 * i).template cast<double>();
  }
}

// What the filter kept for a smoother at one published estimate (CalibrationFilter::MotionStep,
// and the motion block's covariance after the update).
template <class Filter>
struct MotionRow {
  typename Filter::MotionStep step;
  Eigen::Matrix<double, Filter::kMotionDim, Filter::kMotionDim> covariance;
};

template <class Filter>
class HistorySink final : public loop::EstimateSink<Filter> {
 public:
  // At most capacity rows; with tap (the loop's marker source, wrapped), each row has its frame's
  // residuals. The rows go to a file created now: publishing allocates nothing, and throws
  // io::StoreError if the file cannot be written (a full disk).
  HistorySink(std::size_t capacity, const typename Filter::State* truth,
              FrameTap<Filter::State::kMarkers>* tap = nullptr)
      : truth_(truth), tap_(tap), capacity_(capacity) {}
  void publish(std::int64_t t_ns, const Filter& f) override {
    if (rows_.size() == capacity_) return;
    row_ = HistoryRow<Filter>{};
    HistoryRow<Filter>& r = row_;
    r.t_ns = t_ns;
    r.state = f.state();
    r.predicted = f.predicted();
    constexpr int B = Filter::State::kCalibrationBegin, L = Filter::State::kCalibrationDim;
    r.sigma = f.covariance().diagonal().template segment<L>(B).template cast<double>().cwiseSqrt();
    if (truth_ != nullptr) calibration_error(f, *truth_, r);
    // This update's share of the filter's running counts.
    const FilterCounters& c = f.counters();
    r.nis = c.nis_sum - counted_.nis_sum;
    r.nis_dof = static_cast<int>(c.nis_dof - counted_.nis_dof);
    r.markers_gated = static_cast<int>(c.markers_gated - counted_.markers_gated);
    counted_ = c;
    if (tap_ != nullptr)
      if (const auto* frame = tap_->take(t_ns, r.withheld)) record_residuals(f, *frame, r);
    rows_.push_back(r);
    if (motion_) {
      motion_row_.step = f.motion_step();
      motion_row_.covariance =
          f.covariance().template topLeftCorner<Filter::kMotionDim, Filter::kMotionDim>();
      motion_->push_back(motion_row_);
    }
  }
  const RecordStore<HistoryRow<Filter>>& rows() const { return rows_; }
  RecordStore<HistoryRow<Filter>> take_rows() { return std::move(rows_); }
  // A MotionRow beside each row, for a smoother (the filter keeping its motion steps).
  void keep_motion() {
    if (!motion_) motion_.emplace("the tracking pass's motion");
  }
  std::optional<RecordStore<MotionRow<Filter>>> take_motion() { return std::move(motion_); }

 private:
  const typename Filter::State* truth_;
  FrameTap<Filter::State::kMarkers>* tap_;
  std::size_t capacity_;
  FilterCounters counted_{};
  RecordStore<HistoryRow<Filter>> rows_;
  std::optional<RecordStore<MotionRow<Filter>>> motion_;
  // The rows being filled (off the stack: a MotionRow is 5 KB).
  HistoryRow<Filter> row_{};
  MotionRow<Filter> motion_row_{};
};

}  // namespace mirrorcal::calibration
