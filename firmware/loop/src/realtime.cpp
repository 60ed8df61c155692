#include "mirrorcal/loop/realtime.hpp"

#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace mirrorcal::loop {

namespace {

// Touches kPrefaultStackBytes of stack below the caller so that the pages are mapped (and, after
// mlockall, locked) before the loop needs them.
__attribute__((noinline)) void prefault_stack() {
  volatile unsigned char stack[kPrefaultStackBytes];
  for (std::size_t i = 0; i < sizeof stack; i += 4096) stack[i] = 0;
}

std::string why(int err) {
  if (err == EPERM)
    return "not permitted (needs root or CAP_SYS_NICE / CAP_IPC_LOCK, or an rtprio / memlock "
           "limit in /etc/security/limits.conf); running without it";
  if (err == ENOMEM) return "the memlock limit is too small (ulimit -l); running without it";
  return std::string(std::strerror(err)) + "; running without it";
}

}  // namespace

RealtimeOutcome apply_realtime(const RealtimeOptions& o) {
  RealtimeOutcome out;
  if (o.cpu >= 0) {
    const long cpus = sysconf(_SC_NPROCESSORS_CONF);
    if (o.cpu >= CPU_SETSIZE || (cpus > 0 && o.cpu >= cpus)) {
      out.error = "--cpu " + std::to_string(o.cpu) + ": this machine has CPUs 0.." +
                  std::to_string(cpus - 1);
      return out;
    }
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(o.cpu, &set);
    if (sched_setaffinity(0, sizeof set, &set) == 0)
      out.notes.push_back("pinned to CPU " + std::to_string(o.cpu));
    else if (errno == EINVAL)
      out.notes.push_back("CPU " + std::to_string(o.cpu) +
                          " is not available to this process (cpuset); running unpinned");
    else
      out.notes.push_back("CPU affinity: " + why(errno));
  }
  if (o.lock_memory) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
      prefault_stack();
      out.notes.push_back("memory locked, " + std::to_string(kPrefaultStackBytes / 1024) +
                          " KiB of stack pre-faulted");
    } else {
      out.notes.push_back("mlockall: " + why(errno));
    }
  }
  if (o.fifo_priority != 0) {
    const int lo = sched_get_priority_min(SCHED_FIFO), hi = sched_get_priority_max(SCHED_FIFO);
    if (o.fifo_priority < lo || o.fifo_priority > hi) {
      out.error = "--rt-priority " + std::to_string(o.fifo_priority) + ": SCHED_FIFO takes " +
                  std::to_string(lo) + ".." + std::to_string(hi);
      return out;
    }
    sched_param sp{};
    sp.sched_priority = o.fifo_priority;
    if (sched_setscheduler(0, SCHED_FIFO, &sp) == 0)
      out.notes.push_back("SCHED_FIFO priority " + std::to_string(o.fifo_priority));
    else
      out.notes.push_back("SCHED_FIFO: " + why(errno));
  }
  return out;
}

}  // namespace mirrorcal::loop
