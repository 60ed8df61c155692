// Stage 2's filters (M = 3, double) through a radtan lens: its coefficients known (NK = 4) or
// estimated (NK = 8). Both are compiled once in the estimator library (extern templates).
#include "filter_ops_impl.hpp"

namespace mirrorcal::bench {

std::unique_ptr<FilterOps> make_stage2_filter_ops(int intrinsics) {
  if (intrinsics == 4) return std::make_unique<FilterOpsOf<double, 3, 4>>();
  if (intrinsics == 8) return std::make_unique<FilterOpsOf<double, 3, 8>>();
  return nullptr;
}

}  // namespace mirrorcal::bench
