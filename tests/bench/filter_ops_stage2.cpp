// Stage 2's filters (M = 3, double) through a radtan lens: its coefficients known (NK = 4) or
// estimated (NK = 8), and stage 1 with the IMU's intrinsics. All are compiled once in the
// estimator library (extern templates).
#include "filter_ops_impl.hpp"

namespace mirrorcal::bench {

std::unique_ptr<FilterOps> make_stage2_filter_ops(int intrinsics) {
  if (intrinsics == 4) return std::make_unique<FilterOpsOf<double, 3, 4>>();
  if (intrinsics == 8) return std::make_unique<FilterOpsOf<double, 3, 8>>();
  return nullptr;
}

namespace {

// A template, so that a model the build lacks is not instantiated here.
template <int NI>
std::unique_ptr<FilterOps> imu_filter_ops() {
  if constexpr (imu_model_built(NI))
    return std::make_unique<FilterOpsOf<double, 3, 0, false, NI>>();
  return nullptr;
}

}  // namespace

std::unique_ptr<FilterOps> make_imu_filter_ops(int imu_intrinsics) {
  return imu_intrinsics == 12 ? imu_filter_ops<12>() : nullptr;
}

}  // namespace mirrorcal::bench
