// Running the loop as a real-time task: SCHED_FIFO at a priority, all memory locked with the stack
// pre-faulted (no page fault inside the loop), and pinned to one CPU. Call once at start-up, after
// the large buffers are allocated and before the loop runs.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace mirrorcal::loop {

struct RealtimeOptions {
  int fifo_priority = 0;     // SCHED_FIFO priority 1..99; 0 leaves the scheduling alone
  bool lock_memory = false;  // mlockall(MCL_CURRENT | MCL_FUTURE) and pre-fault the stack
  int cpu = -1;              // pin to this CPU; -1 leaves the affinity alone
};

struct RealtimeOutcome {
  // One line per setting asked for: what was done, or why it was not (missing privileges are not
  // an error: the loop runs anyway, just without that guarantee).
  std::vector<std::string> notes;
  // Set when a request is wrong in itself (a priority out of range, a CPU that does not exist):
  // the caller should stop with this message.
  std::string error;
};

RealtimeOutcome apply_realtime(const RealtimeOptions& o);

// Bytes of stack touched by apply_realtime when it locks memory.
constexpr std::size_t kPrefaultStackBytes = 256 * 1024;

}  // namespace mirrorcal::loop
