// The writer the board's loop will record through allocates nothing per sample or frame once
// open: it counts every malloc family call (forwarding to glibc's __libc_* entry points, which
// operator new also reaches; under AddressSanitizer, which owns malloc, through its allocation
// hook). A reduced form of tests/estimator/no_heap_test.cpp's harness, for C allocation only.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstddef>

#include "test_support.hpp"

#if defined(__SANITIZE_ADDRESS__)
#define MIRRORCAL_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define MIRRORCAL_ASAN 1
#endif
#endif

namespace {
std::atomic<bool> g_armed{false};
std::atomic<long> g_allocations{0};
inline void count() {
  if (g_armed.load(std::memory_order_relaxed)) g_allocations.fetch_add(1);
}
}  // namespace

#ifdef MIRRORCAL_ASAN
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*)(const volatile void*,
                                                                  std::size_t),
                                                         void (*)(const volatile void*));
namespace {
void on_malloc(const volatile void*, std::size_t) {
  count();
}
void on_free(const volatile void*) {}
const int g_hooks = __sanitizer_install_malloc_and_free_hooks(on_malloc, on_free);
}  // namespace
#else
extern "C" {
void* __libc_malloc(std::size_t) noexcept;
void* __libc_calloc(std::size_t, std::size_t) noexcept;
void* __libc_realloc(void*, std::size_t) noexcept;
void* __libc_memalign(std::size_t, std::size_t) noexcept;
void __libc_free(void*) noexcept;
void* malloc(std::size_t n) noexcept {
  count();
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  count();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) noexcept {
  count();
  return __libc_realloc(p, n);
}
void* memalign(std::size_t al, std::size_t n) noexcept {
  count();
  return __libc_memalign(al, n);
}
void* aligned_alloc(std::size_t al, std::size_t n) noexcept {
  count();
  return __libc_memalign(al, n);
}
int posix_memalign(void** out, std::size_t al, std::size_t n) noexcept {
  count();
  void* p = __libc_memalign(al, n);
  if (p == nullptr) return 12;  // ENOMEM
  *out = p;
  return 0;
}
void free(void* p) noexcept {
  __libc_free(p);
}
}  // extern "C"
#endif

using namespace rectest;

TEST(RecordingWriter, TheCounterSeesAllocations) {
  g_allocations = 0;
  g_armed = true;
  auto* v = new std::vector<double>(1000);  // operator new reaches malloc
  g_armed = false;
  delete v;
  EXPECT_GE(g_allocations.load(), 2);
}

TEST(RecordingWriter, AddsSamplesFramesAndImagesWithoutTheHeap) {
  const TempDir tmp("writer-no-heap");
  std::string err;
  mc::sim::RecordingWriter w;
  ASSERT_TRUE(w.open(tmp.path, err)) << err;
  const std::uint8_t pixels[4 * 3] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  const mc::sim::GrayImage image{4, 3, pixels};
  mc::MarkerFrame<3> frame;
  frame.seen = {true, true, false};
  frame.uv.fill(Eigen::Vector2d::Zero());
  // The first image creates cam0/data/ (it may allocate, once): before arming.
  frame.t_ns = 1;
  ASSERT_TRUE(w.add_frame(frame, &image));

  g_allocations = 0;
  g_armed = true;
  bool ok = true;
  for (int k = 0; k < 2000; ++k) {  // enough rows to flush the stdio buffers several times
    mc::ImuSample s;
    s.t_ns = 10 + 5 * k;
    s.gyro = Eigen::Vector3d(0.1 * k, -2e-7, 3.0);
    s.accel = Eigen::Vector3d(9.81, 1.0 / (k + 1), -0.5);
    ok = w.add_imu(s) && ok;
    if (k % 10 == 0) {
      frame.t_ns = 12 + 5 * k;
      frame.uv[0] = Eigen::Vector2d(320.123456789 + k, 240.5);
      frame.uv[1] = Eigen::Vector2d(1e-9, 479.99999999);
      ok = w.add_frame(frame, k % 100 == 0 ? &image : nullptr) && ok;
    }
  }
  g_armed = false;
  EXPECT_TRUE(ok) << w.error();
  EXPECT_EQ(g_allocations.load(), 0);
  ASSERT_TRUE(w.close(err)) << err;
  // It did write: 2000 samples and a header.
  const std::string imu = slurp(tmp.path + "/mav0/imu0/data.csv");
  EXPECT_EQ(std::count(imu.begin(), imu.end(), '\n'), 2001);
  EXPECT_TRUE(fs::exists(tmp.path + "/mav0/cam0/data/512.pgm"));
}
