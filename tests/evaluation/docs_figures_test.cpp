// The campaigns in docs/campaign are this code's: their first runs, made again with the command
// each README there names, come out bit for bit as committed (every column but the times).
// A change that moves any figure of a published campaign fails here until the campaign is made
// again and its docs say what changed; a refactoring that changes nothing passes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace {

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> cells;
  std::string::size_type from = 0;
  for (auto comma = line.find(','); comma != std::string::npos; comma = line.find(',', from)) {
    cells.push_back(line.substr(from, comma - from));
    from = comma + 1;
  }
  cells.push_back(line.substr(from));
  return cells;
}

// The header and the first `rows` runs of a runs.csv.
std::vector<std::vector<std::string>> first_rows(const std::filesystem::path& path, int rows) {
  std::ifstream in(path);
  std::vector<std::vector<std::string>> out;
  std::string line;
  while (static_cast<int>(out.size()) <= rows && std::getline(in, line)) out.push_back(split(line));
  return out;
}

// The first `runs` rows of file in the campaign made in dir against the committed campaign's,
// every column but those in skip (times).
void expect_same_rows(const std::filesystem::path& dir, const std::string& campaign,
                      const std::string& file, int runs, const std::vector<std::string>& skip) {
  const auto made = first_rows(dir / file, runs);
  const auto committed =
      first_rows(std::filesystem::path(MIRRORCAL_SOURCE_DIR) / campaign / file, runs);
  ASSERT_EQ(made.size(), static_cast<std::size_t>(runs + 1)) << file;
  ASSERT_EQ(committed.size(), made.size()) << campaign << "/" << file;
  ASSERT_EQ(made[0], committed[0]) << campaign << "/" << file << ": the columns differ";
  for (std::size_t r = 1; r < made.size(); ++r) {
    ASSERT_EQ(made[r].size(), committed[r].size());
    for (std::size_t c = 0; c < made[r].size(); ++c) {
      if (std::find(skip.begin(), skip.end(), made[0][c]) != skip.end()) continue;
      EXPECT_EQ(made[r][c], committed[r][c])
          << campaign << "/" << file << ", run " << r - 1 << ", " << made[0][c];
    }
  }
}

// Runs montecarlo with options for `runs` runs and compares its runs.csv (and with --batch its
// batch.csv) with the committed ones.
void expect_reproduces(const std::string& campaign, const std::string& options, int runs) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("mirrorcal-docs-figures-" + std::to_string(getpid()));
  const std::string cmd = std::string(MIRRORCAL_BIN) + " montecarlo --runs " +
                          std::to_string(runs) + " --jobs 2 --no-plots " + options + " --out " +
                          dir.string() + " > " + dir.string() + ".log 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  expect_same_rows(dir, campaign, "runs.csv", runs, {"wall_s"});
  if (options.find("--batch") != std::string::npos)
    expect_same_rows(dir, campaign, "batch.csv", runs, {"batch_cpu_s", "filter_wall_s"});
  std::filesystem::remove_all(dir);
  std::filesystem::remove(dir.string() + ".log");
}

TEST(DocsFigures, PaperStageOneCampaignReproduces) {
  expect_reproduces("docs/campaign", "--seed 1", 4);
}

TEST(DocsFigures, PaperStageTwoCampaignReproduces) {
  expect_reproduces("docs/campaign/stage2", "--intrinsics --seed 1", 2);
}

TEST(DocsFigures, RandomFamilyCampaignReproduces) {
  expect_reproduces("docs/campaign/random", "--scenario random --seed 1", 4);
}

TEST(DocsFigures, FilterAgainstBatchCampaignReproduces) {
#ifdef MIRRORCAL_BATCH
  expect_reproduces("docs/campaign/batch", "--scenario random --seed 1 --batch", 2);
#else
  GTEST_SKIP() << "a build without the batch (MIRRORCAL_BATCH)";
#endif
}

}  // namespace
