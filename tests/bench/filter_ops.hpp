// Single filter operations of one configuration (M markers, float or double), prepared so that a
// benchmark or an instruction count can run them one at a time: a filter near convergence in
// front of the mirror, the IMU samples of one step and a frame seeing every marker.
//
// One translation unit per marker count (filter_ops_m*.cpp): each configuration is a heavy Eigen
// instantiation, so they build in parallel and the large ones only when asked for
// (-DMIRRORCAL_BENCH_LARGE_M=ON).
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

namespace mirrorcal::bench {

class FilterOps {
 public:
  virtual ~FilterOps() = default;
  virtual int markers() const = 0;
  virtual int dim() const = 0;                      // error-state dimension
  virtual std::size_t filter_bytes() const = 0;     // sizeof the filter object
  virtual std::size_t workspace_bytes() const = 0;  // its thread-local workspaces
  virtual void restore() = 0;                       // back to the prepared filter
  virtual bool predict() = 0;                       // one IMU step (5 ms); true if it succeeded
  virtual bool update() = 0;                        // one frame, every marker seen
  // Reads the covariance, which first applies the predicts' deferred cross-covariance (what an
  // update or any reader does once per frame); returns an entry of it.
  virtual double settle() = 0;
  // The estimate as an offset from the prepared one (error state), then the covariance, column by
  // column: for comparing two filters' results on the same inputs.
  virtual std::vector<double> estimate() = 0;
};

// The configuration, or nullptr if it is not built.
std::unique_ptr<FilterOps> make_filter_ops(int markers, bool single_precision);
// The textbook full-state UKF of the same model on the same inputs (textbook_ukf.hpp), double,
// or nullptr if that marker count is not built.
std::unique_ptr<FilterOps> make_textbook_ops(int markers);

// Stage 2 at M = 3, double, through a radtan lens: intrinsics 4 (fu fv cu cv, the lens known) or
// 8 (and the lens's four coefficients), or nullptr.
std::unique_ptr<FilterOps> make_stage2_filter_ops(int intrinsics);

// Stage 1 at M = 3, double, with the IMU's intrinsics: 12 (scale-misalignment), or nullptr if
// that model is not built.
std::unique_ptr<FilterOps> make_imu_filter_ops(int imu_intrinsics);

// The marker counts built into this program, ascending.
std::vector<int> built_marker_counts();

}  // namespace mirrorcal::bench
