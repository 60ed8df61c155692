// Where the filter expects each marker's reflection: the estimator's own measurement model
// (predict_markers) at the current mean, and its covariance from the state's uncertainty, sampled
// at +-1 sigma along the Cholesky columns of the block the camera reads (central differences, so
// it is the linearised covariance J P J^T without writing J). The loop hands it to marker
// identification (CalibrationLoop::set_identifier), which gates on it.
// Fixed-size throughout: no allocation.
#pragma once

#include "mirrorcal/estimator/calibration_filter.hpp"
#include "mirrorcal/hal/frames.hpp"

namespace mirrorcal::loop {

// The Cholesky factor of the measured block's covariance, in the thread's workspace.
template <typename S, int L>
struct PredictionFactor {
  Eigen::Matrix<S, L, L> chol;
};

// For a frame of unlabelled spots (frame.seen and frame.uv as detected): every marker at the time
// the loop took the frame at, the mean row of its spots under a rolling shutter. False if the
// covariance of the measured block cannot be factored (then no prediction).
template <class Filter>
bool predict_marker_pixels(const Filter& filter, const MarkerFrame<Filter::State::kMarkers>& frame,
                           hal::MarkerPrediction<Filter::State::kMarkers>& out) {
  using State = typename Filter::State;
  using S = typename State::Scalar;
  constexpr int M = State::kMarkers;
  constexpr int B = State::kMeasuredBegin, L = State::kMeasuredDim;
  using Pixels = Eigen::Matrix<S, 2 * M, 1>;

  const Pinhole<S> fixed = filter.config().intrinsics.template cast<S>();
  const State& mean = filter.state();
  const Exposure<S> exposed = filter.exposure(frame.t_ns);
  std::array<S, M> readout;
  readout.fill(fixed.line_delay_s * S(readout_anchor_row(frame)));
  std::array<bool, M> ok;
  ok.fill(true);
  Pixels z0 = Pixels::Zero();
  predict_markers(mean, fixed, exposed, readout, z0, ok);

  // The factor in the thread's workspace, by the update's own kernel: on the stack, the block, an
  // Eigen LLT of it and its factor took 88 KB at 6 markers with the lens estimated (L = 39).
  auto& chol = thread_workspace<PredictionFactor<S, L>>().chol;
  chol = filter.covariance().template block<L, L>(B, B);
  if (!cholesky_in_place(chol)) return false;

  std::array<Eigen::Matrix<S, 2, 2>, M> cov;
  for (auto& c : cov) c.setZero();
  for (int j = 0; j < L; ++j) {
    State plus = mean, minus = mean;
    const Eigen::Matrix<S, L, 1> d = chol.col(j);
    plus.template boxplus_block<B, L>(d);
    minus.template boxplus_block<B, L>(Eigen::Matrix<S, L, 1>(-d));
    Pixels zp = Pixels::Zero(), zm = Pixels::Zero();
    predict_markers(plus, fixed, exposed, readout, zp, ok);
    predict_markers(minus, fixed, exposed, readout, zm, ok);
    for (int i = 0; i < M; ++i) {
      const Eigen::Matrix<S, 2, 1> a =
          S(0.5) * (zp.template segment<2>(2 * i) - zm.template segment<2>(2 * i));
      cov[static_cast<std::size_t>(i)] += a * a.transpose();
    }
  }
  for (int i = 0; i < M; ++i) {
    const auto ii = static_cast<std::size_t>(i);
    out.valid[ii] = ok[ii];
    out.uv[ii] = z0.template segment<2>(2 * i).template cast<double>();
    out.covariance[ii] = cov[ii].template cast<double>();
  }
  return true;
}

}  // namespace mirrorcal::loop
