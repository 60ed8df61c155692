// Results written whole or not at all (mirrorcal/sim_host/files.hpp): a set of files replaces the
// earlier one only when committed, and a writer killed at any moment before leaves the earlier
// files as they were. Kills are made at known points (the child says where it is through a pipe),
// never after a sleep.
#include <gtest/gtest.h>

#include <csignal>
#include <string>

#include <sys/wait.h>
#include <unistd.h>

#include "mirrorcal/sim_host/files.hpp"
#include "test_support.hpp"

using namespace rectest;

namespace {

// Where the child writer stops and waits to be killed.
enum class KillAt { kWhileWriting, kAfterCommit };

// Forks a writer that replaces a.txt and b.txt (already holding "old a", "old b") by a set of new
// contents, and kills it with SIGKILL at the point given.
void kill_writer_at(const std::string& dir, KillAt at) {
  int ready[2], never[2];
  ASSERT_EQ(pipe(ready), 0);
  ASSERT_EQ(pipe(never), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    std::string err;
    mc::files::OutputSet set;
    std::FILE* a = set.add(dir + "/a.txt", err);
    std::FILE* b = set.add(dir + "/b.txt", err);
    if (a == nullptr || b == nullptr) _exit(1);
    std::fputs("new a, complete\n", a);
    std::fputs("new b, cut here", b);
    std::fflush(a);
    std::fflush(b);  // the bytes are in the temporary files
    if (at == KillAt::kAfterCommit) {
      std::fputs(", and complete\n", b);
      if (!set.commit(err)) _exit(1);
    }
    char c = 'x';
    if (write(ready[1], &c, 1) != 1) _exit(1);
    if (read(never[0], &c, 1) < 0) _exit(1);  // blocks: nobody writes to it
    _exit(0);
  }
  close(ready[1]);
  close(never[0]);
  char c = 0;
  ASSERT_EQ(read(ready[0], &c, 1), 1) << "the writer failed before the point of the kill";
  ASSERT_EQ(kill(pid, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  close(ready[0]);
  close(never[1]);
}

}  // namespace

TEST(OutputSet, ReplacesEveryFileWhenCommittedAndNoneBefore) {
  const TempDir tmp("set-commit");
  spit(tmp.path + "/a.txt", "old a");
  std::string err;
  mc::files::OutputSet set;
  std::FILE* a = set.add(tmp.path + "/a.txt", err);
  std::FILE* b = set.add(tmp.path + "/b.txt", err);
  ASSERT_TRUE(a != nullptr && b != nullptr) << err;
  std::fputs("new a", a);
  std::fputs("new b", b);
  std::fflush(a);
  EXPECT_EQ(slurp(tmp.path + "/a.txt"), "old a");
  EXPECT_FALSE(fs::exists(tmp.path + "/b.txt"));
  ASSERT_TRUE(set.commit(err)) << err;
  EXPECT_EQ(slurp(tmp.path + "/a.txt"), "new a");
  EXPECT_EQ(slurp(tmp.path + "/b.txt"), "new b");
  // Nothing but the results is left in the folder.
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp.path), fs::directory_iterator()), 2);
}

TEST(OutputSet, ASetNeverCommittedLeavesTheEarlierFilesAndNoTemporaryOne) {
  const TempDir tmp("set-dropped");
  spit(tmp.path + "/a.txt", "old a");
  {
    std::string err;
    mc::files::OutputSet set;
    std::FILE* a = set.add(tmp.path + "/a.txt", err);
    ASSERT_NE(a, nullptr) << err;
    std::fputs("new a", a);
  }
  EXPECT_EQ(slurp(tmp.path + "/a.txt"), "old a");
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp.path), fs::directory_iterator()), 1);
}

TEST(OutputSet, AWriterKilledWhileWritingLeavesTheEarlierFiles) {
  const TempDir tmp("set-killed-writing");
  spit(tmp.path + "/a.txt", "old a");
  spit(tmp.path + "/b.txt", "old b");
  kill_writer_at(tmp.path, KillAt::kWhileWriting);
  EXPECT_EQ(slurp(tmp.path + "/a.txt"), "old a");
  EXPECT_EQ(slurp(tmp.path + "/b.txt"), "old b");
  // Its temporary files are left; the next writer of those files removes them.
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp.path), fs::directory_iterator()), 4);
  std::string err;
  mc::files::OutputSet set;
  ASSERT_NE(set.add(tmp.path + "/a.txt", err), nullptr) << err;
  ASSERT_NE(set.add(tmp.path + "/b.txt", err), nullptr) << err;
  ASSERT_TRUE(set.commit(err)) << err;
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp.path), fs::directory_iterator()), 2);
}

TEST(OutputSet, AWriterKilledAfterItsCommitLeavesTheNewFilesComplete) {
  const TempDir tmp("set-killed-committed");
  spit(tmp.path + "/a.txt", "old a");
  spit(tmp.path + "/b.txt", "old b");
  kill_writer_at(tmp.path, KillAt::kAfterCommit);
  EXPECT_EQ(slurp(tmp.path + "/a.txt"), "new a, complete\n");
  EXPECT_EQ(slurp(tmp.path + "/b.txt"), "new b, cut here, and complete\n");
}

TEST(OutputSet, AFileThatCannotBeCreatedIsNamed) {
  const TempDir tmp("set-no-folder");
  std::string err;
  mc::files::OutputSet set;
  EXPECT_EQ(set.add(tmp.path + "/missing/a.txt", err), nullptr);
  EXPECT_NE(err.find(tmp.path + "/missing/a.txt: cannot write: No such file or directory"),
            std::string::npos)
      << err;
}

// flock() locks belong to an open file: a second process's lock_folder is refused while the first
// holds the folder, and gets it once the first has ended.
TEST(LockFolder, ASecondWriterIsRefusedUntilTheFirstEnds) {
  const TempDir tmp("lock");
  int ready[2], release[2];
  ASSERT_EQ(pipe(ready), 0);
  ASSERT_EQ(pipe(release), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    close(release[1]);  // else its read below would never see the end
    std::string err;
    char c = mc::files::lock_folder(tmp.path, err) ? 'y' : 'n';
    if (write(ready[1], &c, 1) != 1) _exit(1);
    if (read(release[0], &c, 1) < 0) _exit(1);  // until the parent closes its end
    _exit(0);
  }
  close(ready[1]);
  close(release[0]);
  char c = 0;
  ASSERT_EQ(read(ready[0], &c, 1), 1);
  ASSERT_EQ(c, 'y');
  std::string err;
  EXPECT_FALSE(mc::files::lock_folder(tmp.path, err));
  EXPECT_NE(err.find(tmp.path + ": another mirrorcal is writing into this folder"),
            std::string::npos)
      << err;
  close(release[1]);  // the first writer ends
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(mc::files::lock_folder(tmp.path, err)) << err;
  close(ready[0]);
}
