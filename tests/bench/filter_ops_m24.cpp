#include "filter_ops_impl.hpp"

namespace mirrorcal::bench {

std::unique_ptr<FilterOps> make_filter_ops_m24(bool single_precision) {
  if (single_precision) return std::make_unique<FilterOpsOf<float, 24>>();
  return std::make_unique<FilterOpsOf<double, 24>>();
}

std::unique_ptr<FilterOps> make_textbook_ops_m24() {
  return std::make_unique<FilterOpsOf<double, 24, 0, true>>();
}

}  // namespace mirrorcal::bench
