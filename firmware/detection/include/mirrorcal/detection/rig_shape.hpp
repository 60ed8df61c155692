// The rig's shape from its mirror images alone, for identical LEDs under loose priors. Over K
// frames of the same M reflections, tracked from frame to frame but not yet named, the markers'
// places in the camera frame and each frame's plane mirror are fitted jointly (bundle adjustment
// over 3 M + 3 K unknowns). The mirror images alone do not fix the rig's scale (the rig twice as
// large before a mirror twice as far looks the same), nor which track is which marker: both come
// from the priors' guesses. Each hypothesis of the names is fitted with its guesses as the prior,
// and the likeliest names the tracks (shape_bootstrap.hpp keeps the names over frames).
// Header-only; nothing allocates.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "mirrorcal/detection/mirror_fit.hpp"

namespace mirrorcal::detection {

// K frames of M tracks: uv[k][j] is track j's reflection in frame k (every track in every frame).
template <int M, int K>
struct TrackWindow {
  std::array<std::array<Eigen::Vector2d, M>, K> uv{};
};

template <int M>
struct RigShape {
  bool made = false;  // the fit converged and explains the tracks as one rig's reflections
  // The fit's chi-square (reprojections and the priors' term) and its degrees of freedom
  // (2 M K - 3 K: 2 M K residuals and 3 M priors, less 3 M markers and 3 K mirrors).
  double cost = std::numeric_limits<double>::infinity();
  int dof = 0;
  // label_of_track[j]: the marker track j is, by the priors' guesses.
  std::array<int, M> label_of_track{};
  // How much better the chosen names fit the guesses than the next best (their chi-square's
  // difference, 3 M dof): small when the guesses cannot tell two markers apart. The labels are
  // then consistent over frames but their names a guess.
  double naming_margin = 0.0;
  // The markers by label, with the largest sigma of any of their coordinates.
  RigGeometry<M> geometry{};
};

namespace rig_shape_detail {

template <int M>
using Markers = std::array<Eigen::Vector3d, M>;

// One hypothesis of the tracks' names: guess[j] is the priors' guess of the marker track j is.
template <int M, int K>
struct Problem {
  const RigGeometry<M>* prior_ = nullptr;
  const TrackWindow<M, K>* tracks_ = nullptr;
  Markers<M> guess{};
  const RigGeometry<M>& prior() const { return *prior_; }
  const TrackWindow<M, K>& tracks() const { return *tracks_; }
};
template <int K>
using Mirrors = std::array<MirrorInCamera<double>, K>;

// Frame k's residuals (px over pixel sigma) for markers p; false if a reflection is behind the
// camera.
template <int M, int K>
bool frame_residuals(const Problem<M, K>& pb, const Markers<M>& p, const MirrorInCamera<double>& m,
                     int k, Eigen::Matrix<double, 2 * M, 1>& r) {
  for (int j = 0; j < M; ++j) {
    Eigen::Vector2d uv;
    if (!project(pb.prior().camera, m.image(p[std::size_t(j)]), uv)) return false;
    r.template segment<2>(2 * j) =
        (uv - pb.tracks().uv[std::size_t(k)][std::size_t(j)]) / pb.prior().pixel_sigma;
  }
  return true;
}

// The priors' term: how far the markers lie from the hypothesis' guesses, over their sigma.
template <int M, int K>
double prior_cost(const Problem<M, K>& pb, const Markers<M>& p) {
  double cost = 0.0;
  for (int j = 0; j < M; ++j) cost += (p[std::size_t(j)] - pb.guess[std::size_t(j)]).squaredNorm();
  return cost / (pb.prior().marker_sigma_m * pb.prior().marker_sigma_m);
}

template <int M, int K>
double total_cost(const Problem<M, K>& pb, const Markers<M>& p, const Mirrors<K>& mirrors) {
  double cost = 0.0;
  Eigen::Matrix<double, 2 * M, 1> r;
  for (int k = 0; k < K; ++k) {
    if (mirrors[std::size_t(k)].height <= 0.0 ||
        !frame_residuals<M, K>(pb, p, mirrors[std::size_t(k)], k, r))
      return std::numeric_limits<double>::infinity();
    cost += r.squaredNorm();
  }
  return cost + prior_cost<M, K>(pb, p);
}

// The normal equations, split into the markers' block and each frame's mirror block, so that the
// step is solved on the markers' Schur complement (3 M unknowns) whatever K is.
template <int M, int K>
struct Normal {
  Eigen::Matrix<double, 3 * M, 3 * M> hpp;
  Eigen::Matrix<double, 3 * M, 1> bp;
  std::array<Eigen::Matrix<double, 3 * M, 3>, K> hpm;
  std::array<Eigen::Matrix3d, K> hmm;
  std::array<Eigen::Vector3d, K> bm;
};

// Forward-difference Jacobians: a marker's coordinates move its reflection in every frame, a
// frame's mirror every reflection of that frame.
template <int M, int K>
void linearise(const Problem<M, K>& pb, const Markers<M>& p, const Mirrors<K>& mirrors,
               Normal<M, K>& ne) {
  constexpr double kStep = 1e-7;
  ne.hpp.setZero();
  ne.bp.setZero();
  Eigen::Matrix<double, 2 * M, 1> r, rd;
  for (int k = 0; k < K; ++k) {
    const MirrorInCamera<double>& m = mirrors[std::size_t(k)];
    frame_residuals<M, K>(pb, p, m, k, r);
    Eigen::Matrix<double, 2 * M, 3 * M> jp;
    Eigen::Matrix<double, 2 * M, 3> jm;
    for (int c = 0; c < 3 * M; ++c) {
      Markers<M> moved_p = p;
      moved_p[std::size_t(c / 3)](c % 3) += kStep;
      frame_residuals<M, K>(pb, moved_p, m, k, rd);
      jp.col(c) = (rd - r) / kStep;
    }
    for (int c = 0; c < 3; ++c) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      d(c) = c == 2 ? kStep * m.height : kStep;
      frame_residuals<M, K>(pb, p, mirror_fit_detail::moved(m, d), k, rd);
      jm.col(c) = (rd - r) / d(c);
    }
    ne.hpp.noalias() += jp.transpose() * jp;
    ne.bp.noalias() += jp.transpose() * r;
    ne.hpm[std::size_t(k)] = jp.transpose() * jm;
    ne.hmm[std::size_t(k)] = jm.transpose() * jm;
    ne.bm[std::size_t(k)] = jm.transpose() * r;
  }
  const double var = pb.prior().marker_sigma_m * pb.prior().marker_sigma_m;
  ne.hpp.diagonal().array() += 1.0 / var;
  for (int j = 0; j < M; ++j)
    ne.bp.template segment<3>(3 * j) += (p[std::size_t(j)] - pb.guess[std::size_t(j)]) / var;
}

// Levenberg-Marquardt over the markers and the mirrors; returns the cost it ends at.
template <int M, int K>
double bundle_adjust(const Problem<M, K>& pb, Markers<M>& p, Mirrors<K>& mirrors,
                     Eigen::Matrix<double, 3 * M, 3 * M>* marker_information) {
  double cost = total_cost<M, K>(pb, p, mirrors), lambda = 1e-3;
  Normal<M, K> ne;
  for (int iteration = 0; iteration < 200 && std::isfinite(cost); ++iteration) {
    linearise<M, K>(pb, p, mirrors, ne);
    bool improved = false;
    while (lambda < 1e8) {
      Eigen::Matrix<double, 3 * M, 3 * M> s = ne.hpp;
      s.diagonal() *= 1.0 + lambda;
      Eigen::Matrix<double, 3 * M, 1> rhs = ne.bp;
      std::array<Eigen::Matrix3d, K> hmm_inv;
      for (int k = 0; k < K; ++k) {
        Eigen::Matrix3d a = ne.hmm[std::size_t(k)];
        a.diagonal() *= 1.0 + lambda;
        hmm_inv[std::size_t(k)] = a.inverse();
        s.noalias() -=
            ne.hpm[std::size_t(k)] * hmm_inv[std::size_t(k)] * ne.hpm[std::size_t(k)].transpose();
        rhs.noalias() -= ne.hpm[std::size_t(k)] * (hmm_inv[std::size_t(k)] * ne.bm[std::size_t(k)]);
      }
      const Eigen::Matrix<double, 3 * M, 1> dp = -s.ldlt().solve(rhs);
      Markers<M> next_p = p;
      for (int j = 0; j < M; ++j) next_p[std::size_t(j)] += dp.template segment<3>(3 * j);
      Mirrors<K> next_m = mirrors;
      for (int k = 0; k < K; ++k) {
        const Eigen::Vector3d dm =
            -hmm_inv[std::size_t(k)] *
            (ne.bm[std::size_t(k)] + ne.hpm[std::size_t(k)].transpose() * dp);
        next_m[std::size_t(k)] = mirror_fit_detail::moved(mirrors[std::size_t(k)], dm);
      }
      const double next = total_cost<M, K>(pb, next_p, next_m);
      if (next < cost) {
        improved = cost - next > 1e-9 * (1.0 + next);
        p = next_p;
        mirrors = next_m;
        cost = next;
        lambda = std::max(lambda * 0.3, 1e-12);
        break;
      }
      lambda *= 10.0;
    }
    if (!improved) break;
  }
  if (marker_information != nullptr && std::isfinite(cost)) {
    linearise<M, K>(pb, p, mirrors, ne);
    Eigen::Matrix<double, 3 * M, 3 * M> s = ne.hpp;
    for (int k = 0; k < K; ++k)
      s.noalias() -= ne.hpm[std::size_t(k)] * ne.hmm[std::size_t(k)].inverse() *
                     ne.hpm[std::size_t(k)].transpose();
    *marker_information = s;
  }
  return cost;
}

// Every permutation of 0..M-1 (M! of them; 720 at M = 6), in lexicographic order.
template <int M, class F>
void for_each_permutation(F&& f) {
  std::array<int, M> perm{};
  std::iota(perm.begin(), perm.end(), 0);
  do {
    f(perm);
  } while (std::next_permutation(perm.begin(), perm.end()));
}

// The largest standard deviation of any marker's coordinate.
template <int M>
double largest_sigma(const Eigen::Matrix<double, 3 * M, 3 * M>& information) {
  const Eigen::Matrix<double, 3 * M, 3 * M> cov =
      information.ldlt().solve(Eigen::Matrix<double, 3 * M, 3 * M>::Identity());
  return std::sqrt(std::max(cov.diagonal().maxCoeff(), 0.0));
}

// One hypothesis' adjustment: its markers, mirrors and cost.
template <int M, int K>
struct Fit {
  Fit() { mirrors.fill(MirrorFit{}.mirror); }
  double cost = std::numeric_limits<double>::infinity();
  Markers<M> p{};
  Mirrors<K> mirrors;
};

// The adjustment from the markers p: each frame's mirror fitted to them first, from its five
// starts. A frame's mirror fitted to the guesses may settle in the wrong tilt, so the mirrors are
// refitted to the adjusted markers and the adjustment rerun while that lowers the cost.
template <int M, int K>
Fit<M, K> adjust_from(const Problem<M, K>& pb, const Markers<M>& p) {
  Fit<M, K> fit;
  fit.p = p;
  RigGeometry<M> by_track = pb.prior();
  std::array<bool, M> all{};
  all.fill(true);
  for (int round = 0; round < 4; ++round) {
    by_track.markers_c = fit.p;
    Fit<M, K> next = fit;
    for (int k = 0; k < K; ++k) {
      const MirrorFit f = fit_mirror<M>(by_track, all, pb.tracks().uv[std::size_t(k)]);
      if (f.made)
        next.mirrors[std::size_t(k)] = f.mirror;
      else if (round == 0)
        return fit;  // no mirror shows this frame's reflections
    }
    next.cost = bundle_adjust<M, K>(pb, next.p, next.mirrors, nullptr);
    if (!(next.cost < fit.cost - 1e-6 * (1.0 + next.cost))) break;
    fit = next;
  }
  return fit;
}

// The adjustment from the guesses moved together by a sigma along each axis: its valleys run
// along the rig's common offset, which the mirror sees least.
template <int M, int K>
Fit<M, K> adjust_from_offsets(const Problem<M, K>& pb, Fit<M, K> fit) {
  for (int start = 0; start < 6; ++start) {
    Eigen::Vector3d offset = Eigen::Vector3d::Zero();
    offset(start / 2) = (start % 2 == 0 ? 1.0 : -1.0) * pb.prior().marker_sigma_m;
    Markers<M> p = pb.guess;
    for (Eigen::Vector3d& x : p) x += offset;
    const Fit<M, K> f = adjust_from<M, K>(pb, p);
    if (f.cost < fit.cost) fit = f;
  }
  return fit;
}

// The two likeliest hypotheses so far, by their fit's cost and naming cost, with their fits.
template <int M, int K>
struct Likeliest {
  std::array<int, 2> h{-1, -1};
  std::array<Fit<M, K>, 2> fit{};
  std::array<double, 2> total{std::numeric_limits<double>::infinity(),
                              std::numeric_limits<double>::infinity()};

  // Hypothesis hyp's fit, at that total, takes its place among the two; its own earlier one
  // leaves.
  void offer(int hyp, const Fit<M, K>& f, double t) {
    if (h[0] == hyp) {
      h[0] = h[1];
      fit[0] = fit[1];
      total[0] = total[1];
      drop_second();
    }
    if (h[1] == hyp) drop_second();
    const int at = t < total[0] ? 0 : t < total[1] ? 1 : 2;
    if (at == 0) {
      h[1] = h[0];
      fit[1] = fit[0];
      total[1] = total[0];
    }
    if (at < 2) {
      h[std::size_t(at)] = hyp;
      fit[std::size_t(at)] = f;
      total[std::size_t(at)] = t;
    }
  }
  void drop_second() {
    h[1] = -1;
    total[1] = std::numeric_limits<double>::infinity();
  }
};

}  // namespace rig_shape_detail

// What names cost beyond the shape's fit: nothing.
struct NoNamingCost {
  template <class Names>
  double operator()(const Names&) const {
    return 0.0;
  }
};

// The rig's shape and names from K frames of tracked reflections (see the top of this file).
// prior: the guesses of the markers (by label), their sigma, the camera and the pixel noise.
// Each hypothesis of the names is fitted with its guesses as the prior (the maximum a
// posteriori shape); the likeliest wins, its likelihood the fit's and naming_cost(names) (another
// cue's, -2 log: the LEDs' brightness code), names[j] the marker track j is. The hypotheses: every
// permutation up to M = 4, else the kHypotheses whose guesses best explain the first frame.
template <int M, int K, class NamingCost = NoNamingCost>
RigShape<M> fit_rig_shape(const RigGeometry<M>& prior, const TrackWindow<M, K>& tracks,
                          const NamingCost& naming_cost = {}) {
  namespace d = rig_shape_detail;
  constexpr int kHypotheses = 24;
  std::array<std::array<int, M>, kHypotheses> names{};
  std::array<double, kHypotheses> first_cost{};
  first_cost.fill(std::numeric_limits<double>::infinity());
  std::array<bool, M> all{};
  all.fill(true);
  d::for_each_permutation<M>([&](const std::array<int, M>& perm) {
    std::array<Eigen::Vector2d, M> uv;
    for (int j = 0; j < M; ++j)
      uv[std::size_t(perm[std::size_t(j)])] = tracks.uv[0][std::size_t(j)];
    const double c = fit_mirror<M>(prior, all, uv).cost + naming_cost(perm);
    int at = kHypotheses;
    while (at > 0 && c < first_cost[std::size_t(at - 1)]) --at;
    if (at == kHypotheses) return;
    for (int t = kHypotheses - 1; t > at; --t) {
      first_cost[std::size_t(t)] = first_cost[std::size_t(t - 1)];
      names[std::size_t(t)] = names[std::size_t(t - 1)];
    }
    first_cost[std::size_t(at)] = c;
    names[std::size_t(at)] = perm;
  });

  // Every hypothesis adjusted from its guesses (their costs kept); the two likeliest again from
  // six starts more.
  const auto problem = [&](int h) {
    d::Problem<M, K> pb;
    pb.prior_ = &prior;
    pb.tracks_ = &tracks;
    for (int j = 0; j < M; ++j)
      pb.guess[std::size_t(j)] =
          prior.markers_c[std::size_t(names[std::size_t(h)][std::size_t(j)])];
    return pb;
  };
  // cost: each hypothesis' fit and naming cost (a fit's own cost is the fit's alone).
  std::array<double, kHypotheses> cost{};
  cost.fill(std::numeric_limits<double>::infinity());
  d::Likeliest<M, K> top;
  const auto offer = [&](int h, const d::Fit<M, K>& f) {
    const double c = f.cost + naming_cost(names[std::size_t(h)]);
    if (!(c < cost[std::size_t(h)])) return;
    cost[std::size_t(h)] = c;
    top.offer(h, f, c);
  };
  for (int h = 0; h < kHypotheses; ++h)
    if (std::isfinite(first_cost[std::size_t(h)]))
      offer(h, d::adjust_from<M, K>(problem(h), problem(h).guess));
  const d::Likeliest<M, K> first = top;
  for (int r = 0; r < 2; ++r)
    if (first.h[std::size_t(r)] >= 0)
      offer(first.h[std::size_t(r)], d::adjust_from_offsets<M, K>(problem(first.h[std::size_t(r)]),
                                                                  first.fit[std::size_t(r)]));
  // The tracks' places do not depend on their names: every hypothesis is adjusted again from the
  // markers of the best fit so far, a valley its own starts may have missed. The priors' term and
  // the naming cost then tell the names apart.
  if (top.h[0] >= 0) {
    const d::Markers<M> valley = (top.fit[1].cost < top.fit[0].cost ? top.fit[1] : top.fit[0]).p;
    for (int h = 0; h < kHypotheses; ++h)
      if (std::isfinite(first_cost[std::size_t(h)]))
        offer(h, d::adjust_from<M, K>(problem(h), valley));
  }
  const int h_best = top.h[0];

  RigShape<M> best;
  // 2 M K residuals and 3 M priors, less 3 M markers and 3 K mirrors.
  best.dof = 2 * M * K - 3 * K;
  if (h_best < 0) return best;
  const d::Fit<M, K>& chosen = top.fit[0];
  best.cost = chosen.cost;
  best.label_of_track = names[std::size_t(h_best)];
  double runner_up = std::numeric_limits<double>::infinity();
  for (int h = 0; h < kHypotheses; ++h)
    if (h != h_best) runner_up = std::min(runner_up, cost[std::size_t(h)]);
  best.naming_margin = runner_up - top.total[0];
  // One rig's reflections fit to their chi-square; a track that is no marker's (a room light
  // drifting across the image) does not (mean plus four standard deviations).
  if (!(best.cost < best.dof + 4.0 * std::sqrt(2.0 * best.dof))) return best;
  d::Fit<M, K> final_fit = chosen;
  Eigen::Matrix<double, 3 * M, 3 * M> information;
  d::bundle_adjust<M, K>(problem(h_best), final_fit.p, final_fit.mirrors, &information);
  best.geometry = prior;
  for (int j = 0; j < M; ++j)
    best.geometry.markers_c[std::size_t(best.label_of_track[std::size_t(j)])] =
        final_fit.p[std::size_t(j)];
  best.geometry.marker_sigma_m = d::largest_sigma<M>(information);
  best.made = true;
  return best;
}

}  // namespace mirrorcal::detection
