// Runs one operation a given number of times, for instruction counts under callgrind, which do
// not depend on the machine's load: the count of N operations less that of none is N times the
// cost of one.
//   mirrorcal_opcount predict|update|restore <M> <float|double> <N>
//                                            (restore: the filter reset that precedes each
//                                            operation, alone, to subtract)
//   mirrorcal_opcount recording <N>          N runs of the whole loop over the 60 s recording
//   mirrorcal_opcount sizes                  sizeof the filter of every configuration built
#include <cstdio>
#include <cstdlib>
#include <string>

#include "filter_ops.hpp"
#include "recording.hpp"

namespace mb = mirrorcal::bench;

namespace {

int usage() {
  std::fputs(
      "usage: mirrorcal_opcount predict|update|restore <M> <float|double> <N>\n"
      "       mirrorcal_opcount recording <N>\n"
      "       mirrorcal_opcount sizes\n",
      stderr);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string what = argc > 1 ? argv[1] : "";
  if (what == "sizes" && argc == 2) {
    for (const bool single : {false, true})
      for (const int m : mb::built_marker_counts()) {
        const auto ops = mb::make_filter_ops(m, single);
        std::printf("%s %d %d %zu\n", single ? "float" : "double", m, ops->dim(),
                    ops->filter_bytes());
      }
    return 0;
  }
  if (what == "recording" && argc == 3) {
    const long n = std::atol(argv[2]);
    const mb::Recording rec = mb::paper_recording();
    std::uint64_t used = 0;
    for (long i = 0; i < n; ++i) used += mb::calibrate(rec);
    std::printf("markers used %llu\n", static_cast<unsigned long long>(used));
    return 0;
  }
  if ((what == "predict" || what == "update" || what == "restore") && argc == 5) {
    const std::string type = argv[3];
    if (type != "float" && type != "double") return usage();
    const auto ops = mb::make_filter_ops(std::atoi(argv[2]), type == "float");
    if (!ops) {
      std::fprintf(stderr, "mirrorcal_opcount: M = %s is not built\n", argv[2]);
      return 2;
    }
    const long n = std::atol(argv[4]);
    long failed = 0;
    for (long i = 0; i < n; ++i) {
      ops->restore();
      if (what == "update") failed += ops->update() ? 0 : 1;
      if (what == "predict") failed += ops->predict() ? 0 : 1;
    }
    return failed == 0 ? 0 : 1;
  }
  return usage();
}
