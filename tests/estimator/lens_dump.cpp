// Prints, for each lens model, a grid of camera-frame points and the pixels mirrorcal's project()
// gives them, for lens_vs_opencv.py to compare with OpenCV's own projections. The grid spans the
// paper camera's image to beyond its corners (where distortion is largest), at several depths.
#include <cstdio>

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mc = mirrorcal;

int main() {
  const struct {
    mc::Distortion model;
    std::array<double, 4> coeffs;
  } lenses[] = {
      {mc::Distortion::kRadtan, {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05}},  // EuRoC
      {mc::Distortion::kRadtan, {0.1, -0.05, 0.002, -0.003}},
      {mc::Distortion::kEquidistant, {0.00348238, 0.000715034, -0.00205323, 0.000202936}},
      {mc::Distortion::kEquidistant, {0.05, -0.02, 0.01, -0.004}},
  };
  for (const auto& lens : lenses) {
    // cv::projectPoints has no skew (cv::fisheye's has, as alpha = skew / fu).
    const double skew = lens.model == mc::Distortion::kEquidistant ? 3.0 : 0.0;
    mc::Pinhole<double> k{833.33, 830.1, 322.0, 248.0, skew, lens.model, lens.coeffs};
    for (int i = -6; i <= 6; ++i)
      for (int j = -5; j <= 5; ++j)
        for (const double z : {0.3, 1.0, 2.5}) {
          // Up to 1.25 times the corner's ray: (320, 240) px off the centre at f = 833 px.
          const double x = 1.25 * (320.0 / 833.33) * i / 6.0, y = 1.25 * (240.0 / 830.1) * j / 5.0;
          const Eigen::Vector3d p(x * z, y * z, z);
          Eigen::Vector2d uv;
          if (!mc::project<double>(k, p, uv)) return 1;
          std::printf(
              "%s %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g "
              "%.17g\n",
              mc::to_string(k.distortion), k.fu, k.fv, k.cu, k.cv, k.skew, k.coeffs[0], k.coeffs[1],
              k.coeffs[2], k.coeffs[3], p.x(), p.y(), p.z(), uv.x(), uv.y());
        }
  }
  return 0;
}
