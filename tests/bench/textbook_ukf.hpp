// A textbook unscented Kalman filter of the same model: the baseline the benchmark measures
// mirrorcal's filter against, in the same run on the same inputs, so that the ratio cannot rot.
// Everything the filter's structure would spare it, it does: every state is sampled in predict
// and in update (2N + 1 points of the scaled unscented transform, alpha 1, beta 2, kappa 0), the
// calibration's constants are carried through the propagation like any state, the statistics are
// full N x N products and the gain a general solve (Eigen's kernels). The manifold is handled as
// the filter does: points are the mean boxplus the columns of gamma times the Cholesky factor, and
// their spread is taken in the tangent space at the propagated centre.
#pragma once

#include <Eigen/Cholesky>
#include <array>
#include <cstddef>

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal::bench {

template <class State>
class TextbookUkf {
 public:
  using S = typename State::Scalar;
  static constexpr int N = State::kDim;
  using Covariance = Eigen::Matrix<S, N, N>;
  using Vector = Eigen::Matrix<S, N, 1>;
  // The points' offsets, N x 2N: fixed-size while Eigen allows such an object (M = 3, 6, 12), of
  // dynamic width beyond (M = 24: 141 KB in double), allocated once with the filter.
  static constexpr bool kFixedDeltas =
      std::size_t(N) * 2 * N * sizeof(S) <= std::size_t(EIGEN_STACK_ALLOCATION_LIMIT);
  using Deltas = Eigen::Matrix<S, N, kFixedDeltas ? 2 * N : Eigen::Dynamic>;

  TextbookUkf() : deltas_(N, 2 * N), spread_(N, 2 * N) {}

  void reset(const State& x, const Covariance& p) {
    x_ = x;
    p_ = p;
  }
  const State& state() const { return x_; }
  const Covariance& covariance() const { return p_; }

  // Every point through propagate(State&); q is the process noise. False if P is not positive
  // definite.
  template <class Propagate>
  bool predict(Propagate&& propagate, const Covariance& q) {
    if (!draw_points()) return false;
    State centre = x_;
    propagate(centre);
    for (int i = 0; i < 2 * N; ++i) {
      State point = points_[static_cast<std::size_t>(i)];
      propagate(point);
      deltas_.col(i) = point.template boxminus_block<0, N>(centre);
    }
    const Vector mean = deltas_.rowwise().sum() * weight_;  // the centre's weight is 0
    spread_ = deltas_.colwise() - mean;
    p_ = centre_weight_c_ * mean * mean.transpose() + weight_ * spread_ * spread_.transpose() + q;
    x_ = centre;
    x_.template boxplus_block<0, N>(mean);
    return true;
  }

  // z = measure(State, z, ok) with noise variance r on each row; false if a point is outside the
  // measurement's domain or a factorisation fails.
  template <int Z, class Measure>
  bool update(Measure&& measure, const Eigen::Matrix<S, Z, 1>& z, const S r) {
    using ZVec = Eigen::Matrix<S, Z, 1>;
    if (!draw_points()) return false;
    Eigen::Matrix<S, Z, 2 * N + 1> images;
    bool ok = true;
    ZVec zi;
    measure(x_, zi, ok);
    images.col(2 * N) = zi;
    for (int i = 0; i < 2 * N; ++i) {
      measure(points_[static_cast<std::size_t>(i)], zi, ok);
      images.col(i) = zi;
    }
    if (!ok) return false;
    const ZVec mean = images.template leftCols<2 * N>().rowwise().sum() * weight_ +
                      centre_weight_m_ * images.col(2 * N);
    const Eigen::Matrix<S, Z, 2 * N + 1> spread = images.colwise() - mean;
    Eigen::Matrix<S, Z, Z> p_zz =
        weight_ * spread.template leftCols<2 * N>() *
            spread.template leftCols<2 * N>().transpose() +
        centre_weight_c_ * spread.col(2 * N) * spread.col(2 * N).transpose();
    p_zz.diagonal().array() += r;
    // The points' offsets from the mean are the deltas draw_points made (the centre's is zero).
    const Eigen::Matrix<S, N, Z> p_xz =
        weight_ * deltas_ * spread.template leftCols<2 * N>().transpose();
    const Eigen::LLT<Eigen::Matrix<S, Z, Z>> llt(p_zz);
    if (llt.info() != Eigen::Success) return false;
    const Eigen::Matrix<S, N, Z> gain = llt.solve(p_xz.transpose()).transpose();
    x_.template boxplus_block<0, N>(gain * (z - mean));
    p_ -= gain * p_zz * gain.transpose();
    p_ = (S(0.5) * (p_ + p_.transpose())).eval();
    return true;
  }

 private:
  // points_ = mean boxplus +-gamma L's columns, deltas_ their offsets.
  bool draw_points() {
    const Eigen::LLT<Covariance> llt(p_);
    if (llt.info() != Eigen::Success) return false;
    const Covariance l = llt.matrixL();
    for (int j = 0; j < N; ++j)
      for (int sign = 0; sign < 2; ++sign) {
        const int i = 2 * j + sign;
        deltas_.col(i) = (sign == 0 ? gamma_ : -gamma_) * l.col(j);
        State& point = points_[static_cast<std::size_t>(i)];
        point = x_;
        point.template boxplus_block<0, N>(Vector(deltas_.col(i)));
      }
    return true;
  }

  // alpha 1, beta 2, kappa 0: lambda = alpha^2 (N + kappa) - N = 0.
  const S gamma_ = std::sqrt(S(N));
  const S weight_ = S(1) / S(2 * N);
  const S centre_weight_m_ = S(0);
  const S centre_weight_c_ = S(2);  // lambda / (N + lambda) + 1 - alpha^2 + beta
  State x_{};
  Covariance p_ = Covariance::Identity();
  std::array<State, 2 * N> points_{};
  Deltas deltas_, spread_;
};

}  // namespace mirrorcal::bench
