// Results written whole or not at all (mirrorcal/io/files.hpp): a set of files replaces the
// earlier one only when committed, and a writer killed at any moment before leaves the earlier
// files as they were. Kills are made at known points (the child says where it is through a pipe),
// never after a sleep.
#include <gtest/gtest.h>

#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "mirrorcal/io/files.hpp"
#include "recording_support.hpp"

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
    mc::io::OutputSet set;
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
  mc::io::OutputSet set;
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
    mc::io::OutputSet set;
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
  mc::io::OutputSet set;
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

// SIGTERM, SIGINT, SIGHUP or SIGQUIT coming between two renames of a commit (raised there by the
// test hook) stop the writer only once every file is in place: the new set whole, never some
// files of each. Before, the writer died after the first rename, a new a.txt beside the old b.txt.
TEST(OutputSet, ATerminationSignalBetweenItsRenamesStopsTheWriterAfterTheLast) {
  for (const int signal : {SIGTERM, SIGINT, SIGHUP, SIGQUIT}) {
    const TempDir tmp("set-signal-between-renames");
    for (const char* name : {"a", "b", "c"}) spit(tmp.path + "/" + name + ".txt", "old");
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      const rlimit no_core{0, 0};  // SIGQUIT's default action dumps one
      setrlimit(RLIMIT_CORE, &no_core);
      static int raised;
      raised = signal;
      mc::io::OutputSet::set_between_renames_for_test([] {
        mc::io::OutputSet::set_between_renames_for_test(nullptr);  // once, after the first
        ::raise(raised);
      });
      std::string err;
      mc::io::OutputSet set;
      for (const char* name : {"a", "b", "c"}) {
        std::FILE* f = set.add(tmp.path + "/" + name + ".txt", err);
        if (f == nullptr) _exit(1);
        std::fputs("new", f);
      }
      set.commit(err);
      _exit(0);  // not reached: the signal ends the writer when the commit ends
    }
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == signal) << strsignal(signal);
    for (const char* name : {"a", "b", "c"})
      EXPECT_EQ(slurp(tmp.path + "/" + name + ".txt"), "new") << name << ", " << strsignal(signal);
  }
}

TEST(OutputSet, AFileThatCannotBeCreatedIsNamed) {
  const TempDir tmp("set-no-folder");
  std::string err;
  mc::io::OutputSet set;
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
    char c = mc::io::lock_folder(tmp.path, err) ? 'y' : 'n';
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
  EXPECT_FALSE(mc::io::lock_folder(tmp.path, err));
  EXPECT_NE(err.find(tmp.path + ": another mirrorcal is writing into this folder"),
            std::string::npos)
      << err;
  close(release[1]);  // the first writer ends
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(mc::io::lock_folder(tmp.path, err)) << err;
  close(ready[0]);
}

namespace {

// A record of odd size (not a divisor of the page), without padding, whose bytes say which
// record it is.
struct Rec {
  unsigned char bytes[29] = {};
};
static_assert(sizeof(Rec) == 29);
Rec rec(std::uint64_t k) {
  Rec r;
  const double value = std::ldexp(static_cast<double>(k) + 0.1, static_cast<int>(k % 40) - 20);
  std::memcpy(r.bytes, &k, sizeof k);
  std::memcpy(r.bytes + sizeof k, &value, sizeof value);
  for (std::size_t i = 16; i < sizeof r.bytes; ++i)
    r.bytes[i] = static_cast<unsigned char>(k * 7 + i);
  return r;
}
bool same(const Rec& a, const Rec& b) {
  return std::memcmp(a.bytes, b.bytes, sizeof a.bytes) == 0;
}
void write_rec(mc::io::RecordFile& f, std::size_t k, const Rec& r) {
  f.write(k, &r);
}
Rec read_rec(const mc::io::RecordFile& f, std::size_t k) {
  Rec r;
  std::memset(r.bytes, 0xee, sizeof r.bytes);
  f.read(k, &r);
  return r;
}

}  // namespace

// Records come back byte for byte, forwards, backwards and at random, written in order, in
// reverse or over earlier ones, through a page of a few records (every access crosses pages).
TEST(RecordFile, GivesBackEveryRecordByteForByteInAnyOrder) {
  constexpr std::size_t kN = 1000;
  mc::io::RecordFile ahead(sizeof(Rec), "the test's records", 5 * sizeof(Rec) + 3);
  for (std::size_t k = 0; k < kN; ++k) write_rec(ahead, ahead.size(), rec(k));
  ASSERT_EQ(ahead.size(), kN);
  for (std::size_t k = 0; k < kN; ++k) ASSERT_TRUE(same(read_rec(ahead, k), rec(k))) << k;
  for (std::size_t k = kN; k-- > 0;) ASSERT_TRUE(same(read_rec(ahead, k), rec(k))) << k;
  std::mt19937 random(3);
  for (int i = 0; i < 500; ++i) {
    const std::size_t k = random() % kN;
    ASSERT_TRUE(same(read_rec(ahead, k), rec(k))) << k;
  }
  // Over earlier records, then read again.
  for (std::size_t k = 100; k < 120; ++k) write_rec(ahead, k, rec(k + 5000));
  for (std::size_t k = 0; k < kN; ++k)
    ASSERT_TRUE(same(read_rec(ahead, k), rec(k >= 100 && k < 120 ? k + 5000 : k))) << k;

  // Written backwards (a smoother's order), read forwards.
  mc::io::RecordFile back(sizeof(Rec), "the test's records", 64);
  for (std::size_t k = kN; k-- > 0;) write_rec(back, k, rec(k));
  ASSERT_EQ(back.size(), kN);
  for (std::size_t k = 0; k < kN; ++k) ASSERT_TRUE(same(read_rec(back, k), rec(k))) << k;

  // Records never written read as zeros.
  mc::io::RecordFile holes(sizeof(Rec), "the test's records", 64);
  write_rec(holes, 50, rec(50));
  const Rec zero{};
  ASSERT_EQ(holes.size(), 51u);
  EXPECT_TRUE(same(read_rec(holes, 49), zero));
  EXPECT_TRUE(same(read_rec(holes, 0), zero));
  EXPECT_TRUE(same(read_rec(holes, 50), rec(50)));
}

// The file has no name from the start (nothing left behind, whatever ends the process), and a
// store moved keeps its records.
TEST(RecordFile, LeavesNoFileAndMovesWhole) {
  mc::io::RecordFile f(sizeof(Rec), "the test's records", 64);
  EXPECT_FALSE(fs::exists(f.path())) << f.path();
  for (std::size_t k = 0; k < 40; ++k) write_rec(f, f.size(), rec(k));
  mc::io::RecordFile g = std::move(f);
  ASSERT_EQ(g.size(), 40u);
  for (std::size_t k = 0; k < 40; ++k) ASSERT_TRUE(same(read_rec(g, k), rec(k))) << k;
}

// A write the file system refuses (here the process's file size limit, as a full disk would) is a
// StoreError that names the store's file and why, not a crash.
TEST(RecordFile, AWriteRefusedIsAnErrorNamingTheStore) {
  rlimit old{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);  // EFBIG instead of the signal
  std::string message;
  std::string path;
  {
    mc::io::RecordFile f(sizeof(Rec), "the test's records", 10 * sizeof(Rec));
    path = f.path();
    rlimit small = old;
    small.rlim_cur = 40 * sizeof(Rec);
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
    try {
      for (std::size_t k = 0; k < 1000; ++k) write_rec(f, f.size(), rec(k));
      (void)read_rec(f, 0);  // writes the last page out
    } catch (const mc::io::StoreError& e) {
      message = e.what();
    }
    setrlimit(RLIMIT_FSIZE, &old);
  }
  std::signal(SIGXFSZ, old_handler);
  EXPECT_NE(message.find(path + ": cannot write the temporary store of the test's records: "),
            std::string::npos)
      << message;
  EXPECT_NE(message.find(std::strerror(EFBIG)), std::string::npos) << message;
}
