#include "filter_ops_impl.hpp"

namespace mirrorcal::bench {

std::unique_ptr<FilterOps> make_filter_ops_m12(bool single_precision) {
  if (single_precision) return std::make_unique<FilterOpsOf<float, 12>>();
  return std::make_unique<FilterOpsOf<double, 12>>();
}

std::unique_ptr<FilterOps> make_textbook_ops_m12() {
  return std::make_unique<FilterOpsOf<double, 12, 0, true>>();
}

}  // namespace mirrorcal::bench
