// Real-time settings: wrong requests are refused with a message, and without privileges every
// setting says why it was not applied while the run goes on.
#include <gtest/gtest.h>
#include <sched.h>
#include <sys/wait.h>
#include <unistd.h>

#include <string>

#include "mirrorcal/loop/realtime.hpp"

namespace mcf = mirrorcal::loop;

TEST(Realtime, NothingAskedNothingDone) {
  const mcf::RealtimeOutcome r = mcf::apply_realtime({});
  EXPECT_TRUE(r.error.empty());
  EXPECT_TRUE(r.notes.empty());
}

TEST(Realtime, PriorityOutOfRangeIsAnError) {
  mcf::RealtimeOptions o;
  o.fifo_priority = 100;
  const mcf::RealtimeOutcome r = mcf::apply_realtime(o);
  EXPECT_NE(r.error.find("--rt-priority 100"), std::string::npos) << r.error;
  EXPECT_EQ(sched_getscheduler(0), SCHED_OTHER);
}

TEST(Realtime, MissingCpuIsAnError) {
  mcf::RealtimeOptions o;
  o.cpu = 4096;
  const mcf::RealtimeOutcome r = mcf::apply_realtime(o);
  EXPECT_NE(r.error.find("--cpu 4096"), std::string::npos) << r.error;
}

// In a child process that has given up root (if it had it): every setting is reported, none is
// an error. Exit code 0 when that holds.
TEST(Realtime, WithoutPrivilegesItSaysSoAndGoesOn) {
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    if (getuid() == 0 && (setgid(65534) != 0 || setuid(65534) != 0)) _exit(10);
    mcf::RealtimeOptions o;
    o.fifo_priority = 50;
    o.lock_memory = true;
    o.cpu = 0;
    const mcf::RealtimeOutcome r = mcf::apply_realtime(o);
    if (!r.error.empty()) _exit(11);
    if (r.notes.size() != 3) _exit(12);
    // Unprivileged, SCHED_FIFO is refused (unless an rtprio limit allows it) and says why.
    const bool fifo = sched_getscheduler(0) == SCHED_FIFO;
    if (!fifo && r.notes[2].find("running without it") == std::string::npos) _exit(13);
    _exit(0);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}
