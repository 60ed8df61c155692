// What the sim and montecarlo commands print beside the estimate: the truth in display units and
// the paper's tables.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "mirrorcal/sim/scenario.hpp"

namespace mirrorcal::evaluation {

// Display value of the truth of each calibration parameter, in the row order of
// calibration_params(): p and markers in cm, the rotation as the scenario's three angles in deg.
std::vector<double> truth_display(const sim::Scenario& s, int intrinsics = 0);

// The paper's Tables I, II and III, final value and sigma, in our row order (rotation columns read
// as about x, y, z: see paper_scenario()); NaN for what the paper does not estimate.
struct PaperRow {
  double final_value, sigma;
};
const std::vector<PaperRow>& paper_tables();

}  // namespace mirrorcal::evaluation
