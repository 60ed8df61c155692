#include "filter_ops_impl.hpp"

namespace mirrorcal::bench {

std::unique_ptr<FilterOps> make_filter_ops_m6(bool single_precision) {
  if (single_precision) return std::make_unique<FilterOpsOf<float, 6>>();
  return std::make_unique<FilterOpsOf<double, 6>>();
}

std::unique_ptr<FilterOps> make_textbook_ops_m6() {
  return std::make_unique<FilterOpsOf<double, 6, 0, true>>();
}

}  // namespace mirrorcal::bench
