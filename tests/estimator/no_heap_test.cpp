// No heap on the hot path: predict and update of every filter configuration the product compiles
// must not allocate. This program counts every allocation: it replaces all global operator new
// forms, and the C allocation functions (forwarding to glibc's __libc_* entry points, which Eigen's
// aligned_malloc and everything else reach). Under AddressSanitizer, which owns malloc, it
// counts through the sanitizer's allocation hook instead.
#include <gtest/gtest.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <new>
#include <vector>

#include "mirrorcal/estimator/calibration_filter.hpp"
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
std::atomic<long> g_new_calls{0};     // operator new, any form
std::atomic<long> g_malloc_calls{0};  // malloc family (or the sanitizer's allocator)

inline void count_new() {
  if (g_armed.load(std::memory_order_relaxed)) g_new_calls.fetch_add(1, std::memory_order_relaxed);
}
inline void count_malloc() {
  if (g_armed.load(std::memory_order_relaxed))
    g_malloc_calls.fetch_add(1, std::memory_order_relaxed);
}

void* checked(void* p) {
  if (p == nullptr) throw std::bad_alloc();
  return p;
}

void* aligned(std::size_t size, std::align_val_t al) {
  void* p = nullptr;
  const std::size_t a =
      static_cast<std::size_t>(al) < sizeof(void*) ? sizeof(void*) : static_cast<std::size_t>(al);
  return posix_memalign(&p, a, size == 0 ? 1 : size) == 0 ? p : nullptr;
}

}  // namespace

// ---- the C allocator -------------------------------------------------------------------------
#ifdef MIRRORCAL_ASAN
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*malloc_hook)(const volatile void*,
                                                                             std::size_t),
                                                         void (*free_hook)(const volatile void*));
namespace {
void on_malloc(const volatile void*, std::size_t) {
  count_malloc();
}
void on_free(const volatile void*) {}
const int g_hooks_installed = __sanitizer_install_malloc_and_free_hooks(on_malloc, on_free);
}  // namespace
#else
extern "C" {
void* __libc_malloc(std::size_t) noexcept;
void* __libc_calloc(std::size_t, std::size_t) noexcept;
void* __libc_realloc(void*, std::size_t) noexcept;
void* __libc_memalign(std::size_t, std::size_t) noexcept;
void __libc_free(void*) noexcept;

void* malloc(std::size_t n) noexcept {
  count_malloc();
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  count_malloc();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) noexcept {
  count_malloc();
  return __libc_realloc(p, n);
}
void* memalign(std::size_t al, std::size_t n) noexcept {
  count_malloc();
  return __libc_memalign(al, n);
}
void* aligned_alloc(std::size_t al, std::size_t n) noexcept {
  count_malloc();
  return __libc_memalign(al, n);
}
int posix_memalign(void** out, std::size_t al, std::size_t n) noexcept {
  count_malloc();
  if (al % sizeof(void*) != 0 || (al & (al - 1)) != 0) return EINVAL;
  void* p = __libc_memalign(al, n);
  if (p == nullptr) return ENOMEM;
  *out = p;
  return 0;
}
void free(void* p) noexcept {
  __libc_free(p);
}
}  // extern "C"
#endif

// ---- operator new and delete, every replaceable form ----------------------------------------
// They allocate with malloc and release with free. GCC cannot see that pairing where it inlines a
// replacement delete into a delete-expression, and warns that free() meets operator new's memory.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void* operator new(std::size_t n) {
  count_new();
  return checked(std::malloc(n == 0 ? 1 : n));
}
void* operator new[](std::size_t n) {
  count_new();
  return checked(std::malloc(n == 0 ? 1 : n));
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  count_new();
  return std::malloc(n == 0 ? 1 : n);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  count_new();
  return std::malloc(n == 0 ? 1 : n);
}
void* operator new(std::size_t n, std::align_val_t al) {
  count_new();
  return checked(aligned(n, al));
}
void* operator new[](std::size_t n, std::align_val_t al) {
  count_new();
  return checked(aligned(n, al));
}
void* operator new(std::size_t n, std::align_val_t al, const std::nothrow_t&) noexcept {
  count_new();
  return aligned(n, al);
}
void* operator new[](std::size_t n, std::align_val_t al, const std::nothrow_t&) noexcept {
  count_new();
  return aligned(n, al);
}
void operator delete(void* p) noexcept {
  std::free(p);
}
void operator delete[](void* p) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete(void* p, const std::nothrow_t&) noexcept {
  std::free(p);
}
void operator delete[](void* p, const std::nothrow_t&) noexcept {
  std::free(p);
}
void operator delete(void* p, std::align_val_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::align_val_t) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t, std::align_val_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept {
  std::free(p);
}
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept {
  std::free(p);
}

namespace mirrorcal {
namespace {

struct Counts {
  long news;
  long mallocs;
};

class Armed {
 public:
  Armed() {
    g_new_calls = 0;
    g_malloc_calls = 0;
    g_armed = true;
  }
  Counts disarm() {
    g_armed = false;
    return {g_new_calls.load(), g_malloc_calls.load()};
  }
  ~Armed() { g_armed = false; }
};

// Opaque to the optimiser, so the self-test's allocations cannot be elided.
template <class T>
void escape(T* p) {
  asm volatile("" : : "g"(p) : "memory");
}

TEST(NoHeap, CounterSeesAllocations) {
#ifdef MIRRORCAL_ASAN
  ASSERT_NE(g_hooks_installed, 0) << "sanitizer allocation hook not installed";
#endif
  Armed armed;
  int* a = new int(3);
  escape(a);
  delete a;
  void* b = std::malloc(64);
  escape(b);
  std::free(b);
  std::vector<double> v(100);
  escape(v.data());
  const Counts c = armed.disarm();
  EXPECT_GE(c.news, 2);
  EXPECT_GE(c.mallocs, 2);
}

// Drives one configuration through predicts and every kind of update.
template <typename S, int NK>
Counts exercise() {
  using Filter = CalibrationFilter<S, 3, NK>;
  using State = typename Filter::State;
  const test::SineTrajectory traj = test::wall_mirror_trajectory();
  const test::Rig rig;
  std::vector<ImuSample> imu;
  std::vector<MarkerFrame<3>> frames;
  for (int k = 0; k <= 400; ++k) {
    imu.push_back(traj.imu(k * 5000000LL));
    if (k % 10 == 0) {
      MarkerFrame<3> f;
      f.t_ns = imu.back().t_ns;
      const bool visible = test::render_markers(traj, rig, f.t_ns * 1e-9, f.uv);
      f.seen = {visible, visible, visible};
      frames.push_back(f);
    }
  }
  const State x0 = test::truth_state<S, 3, NK>(traj, rig, 0.0);
  typename Filter::Covariance p0 = Filter::Covariance::Identity() * S(1e-4);
  if constexpr (NK > 0) p0.diagonal().template tail<NK>().setConstant(S(100.0));

  CalibrationConfig cfg;
  cfg.gravity_n = traj.gravity_n;
  cfg.gate_after_frames = 0;  // gate from the first frame, so the outliers take that path too
  Filter warm(cfg);
  warm.reset(x0, p0);
  warm.predict(imu[0], imu[1]);
  warm.update(frames[0]);

  Armed armed;
  Filter f(cfg);
  f.reset(x0, p0);
  int kind = 0;
  for (std::size_t k = 1; k < imu.size(); ++k) {
    f.predict(imu[k - 1], imu[k]);
    if (k % 10 != 0) continue;
    MarkerFrame<3> frame = frames[k / 10];
    switch (kind++ % 5) {
      case 0:
        break;  // full frame
      case 1:
        frame.seen[1] = false;
        break;  // partial
      case 2:
        frame.uv[0] += Eigen::Vector2d(300, 300);
        break;  // outlier: gated
      case 3:
        frame.seen = {false, false, false};
        break;  // empty
      case 4:
        frame.uv[2].x() = std::nan("");
        break;  // NaN: gated
    }
    f.update(frame);
  }
  // A refused predict (non-finite sample) goes through the failure path.
  ImuSample bad = imu[1];
  bad.gyro.x() = std::nan("");
  f.predict(imu[0], bad);
  const Counts c = armed.disarm();
  // The run did what it was meant to: updates used, gated and refused.
  EXPECT_GT(f.counters().markers_used, 50u);
  EXPECT_GE(f.counters().markers_gated, 10u);
  EXPECT_EQ(f.counters().failures, 1u);
  return c;
}

TEST(NoHeap, DoubleStage1) {
  const Counts c = exercise<double, 0>();
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

TEST(NoHeap, DoubleStage2) {
  const Counts c = exercise<double, 5>();
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

TEST(NoHeap, FloatStage1) {
  const Counts c = exercise<float, 0>();
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

}  // namespace
}  // namespace mirrorcal
