#include "filter_ops.hpp"

namespace mirrorcal::bench {

std::unique_ptr<FilterOps> make_filter_ops_m3(bool single_precision);
std::unique_ptr<FilterOps> make_filter_ops_m6(bool single_precision);
std::unique_ptr<FilterOps> make_textbook_ops_m3();
std::unique_ptr<FilterOps> make_textbook_ops_m6();
#ifdef MIRRORCAL_BENCH_LARGE_M
std::unique_ptr<FilterOps> make_filter_ops_m12(bool single_precision);
std::unique_ptr<FilterOps> make_filter_ops_m24(bool single_precision);
std::unique_ptr<FilterOps> make_textbook_ops_m12();
std::unique_ptr<FilterOps> make_textbook_ops_m24();
#endif

std::unique_ptr<FilterOps> make_filter_ops(int markers, bool single_precision) {
  switch (markers) {
    case 3:
      return make_filter_ops_m3(single_precision);
    case 6:
      return make_filter_ops_m6(single_precision);
#ifdef MIRRORCAL_BENCH_LARGE_M
    case 12:
      return make_filter_ops_m12(single_precision);
    case 24:
      return make_filter_ops_m24(single_precision);
#endif
    default:
      return nullptr;
  }
}

std::unique_ptr<FilterOps> make_textbook_ops(int markers) {
  if (markers == 3) return make_textbook_ops_m3();
  if (markers == 6) return make_textbook_ops_m6();
#ifdef MIRRORCAL_BENCH_LARGE_M
  if (markers == 12) return make_textbook_ops_m12();
  if (markers == 24) return make_textbook_ops_m24();
#endif
  return nullptr;
}

std::vector<int> built_marker_counts() {
#ifdef MIRRORCAL_BENCH_LARGE_M
  return {3, 6, 12, 24};
#else
  return {3, 6};
#endif
}

}  // namespace mirrorcal::bench
