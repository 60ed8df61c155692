// Runs one operation a given number of times, for instruction counts under callgrind, which do
// not depend on the machine's load: the count of N operations less that of none is N times the
// cost of one.
//   mirrorcal_opcount predict|predict2|predict10|update|restore <M> <float|double> <N>
//                                            (restore: the filter reset that precedes each
//                                            operation, alone, to subtract; predict2: two
//                                            predicts, the second following a predict as most
//                                            do in the loop: predict2 less predict; predict10:
//                                            a frame's ten predicts at 200 Hz and 20 Hz and the
//                                            covariance read after them, which applies their
//                                            deferred cross-covariance)
//   mirrorcal_opcount textbook-predict|textbook-update|textbook-restore <M> <N>
//                                            the same operations of the textbook full-state UKF
//                                            (textbook_ukf.hpp), double, on the same inputs
//   mirrorcal_opcount stage2-update|stage2-restore <NK> <N>
//                                            stage 2 (M = 3, double, radtan lens) with NK = 4
//                                            (lens known) or 8 (its coefficients estimated)
//   mirrorcal_opcount imu-predict|imu-predict2|imu-predict10|imu-update|imu-restore <NI> <N>
//                                            stage 1 (M = 3, double) with the IMU's NI = 12
//                                            intrinsics (scale-misalignment); imu-predict10 as
//                                            predict10 (its settling read applies the IMU
//                                            block's deferred covariance and checks it)
//   mirrorcal_opcount recording <N>          N runs of the whole loop over the 60 s recording
//   mirrorcal_opcount shipped <N>            N calibrations of it as mirrorcal runs them
//                                            (its free passes, the Gauss-Newton refinement and
//                                            the ideal-IMU check)
//   mirrorcal_opcount shipped-imu <N>        the same with the IMU's intrinsics estimated
//                                            (scale-misalignment)
//   mirrorcal_opcount sizes                  sizeof the filter of every configuration built,
//                                            and of its thread-local workspaces
//   mirrorcal_opcount stack                  peak stack depth of predict and update, measured, of
//                                            every configuration built
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "filter_ops.hpp"
#include "recording.hpp"

namespace mb = mirrorcal::bench;

namespace {

int usage() {
  std::fputs(
      "usage: mirrorcal_opcount predict|predict2|predict10|update|restore <M> <float|double> "
      "<N>\n"
      "       mirrorcal_opcount textbook-predict|textbook-update|textbook-restore <M> <N>\n"
      "       mirrorcal_opcount stage2-update|stage2-restore <4|8> <N>\n"
      "       mirrorcal_opcount imu-predict|imu-predict2|imu-predict10|imu-update|imu-restore <12> "
      "<N>\n"
      "       mirrorcal_opcount recording|shipped|shipped-imu <N>\n"
      "       mirrorcal_opcount sizes|stack\n",
      stderr);
  return 2;
}

// Peak stack depth of a call, measured: the stack below the caller's frame is painted, the call
// runs from that same frame, and the deepest byte it changed shows how far it went (to within
// the few bytes of a frame that it happens not to write). Both helpers are called from the
// same frame, so their regions lie where the measured call's frames will.
constexpr std::size_t kProbeBytes = 4 * 1024 * 1024;  // of the usual 8 MiB main thread stack
constexpr unsigned char kPaint = 0xA5;

[[gnu::noinline]] std::uintptr_t paint_stack() {
  unsigned char region[kProbeBytes];
  std::memset(region, kPaint, sizeof region);
  // The painting must happen; the address leaves as a number (the region is dead by then).
  std::uintptr_t address = reinterpret_cast<std::uintptr_t>(region);
  asm volatile("" : "+r"(address) : : "memory");
  return address;
}

[[gnu::noinline]] std::size_t stack_used_since(std::uintptr_t painted) {
  const volatile unsigned char* p = reinterpret_cast<const volatile unsigned char*>(painted);
  std::size_t untouched = 0;
  while (untouched < kProbeBytes && p[untouched] == kPaint) ++untouched;
  return kProbeBytes - untouched;
}

template <class Op>
std::size_t peak_stack(Op op) {
  op();  // once first: lazy symbol binding and first-touch paths are not the operation's
  const std::uintptr_t painted = paint_stack();
  op();
  return stack_used_since(painted);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string what = argc > 1 ? argv[1] : "";
  if (what == "sizes" && argc == 2) {
    for (const bool single : {false, true})
      for (const int m : mb::built_marker_counts()) {
        const auto ops = mb::make_filter_ops(m, single);
        std::printf("%s %d %d %zu %zu\n", single ? "float" : "double", m, ops->dim(),
                    ops->filter_bytes(), ops->workspace_bytes());
      }
    return 0;
  }
  if (what == "stack" && argc == 2) {
    for (const bool single : {false, true})
      for (const int m : mb::built_marker_counts()) {
        const auto ops = mb::make_filter_ops(m, single);
        const std::size_t predict = peak_stack([&] {
          ops->restore();
          ops->predict();
        });
        const std::size_t update = peak_stack([&] {
          ops->restore();
          ops->update();
        });
        std::printf("%s %d %zu %zu\n", single ? "float" : "double", m, predict, update);
      }
    return 0;
  }
  if ((what == "recording" || what == "shipped" || what == "shipped-imu") && argc == 3) {
    const long n = std::atol(argv[2]);
    const mb::Recording rec = mb::paper_recording();
    std::printf("imu samples %zu, frames %zu, %.0f s\n", rec.data.imu.size(),
                rec.data.frames.size(), rec.scenario.duration_s);
    std::uint64_t used = 0;
    for (long i = 0; i < n; ++i) {
      if (what == "shipped") used += mb::calibrate_as_shipped(rec);
      if (what == "shipped-imu") used += mb::calibrate_as_shipped_with_imu_intrinsics(rec);
      if (what == "recording") used += mb::calibrate(rec);
    }
    std::printf("markers used %llu\n", static_cast<unsigned long long>(used));
    return 0;
  }
  if ((what == "predict" || what == "predict2" || what == "predict10" || what == "update" ||
       what == "restore") &&
      argc == 5) {
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
      if (what == "predict" || what == "predict2") failed += ops->predict() ? 0 : 1;
      if (what == "predict2") failed += ops->predict() ? 0 : 1;
      if (what == "predict10") {
        for (int k = 0; k < 10; ++k) failed += ops->predict() ? 0 : 1;
        failed += ops->settle() > -1e300 ? 0 : 1;  // uses the value: the read is not elided
      }
    }
    return failed == 0 ? 0 : 1;
  }
  if ((what == "textbook-predict" || what == "textbook-update" || what == "textbook-restore") &&
      argc == 4) {
    const auto ops = mb::make_textbook_ops(std::atoi(argv[2]));
    if (!ops) return usage();
    const long n = std::atol(argv[3]);
    long failed = 0;
    for (long i = 0; i < n; ++i) {
      ops->restore();
      if (what == "textbook-predict") failed += ops->predict() ? 0 : 1;
      if (what == "textbook-update") failed += ops->update() ? 0 : 1;
    }
    return failed == 0 ? 0 : 1;
  }
  if ((what == "imu-predict" || what == "imu-predict2" || what == "imu-predict10" ||
       what == "imu-update" || what == "imu-restore") &&
      argc == 4) {
    const auto ops = mb::make_imu_filter_ops(std::atoi(argv[2]));
    if (!ops) {
      std::fprintf(stderr, "mirrorcal_opcount: NI = %s is not built\n", argv[2]);
      return 2;
    }
    const long n = std::atol(argv[3]);
    long failed = 0;
    for (long i = 0; i < n; ++i) {
      ops->restore();
      if (what == "imu-update") failed += ops->update() ? 0 : 1;
      if (what == "imu-predict" || what == "imu-predict2") failed += ops->predict() ? 0 : 1;
      if (what == "imu-predict2") failed += ops->predict() ? 0 : 1;
      if (what == "imu-predict10") {
        for (int k = 0; k < 10; ++k) failed += ops->predict() ? 0 : 1;
        failed += ops->settle() > -1e300 ? 0 : 1;
      }
    }
    return failed == 0 ? 0 : 1;
  }
  if ((what == "stage2-update" || what == "stage2-restore") && argc == 4) {
    const auto ops = mb::make_stage2_filter_ops(std::atoi(argv[2]));
    if (!ops) return usage();
    const long n = std::atol(argv[3]);
    long failed = 0;
    for (long i = 0; i < n; ++i) {
      ops->restore();
      if (what == "stage2-update") failed += ops->update() ? 0 : 1;
    }
    return failed == 0 ? 0 : 1;
  }
  return usage();
}
