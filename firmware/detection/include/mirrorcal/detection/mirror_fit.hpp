// Which plane mirror explains where a rig's markers appear. The camera sees marker i, fixed at p_i
// in its frame, at its mirror image in the plane (MirrorInCamera: the plane's normal n in the
// camera frame and the camera's height h above it), so a labelling of the blobs in one frame
// leaves only those 3 degrees of freedom to fit. A wrong labelling of identical LEDs asks for a
// mirror no plane is: the fit's residual tells them apart before the filter's prediction is sharp
// (marker_identifier.hpp). Header-only; nothing allocates.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>

#include "mirrorcal/estimator/mirror_model.hpp"
#include "mirrorcal/estimator/prior.hpp"

namespace mirrorcal::detection {

// What the fit knows of the rig: the markers in the camera frame (the priors' guesses, or the
// calibration's), how far they may be off, and the camera.
template <int M>
struct RigGeometry {
  std::array<Eigen::Vector3d, M> markers_c{};
  double marker_sigma_m = 0.01;  // 1-sigma of each coordinate
  Pinhole<double> camera{};
  double pixel_sigma = 1.0;
};

// The geometry the priors give: their guesses of the markers, the largest sigma of any of their
// coordinates, the camera the filter assumes and the pixel noise.
template <int M>
RigGeometry<M> prior_geometry(const Prior<M>& prior, const Pinhole<double>& camera,
                              double pixel_sigma) {
  RigGeometry<M> g;
  g.markers_c = prior.markers;
  g.marker_sigma_m = 0.0;
  for (const Eigen::Vector3d& s : prior.sigma_markers)
    g.marker_sigma_m = std::max(g.marker_sigma_m, s.maxCoeff());
  g.camera = camera;
  g.pixel_sigma = pixel_sigma;
  return g;
}

struct MirrorFit {
  bool made = false;  // at least two markers labelled, and a plane found that shows them
  // Sum of the squared residuals over their variances: chi-square with 2 n - 3 degrees of freedom
  // for n markers at the right labels and the right plane. 0 with fewer than two markers (any
  // mirror shows one), infinite when no plane in front of the camera shows them.
  double cost = 0.0;
  MirrorInCamera<double> mirror{Eigen::Vector3d(0, 0, -1), 0.5};
};

namespace mirror_fit_detail {

// Residuals of the mirror (n, h) for the labelled markers, each over its sigma (the pixel noise
// and the marker's own uncertainty seen at its image's depth); false if an image falls behind the
// camera.
template <int M>
bool residuals(const RigGeometry<M>& g, const std::array<bool, M>& seen,
               const std::array<Eigen::Vector2d, M>& uv, const MirrorInCamera<double>& m,
               Eigen::Matrix<double, 2 * M, 1>& r) {
  const double f = 0.5 * (g.camera.fu + g.camera.fv);
  r.setZero();
  for (int i = 0; i < M; ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (!seen[k]) continue;
    const Eigen::Vector3d image = m.image(g.markers_c[k]);
    Eigen::Vector2d p;
    if (!project(g.camera, image, p)) return false;
    const double spread = f * g.marker_sigma_m / image.z();
    const double sigma = std::sqrt(g.pixel_sigma * g.pixel_sigma + spread * spread);
    r.template segment<2>(2 * i) = (p - uv[k]) / sigma;
  }
  return true;
}

// The mirror moved by d = (a, b, dh): the normal tilted along two directions across it.
inline MirrorInCamera<double> moved(const MirrorInCamera<double>& m, const Eigen::Vector3d& d) {
  const Eigen::Vector3d& n = m.normal_c;
  const Eigen::Vector3d t1 = n.unitOrthogonal(), t2 = n.cross(t1);
  return {(n + d.x() * t1 + d.y() * t2).normalized(), m.height + d.z()};
}

// Levenberg-Marquardt from one start; the cost it ends at (infinity if the start shows nothing).
template <int M>
double refine(const RigGeometry<M>& g, const std::array<bool, M>& seen,
              const std::array<Eigen::Vector2d, M>& uv, MirrorInCamera<double>& m) {
  Eigen::Matrix<double, 2 * M, 1> r, rd;
  if (!residuals<M>(g, seen, uv, m, r)) return std::numeric_limits<double>::infinity();
  double cost = r.squaredNorm(), lambda = 1e-3;
  for (int iteration = 0; iteration < 20; ++iteration) {
    Eigen::Matrix<double, 2 * M, 3> jac;
    const double steps[3] = {1e-6, 1e-6, 1e-6 * std::max(m.height, 0.01)};
    for (int c = 0; c < 3; ++c) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      d(c) = steps[c];
      if (!residuals<M>(g, seen, uv, moved(m, d), rd)) return cost;
      jac.col(c) = (rd - r) / steps[c];
    }
    const Eigen::Matrix3d jtj = jac.transpose() * jac;
    const Eigen::Vector3d jtr = jac.transpose() * r;
    bool improved = false;
    while (lambda < 1e6) {
      Eigen::Matrix3d a = jtj;
      a.diagonal() *= 1.0 + lambda;
      const MirrorInCamera<double> next = moved(m, -a.ldlt().solve(jtr));
      if (next.height > 0.0 && residuals<M>(g, seen, uv, next, rd) && rd.squaredNorm() < cost) {
        const double gain = cost - rd.squaredNorm();
        m = next;
        r = rd;
        cost = rd.squaredNorm();
        lambda = std::max(lambda * 0.3, 1e-9);
        improved = gain > 1e-9 * (1.0 + cost);
        break;
      }
      lambda *= 10.0;
    }
    if (!improved) break;
  }
  return cost;
}

}  // namespace mirror_fit_detail

// The plane mirror that best shows the labelled markers (seen) at uv: Levenberg-Marquardt over
// (n, h) from five starts, the camera facing the mirror square and tilted 35 deg either way about
// its x and y axes, the height from the labelled pair furthest apart in the image.
template <int M>
MirrorFit fit_mirror(const RigGeometry<M>& g, const std::array<bool, M>& seen,
                     const std::array<Eigen::Vector2d, M>& uv) {
  MirrorFit best;
  int a = -1, b = -1, n = 0;
  double widest = 0.0;
  for (int i = 0; i < M; ++i) {
    if (!seen[static_cast<std::size_t>(i)]) continue;
    ++n;
    for (int j = 0; j < i; ++j)
      if (seen[static_cast<std::size_t>(j)]) {
        const double d = (uv[static_cast<std::size_t>(i)] - uv[static_cast<std::size_t>(j)]).norm();
        if (d > widest) {
          widest = d;
          a = i;
          b = j;
        }
      }
  }
  if (n < 2 || !(widest > 1.0)) return best;
  // Markers a and b, a distance D apart, appear D f / (2 h) apart when the mirror is square on.
  const double f = 0.5 * (g.camera.fu + g.camera.fv);
  const double apart =
      (g.markers_c[static_cast<std::size_t>(a)] - g.markers_c[static_cast<std::size_t>(b)]).norm();
  const double height = std::max(0.5 * f * apart / widest, 0.05);
  constexpr double kTilt = 0.61;  // 35 deg
  const Eigen::Vector3d starts[5] = {{0, 0, -1},
                                     {std::sin(kTilt), 0, -std::cos(kTilt)},
                                     {-std::sin(kTilt), 0, -std::cos(kTilt)},
                                     {0, std::sin(kTilt), -std::cos(kTilt)},
                                     {0, -std::sin(kTilt), -std::cos(kTilt)}};
  best.cost = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3d& normal : starts) {
    MirrorInCamera<double> m{normal, height};
    const double cost = mirror_fit_detail::refine<M>(g, seen, uv, m);
    if (cost < best.cost) {
      best.made = true;
      best.cost = cost;
      best.mirror = m;
    }
  }
  return best;
}

}  // namespace mirrorcal::detection
