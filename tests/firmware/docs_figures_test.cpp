// The campaigns in docs/campaign are this code's: their first runs, made again with the command
// each README there names, come out bit for bit as committed (every column but the wall time).
// A change that moves any figure of a published campaign fails here until the campaign is made
// again and its docs say what changed; a refactoring that changes nothing passes.
#include <gtest/gtest.h>

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

// Runs montecarlo with options for `runs` runs and compares its runs.csv with the committed one.
void expect_reproduces(const std::string& campaign, const std::string& options, int runs) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("mirrorcal-docs-figures-" + std::to_string(getpid()));
  const std::string cmd = std::string(MIRRORCAL_BIN) + " montecarlo --runs " +
                          std::to_string(runs) + " --jobs 2 --no-plots " + options + " --out " +
                          dir.string() + " > " + dir.string() + ".log 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const auto made = first_rows(dir / "runs.csv", runs);
  const auto committed =
      first_rows(std::filesystem::path(MIRRORCAL_SOURCE_DIR) / campaign / "runs.csv", runs);
  ASSERT_EQ(made.size(), static_cast<std::size_t>(runs + 1));
  ASSERT_EQ(committed.size(), made.size()) << campaign;
  ASSERT_EQ(made[0], committed[0]) << campaign << ": the columns differ";
  std::size_t wall = 0;
  while (wall < made[0].size() && made[0][wall] != "wall_s") ++wall;
  for (std::size_t r = 1; r < made.size(); ++r) {
    ASSERT_EQ(made[r].size(), committed[r].size());
    for (std::size_t c = 0; c < made[r].size(); ++c) {
      if (c == wall) continue;
      EXPECT_EQ(made[r][c], committed[r][c]) << campaign << ", run " << r - 1 << ", " << made[0][c];
    }
  }
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

}  // namespace
