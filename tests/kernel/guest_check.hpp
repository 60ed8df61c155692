// Checks for the guest programs of the kernel-in-the-loop tests. They run as the only program of a
// minimal Linux (no GoogleTest for arm64 there), print what they check and exit non-zero when any
// check failed; toolchain/kernel/run-in-qemu turns that into the CTest result.
#pragma once

#include <cerrno>
#include <cstdio>
#include <cstring>

namespace mirrorcal::guest {

inline int& failures() {
  static int n = 0;
  return n;
}

inline bool check(bool ok, const char* what, const char* file, int line) {
  if (!ok) {
    ++failures();
    std::printf("FAILED %s:%d: %s (errno: %s)\n", file, line, what, std::strerror(errno));
  }
  return ok;
}

inline int finish(const char* name) {
  std::printf("%s: %s (%d failed checks)\n", name, failures() == 0 ? "passed" : "FAILED",
              failures());
  std::fflush(stdout);
  return failures() == 0 ? 0 : 1;
}

}  // namespace mirrorcal::guest

#define GUEST_CHECK(cond) ::mirrorcal::guest::check((cond), #cond, __FILE__, __LINE__)
