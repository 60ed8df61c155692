// The estimate over time, as the loop publishes it: a sink that keeps every published estimate in
// storage reserved before the loop starts, and the calibration parameters' names and units.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "mirrorcal/firmware/loop.hpp"

namespace mirrorcal::app {

// A calibration parameter as printed and written: rows of the paper's tables.
struct ParamInfo {
  std::string name;  // p_x, rot_y, f2_z, fu ...
  std::string unit;  // cm, deg, px (display units)
  double scale;      // SI -> display
};

// The calibration block of the error state, [p_b_c, phi, markers, t_d, intrinsics], in order.
std::vector<ParamInfo> calibration_params(int markers, int intrinsics);

template <class Filter>
struct HistoryRow {
  using State = typename Filter::State;
  static constexpr int kCalib = State::kDim - State::kPbc;
  std::int64_t t_ns = 0;
  State state{};
  State predicted{};  // the estimate before this frame's update (CalibrationFilter::predicted)
  Eigen::Matrix<double, kCalib, 1> sigma = Eigen::Matrix<double, kCalib, 1>::Zero();
  Eigen::Matrix<double, kCalib, 1> error = Eigen::Matrix<double, kCalib, 1>::Zero();  // if truth
  double nees = 0.0;                                                                  // if truth
};

// The calibration block's error of an estimate against the truth (boxminus: the rotation error
// is log(R_true^T R_est)) and its NEES under the estimate's covariance.
template <class Filter>
void calibration_error(const Filter& f, const typename Filter::State& truth,
                       HistoryRow<Filter>& row) {
  using State = typename Filter::State;
  constexpr int B = State::kPbc, L = State::kDim - State::kPbc;
  const auto e = f.state().template boxminus_block<B, L>(truth);
  row.error = e.template cast<double>();
  const Eigen::Matrix<double, L, L> p =
      f.covariance().template block<L, L>(B, B).template cast<double>();
  row.nees = row.error.dot(p.ldlt().solve(row.error));
}

template <class Filter>
class HistorySink final : public firmware::EstimateSink<Filter> {
 public:
  HistorySink(std::size_t capacity, const typename Filter::State* truth) : truth_(truth) {
    rows_.reserve(capacity);
  }
  void publish(std::int64_t t_ns, const Filter& f) override {
    if (rows_.size() == rows_.capacity()) return;  // never grow inside the loop
    HistoryRow<Filter>& r = rows_.emplace_back();
    r.t_ns = t_ns;
    r.state = f.state();
    r.predicted = f.predicted();
    constexpr int B = Filter::State::kPbc, L = Filter::State::kDim - B;
    r.sigma = f.covariance().diagonal().template segment<L>(B).template cast<double>().cwiseSqrt();
    if (truth_ != nullptr) calibration_error(f, *truth_, r);
  }
  const std::vector<HistoryRow<Filter>>& rows() const { return rows_; }

 private:
  const typename Filter::State* truth_;
  std::vector<HistoryRow<Filter>> rows_;
};

}  // namespace mirrorcal::app
