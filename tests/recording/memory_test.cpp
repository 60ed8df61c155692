// calibrate streams a recording from its files: its memory does not grow with their size. A
// recording whose CSV rows are padded to 110 MB (trailing blanks, which every reader skips)
// calibrates to the same bytes as the unpadded one, in a small fraction of that memory.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "test_support.hpp"

using namespace rectest;

namespace {

struct Measured {
  int status = -1;
  long peak_rss_kib = 0;  // the child's largest resident set (ru_maxrss)
};

// mirrorcal with args, its output into log, env added to its environment; the child's own peak
// memory from wait4 (or its children's, gnuplot's, if larger: wait4 counts the children it
// waited for).
Measured run_measured(const std::vector<std::string>& args, const std::string& log,
                      const std::vector<std::string>& env = {}) {
  Measured r;
  const pid_t pid = spawn_mirrorcal(args, log, env);
  int status = 0;
  rusage usage{};
  if (pid < 0 || wait4(pid, &status, 0, &usage) != pid) return r;
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.peak_rss_kib = usage.ru_maxrss;
  return r;
}

// Copies from to to with every data row padded with blanks to width characters.
std::uint64_t pad_rows(const std::string& from, const std::string& to, std::size_t width) {
  std::ifstream in(from);
  std::ofstream out(to, std::ios::binary | std::ios::trunc);
  std::string line;
  std::getline(in, line);
  out << line << '\n';
  std::uint64_t bytes = line.size() + 1;
  while (std::getline(in, line)) {
    if (line.size() < width) line.append(width - line.size(), ' ');
    out << line << '\n';
    bytes += line.size() + 1;
  }
  return bytes;
}

TEST(StreamedInput, A110MBRecordingCalibratesInBoundedMemoryToTheSameBytes) {
  TempDir tmp("streamed-input");
  const std::string plain = tmp.path + "/plain", padded = tmp.path + "/padded";
  const auto s = short_scenario(10.0);
  write_recording(plain, s, mc::sim::simulate(s, 5), 5);
  write_recording(padded, s, mc::sim::simulate(s, 5), 5);
  // Rows of half the longest line the reader takes (64 KiB), 110 MB in all.
  constexpr std::size_t kWidth = 33000;
  std::uint64_t bytes = 0;
  for (const char* csv : {"/mav0/imu0/data.csv", "/mav0/cam0/features.csv"})
    bytes += pad_rows(plain + csv, padded + csv, kWidth);
  ASSERT_GT(bytes, 100u << 20);

  const Measured small =
      run_measured({"calibrate", plain, "--out", tmp.path + "/out-plain"}, tmp.path + "/plain.log");
  ASSERT_EQ(small.status, 0) << slurp(tmp.path + "/plain.log");
  const Measured large = run_measured({"calibrate", padded, "--out", tmp.path + "/out-padded"},
                                      tmp.path + "/padded.log");
  ASSERT_EQ(large.status, 0) << slurp(tmp.path + "/padded.log");

  // Loaded whole, the files alone took more than their 110 MB; streamed, the reader's buffers
  // (64 KiB a file) add next to nothing to what the calibration itself needs.
  const long bytes_kib = static_cast<long>(bytes >> 10);
  std::printf("calibrate's peak memory: %ld KiB for %ld KiB of files, %ld KiB unpadded\n",
              large.peak_rss_kib, bytes_kib, small.peak_rss_kib);
  // Under AddressSanitizer the program's shadow memory and quarantine alone take about 85 MB,
  // padded or not: there only the comparison with the unpadded run below says something.
#if !defined(__SANITIZE_ADDRESS__)
  EXPECT_LT(large.peak_rss_kib, bytes_kib / 4)
      << "peak " << large.peak_rss_kib << " KiB for " << bytes_kib << " KiB of files";
#endif
  EXPECT_LT(large.peak_rss_kib, small.peak_rss_kib + 8 * 1024)
      << "padded " << large.peak_rss_kib << " KiB, plain " << small.peak_rss_kib << " KiB";
  for (const char* file : {"/camchain-imucam.yaml", "/estimates.csv"})
    EXPECT_EQ(slurp(tmp.path + "/out-padded" + file), slurp(tmp.path + "/out-plain" + file))
        << file;
}

}  // namespace
