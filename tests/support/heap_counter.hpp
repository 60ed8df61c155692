// Counts heap allocations, to prove that code on the hot path does not allocate: linking
// heap_counter.cpp into a test program replaces every global operator new form and the C
// allocation functions (forwarding to glibc's __libc_* entry points, which Eigen's aligned_malloc
// and everything else reach). Under AddressSanitizer, which owns malloc, it counts through the
// sanitizer's allocation hook instead. One program per use: the replacement is global.
#pragma once

namespace mirrorcal::test {

struct AllocationCounts {
  long news;     // operator new, any form
  long mallocs;  // malloc family (or the sanitizer's allocator)
};

// Counts allocations from construction until disarm() (or destruction).
class CountAllocations {
 public:
  CountAllocations();
  ~CountAllocations();
  AllocationCounts disarm();
};

// False if the counting hook could not be installed (sanitizer builds only).
bool allocation_counting_works();

}  // namespace mirrorcal::test
