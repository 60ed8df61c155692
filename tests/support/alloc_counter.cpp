// The allocation counter of alloc_counter.hpp: replaces all global operator new forms, and the C
// allocation functions (forwarding to glibc's __libc_* entry points, which Eigen's aligned_malloc
// and everything else reach).
#include "alloc_counter.hpp"

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdlib>
#include <new>

#include "sanitizers.hpp"

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
#if MIRRORCAL_ASAN
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

namespace mirrorcal::test {

AllocCounter::AllocCounter() {
  g_new_calls = 0;
  g_malloc_calls = 0;
  g_armed = true;
}

AllocCounter::~AllocCounter() {
  g_armed = false;
}

AllocCounts AllocCounter::stop() {
  g_armed = false;
  AllocCounts c;
  c.news = g_new_calls.load();
  c.mallocs = g_malloc_calls.load();
  return c;
}

bool alloc_counter_installed() {
#if MIRRORCAL_ASAN
  return g_hooks_installed != 0;
#else
  return true;
#endif
}

}  // namespace mirrorcal::test
