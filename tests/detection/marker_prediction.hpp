// A filter's prediction placed by hand, for the identifier's tests (detection_test.cpp,
// blob_tracker_test.cpp).
#pragma once

#include <array>
#include <cstddef>

#include "mirrorcal/hal/frames.hpp"

namespace marker_prediction {

// Every marker predicted at uv, with sigma_px in each direction (1 px: a settled filter's).
template <std::size_t N>
mirrorcal::hal::MarkerPrediction<static_cast<int>(N)> prediction_at(
    const std::array<Eigen::Vector2d, N>& uv, double sigma_px) {
  mirrorcal::hal::MarkerPrediction<static_cast<int>(N)> p;
  for (std::size_t i = 0; i < N; ++i) {
    p.valid[i] = true;
    p.uv[i] = uv[i];
    p.covariance[i] = sigma_px * sigma_px * Eigen::Matrix2d::Identity();
  }
  return p;
}

}  // namespace marker_prediction
