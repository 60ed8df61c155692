// The error plots of a campaign: one picture per parameter group, whatever the parameters' scales.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "mirrorcal/evaluation/plots.hpp"

namespace mirrorcal::evaluation {
namespace {

// Two parameters of one group whose scales differ a thousandfold: the converged y range of the
// first (a few units) holds none of the second's errors (thousands).
std::vector<ErrorSeries> runs_of_two_scales(const std::vector<ParamInfo>& params) {
  std::vector<ErrorSeries> runs(2);
  for (std::size_t r = 0; r < runs.size(); ++r) {
    ErrorSeries& s = runs[r];
    s.error.resize(params.size());
    s.sigma.resize(params.size());
    for (int i = 0; i < 50; ++i) {
      s.t_s.push_back(0.1 * i);
      s.nees.push_back(16.0);
      const double sign = (i + int(r)) % 2 == 0 ? 1.0 : -1.0;
      s.error[0].push_back(sign * 1.0);
      s.sigma[0].push_back(2.0);
      s.error[1].push_back(sign * 3000.0);
      s.sigma[1].push_back(2000.0);
    }
  }
  return runs;
}

TEST(Plots, EveryGroupIsDrawnWhenOneParameterIsOutOfTheLastOnesRange) {
  const std::vector<ParamInfo> params = {{"f1_x", "cm", 100.0, CalibrationGroup::kMarkers},
                                         {"f1_y", "cm", 100.0, CalibrationGroup::kMarkers}};
  PlotFolder folder("mirrorcal-plots-test");
  ASSERT_FALSE(folder.path.empty());
  std::string error;
  const std::vector<std::string> written =
      plot_errors(folder.path, "test", params, runs_of_two_scales(params), 14.0, 18.0, error);
  ASSERT_FALSE(written.empty()) << error;
  for (const std::string& png : written) {
    ASSERT_TRUE(std::filesystem::exists(png)) << png;
    EXPECT_GT(std::filesystem::file_size(png), 1000u) << png;
  }
  // The converged picture and the one from the prior, and the NEES.
  EXPECT_TRUE(std::filesystem::exists(folder.path + "/error_markers.png"));
  EXPECT_TRUE(std::filesystem::exists(folder.path + "/error_markers_from_prior.png"));
  EXPECT_TRUE(std::filesystem::exists(folder.path + "/nees.png"));
  // gnuplot's files go once the pictures are drawn.
  EXPECT_FALSE(std::filesystem::exists(folder.path + "/errors.dat"));
}

}  // namespace
}  // namespace mirrorcal::evaluation
