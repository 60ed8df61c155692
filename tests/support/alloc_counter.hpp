// Counts heap allocations, so a test can prove that a piece of code does not allocate. Linking
// tests/support/alloc_counter.cpp into a test program replaces every global operator new and the C
// allocation functions of that program (under AddressSanitizer, which owns malloc, it counts
// through the sanitizer's allocation hook instead). Counting is off until an AllocCounter exists.
//
//   mirrorcal::test::AllocCounter counting;
//   code_under_test();
//   const auto c = counting.stop();
//   EXPECT_EQ(c.total(), 0);
#pragma once

namespace mirrorcal::test {

struct AllocCounts {
  long news = 0;     // operator new, any form
  long mallocs = 0;  // malloc, calloc, realloc, the aligned forms (or the sanitizer's allocator)
  long total() const { return news + mallocs; }
};

// Counts every allocation of any thread from construction until stop() or destruction. One at a
// time.
class AllocCounter {
 public:
  AllocCounter();
  ~AllocCounter();
  AllocCounter(const AllocCounter&) = delete;
  AllocCounter& operator=(const AllocCounter&) = delete;
  AllocCounts stop();
};

// Whether the counting hooks are in place (false only if the sanitizer refused its hook).
bool alloc_counter_installed();

// Opaque to the optimiser, so that a self-test's allocations cannot be elided.
template <class T>
void escape(T* p) {
  asm volatile("" : : "g"(p) : "memory");
}

}  // namespace mirrorcal::test
