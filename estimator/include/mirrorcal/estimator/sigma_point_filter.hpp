// A fixed-dimension error-state sigma-point (unscented) Kalman filter on a manifold.
//
// The state type supplies the manifold: its error-state dimension kDim and
//   template <int B, int L> void boxplus_block(const Eigen::Matrix<Scalar, L, 1>& d);
//   template <int B, int L> Eigen::Matrix<Scalar, L, 1> boxminus_block(const State& ref) const;
// which add a tangent perturbation to, and take the tangent difference of, the error-state block
// [B, B+L). The mean is propagated directly, sigma points are tangent perturbations of it, and
// deviations come back through boxminus: quaternions are never averaged (UKF-M style).
//
// Structure is exploited by blocks. A predict names the block its dynamics change (the rest is
// constant); an update names the block its measurement reads. Sigma points span only that block,
// and the rest of the state is carried by the statistical linear regression of the transform:
// with P_bb = L L^T and D the central differences of the outputs along the columns of L, the
// regression matrix is D L^-1. For the cross-covariances this is exactly what a full-state
// unscented transform computes (the full Cholesky factor, ordered block first, perturbs the other
// states only through the block's columns), at a fraction of the cost.
//
// No heap, no exceptions, no OS calls: every matrix is fixed-size; numerical failures are
// returned as a status and leave the filter unchanged.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstdint>
#include <new>

namespace mirrorcal {

// Storage for an operation's large temporaries: one T per thread, in static (thread-local)
// storage, neither on the stack nor in the filter object. Fixed-size matrices grow with the square
// of the state, and the update's reach 0.8 MB at 24 markers, which no stack frame should hold
// (the target is 64 KiB), while the filter object should stay small (32 KiB). T names its user
// (a workspace type of its own per operation and configuration), so users never share one; the
// operation must not be re-entered on the same thread while it uses it (it calls nothing that
// could). The object is built in raw storage at first use and never destroyed: a thread_local
// object with a destructor would register it with the thread at first use, which allocates, and
// the fixed-size matrices and factorisations held here release nothing.
template <class T>
T& thread_workspace() {
  alignas(T) static thread_local unsigned char storage[sizeof(T)];
  static thread_local T* workspace = nullptr;
  if (workspace == nullptr) workspace = ::new (static_cast<void*>(storage)) T;
  return *workspace;
}

// Small dense kernels for the update's fixed sizes (a block of 15-30 states, 2M measurement
// rows). Eigen's triangular solves and LLT run general blocked kernels, whose calls and packing
// cost more than the arithmetic at these sizes. These loops run along contiguous columns, and the
// factor stays a plain matrix that predict's check uses too. Measured alone under callgrind
// (docs/performance.md): the factorisation 9.1k instructions at 22 states (Eigen's LLT about
// 12k), 4.7k at 15; the regression's solve at 22 states and 6 rows 4.5k.

// The lower Cholesky factor of m, in place, its strict upper triangle zeroed (left-looking, one
// column at a time); false if m is not positive definite (or holds a NaN). Column j takes the
// earlier columns four at a time, then two, then one: one pass over column j per four, since at
// these sizes a pass's loop control costs more than its arithmetic (one column per pass: 12.9k
// instructions at 22 states). A caller that only asks whether m is positive definite leaves the
// upper triangle as it was (kZeroUpper false): the factorisation reads only the lower one.
template <bool kZeroUpper = true, class Mat>
bool cholesky_in_place(Mat& m) {
  using S = typename Mat::Scalar;
  constexpr int n = Mat::RowsAtCompileTime;
  for (int j = 0; j < n; ++j) {
    S* cj = &m(0, j);
    int k = 0;
    for (; k + 4 <= j; k += 4) {
      const S *c0 = &m(0, k), *c1 = c0 + n, *c2 = c1 + n, *c3 = c2 + n;
      const S f0 = c0[j], f1 = c1[j], f2 = c2[j], f3 = c3[j];
      for (int i = j; i < n; ++i) cj[i] -= c0[i] * f0 + c1[i] * f1 + c2[i] * f2 + c3[i] * f3;
    }
    if (k + 2 <= j) {
      const S *c0 = &m(0, k), *c1 = c0 + n;
      const S f0 = c0[j], f1 = c1[j];
      for (int i = j; i < n; ++i) cj[i] -= c0[i] * f0 + c1[i] * f1;
      k += 2;
    }
    if (k < j) {
      const S* c0 = &m(0, k);
      const S f0 = c0[j];
      for (int i = j; i < n; ++i) cj[i] -= c0[i] * f0;
    }
    if (!(cj[j] > S(0))) return false;
    const S d = std::sqrt(cj[j]);
    cj[j] = d;
    for (int i = j + 1; i < n; ++i) cj[i] /= d;
    if constexpr (kZeroUpper)
      for (int i = 0; i < j; ++i) cj[i] = S(0);
  }
  return true;
}

// x <- x l^-1 for a lower triangular l (x l = rhs, backward over the columns of x). A column of
// x is a few measurement rows: each step is a short fixed-length multiply-add, held in registers
// (the same solve as l^-T x^T by back substitution, whose inner loop is a reduction the compiler
// cannot vectorise without reassociating: 8.4k instructions at 22 states and 6 rows).
template <class Lower, class Rhs>
void solve_right_lower(const Lower& l, Rhs& x) {
  constexpr int n = Lower::RowsAtCompileTime;
  using Column = Eigen::Matrix<typename Lower::Scalar, Rhs::RowsAtCompileTime, 1>;
  for (int i = n - 1; i >= 0; --i) {
    Column sum = x.col(i);
    for (int k = i + 1; k < n; ++k) sum -= l(k, i) * x.col(k);
    x.col(i) = sum / l(i, i);
  }
}

// x <- x l^-T for a lower triangular l (x l^T = rhs, forward over the columns of x).
template <class Lower, class Rhs>
void solve_right_lower_transposed(const Lower& l, Rhs& x) {
  constexpr int n = Lower::RowsAtCompileTime;
  for (int j = 0; j < n; ++j) {
    for (int k = 0; k < j; ++k) x.col(j) -= l(j, k) * x.col(k);
    x.col(j) /= l(j, j);
  }
}

// Scaled unscented transform (Julier 2002). With n the dimension of the sampled block:
//   lambda = alpha^2 (n + kappa) - n, sigma points at the mean and at +-gamma times the columns of
//   the Cholesky factor, gamma = sqrt(n + lambda) = alpha sqrt(n + kappa), mean weights
//   lambda/(n+lambda) (centre) and 1/(2(n+lambda)) (others), and the centre's covariance weight
//   lambda/(n+lambda) + 1 - alpha^2 + beta.
// With y0 the centre's image and y+-j those of the pair j, write a_j = (y+j - y-j)/2 and
// b_j = (y+j + y-j)/2 - y0. The transform's mean is y0 + sum(b_j)/gamma^2 and, collecting terms,
// its covariance is exactly
//   sum(a_j a_j^T)/gamma^2 + sum(b_j b_j^T)/gamma^2 + (beta - alpha^2) d d^T,  d = mean - y0,
// which is how it is computed here: a sum of Gram matrices, positive semi-definite for any alpha
// and kappa as long as beta >= alpha^2, whereas the textbook weighted sum with a negative centre
// weight can lose definiteness in rounding (as robot_localization found).
// The default alpha = 1 (gamma = sqrt(n)) spreads the points widest: over the wide priors of the
// first frames, where the measurement's higher-order terms matter, points far out see them and the
// filter stays honest; narrower spreads were less so (docs/estimator.md, "The update"). No point
// crosses the mirror there: a marker's mirror image lies about twice the mirror distance away,
// beyond any 4.6-sigma offset of a 10 cm prior.
// beta = 2 is optimal for Gaussian priors.
struct UnscentedParams {
  double alpha = 1.0;
  double beta = 2.0;
  double kappa = 0.0;
};

// The filter's numerical settings: the transform, and when to split an update (see update()).
struct SigmaPointParams {
  UnscentedParams unscented{};
  // An update is split into steps, at most max_steps, so that no step but the last sees a ratio
  // (largest predicted measurement variance of the blocks used) / (its noise variance) above
  // spread_per_step: a step shrinks the measurement's spread by at most 1 + spread_per_step.
  // Smaller values also split steady-state updates, each step counting the linearisation's error
  // again, and were less consistent (docs/estimator.md, "The update"; tested by
  // SigmaPointUpdate.ProgressiveStepsFollowAStronglyNonlinearMeasurement, sigma_point_test.cpp).
  double spread_per_step = 100.0;
  int max_steps = 20;
  // A sigma point outside the measurement's domain (a camera behind the mirror, drawn from a wide
  // prior on its distance) would drop every block it cannot evaluate; the transform is redrawn
  // with alpha halved instead, up to max_shrinks times, before a block is given up as invalid.
  int max_shrinks = 4;
  // An update whose predicted measurement spreads more than this many times its noise also takes
  // the second-order cross terms of the measurement (see add_cross_terms()).
  double cross_terms_above = 1.0;
  // An update linearised at a reference (linearise_at) draws its points with alpha times this:
  // 1 regresses the measurement over the filter's whole spread, a statistical linearisation that
  // pulls a Gauss-Newton iteration in from far off; a small value takes the measurement's local
  // slopes at the reference, its Jacobian, which the iteration's last step needs (calibration's
  // run.hpp, kTangentAlphaScale).
  double linearised_alpha_scale = 1.0;
  // Whether an update also reports what a variance-component estimate of the measurement noise
  // needs (UpdateResult::noise_quadratic and noise_redundancy): one triangular solve per row of
  // the innovation covariance. Off by default: the board's loop does not pay for it; the host's
  // refinement asks for it when it estimates the noise (calibration's noise_estimate.hpp).
  bool noise_statistics = false;
};

enum class FilterStatus : std::uint8_t {
  kOk,
  kCovarianceNotPositiveDefinite,  // the block of P to sample could not be factored
  kInnovationNotPositiveDefinite,  // S could not be factored
  kNoMeasurement,                  // nothing left to update with (none given, all gated or invalid)
  kNonFinite,                      // a NaN or infinity appeared; the filter was left unchanged
};

const char* to_string(FilterStatus s);

template <typename S, int Dim>
struct SigmaWeights {
  S gamma;            // spread: sqrt(n + lambda)
  S inv_gamma2;       // 1 / gamma^2
  S mean_correction;  // beta - alpha^2: weight of the mean's shift in the covariance

  // alpha_scale < 1 draws the points closer to the mean (see SigmaPointParams::max_shrinks).
  static SigmaWeights make(const UnscentedParams& p, double alpha_scale = 1.0) {
    const double alpha = p.alpha * alpha_scale;
    const double g2 = alpha * alpha * (Dim + p.kappa);
    SigmaWeights w;
    w.gamma = S(std::sqrt(g2));
    w.inv_gamma2 = S(1.0 / g2);
    w.mean_correction = S(p.beta - alpha * alpha);
    return w;
  }
};

// Outcome of one update.
struct UpdateResult {
  FilterStatus status = FilterStatus::kNoMeasurement;
  int used = 0;     // measurement blocks that entered the update
  int gated = 0;    // blocks rejected by the Mahalanobis gate
  int invalid = 0;  // blocks the model could not evaluate at some sigma point (e.g. behind camera)
  int steps = 0;    // progressive sub-updates applied (1 for an ordinary update)
  bool cross_terms = false;  // whether the second-order cross terms were added
  double nis = 0.0;          // normalised innovation squared of the blocks used
  // With SigmaPointParams::noise_statistics, over the blocks used, with R the measurement noise
  // (diagonal) and S the innovation covariance: nu^T S^-1 R S^-1 nu (the squared residual R S^-1
  // nu weighted by R^-1, times R's scale) and tr(R S^-1), the update's redundancy in the noise. A
  // model and noise right give E[noise_quadratic] = noise_redundancy (Foerstner's variance
  // component estimate: the noise's variance times their ratio).
  double noise_quadratic = 0.0;
  double noise_redundancy = 0.0;
};

// A Euclidean state R^N: the simplest manifold, used for linear models and in tests.
template <typename Scalar_, int N>
struct EuclideanState {
  using Scalar = Scalar_;
  static constexpr int kDim = N;
  Eigen::Matrix<Scalar, N, 1> x = Eigen::Matrix<Scalar, N, 1>::Zero();

  template <int B, int L>
  void boxplus_block(const Eigen::Matrix<Scalar, L, 1>& d) {
    x.template segment<L>(B) += d;
  }
  template <int B, int L>
  Eigen::Matrix<Scalar, L, 1> boxminus_block(const EuclideanState& ref) const {
    return x.template segment<L>(B) - ref.x.template segment<L>(B);
  }
};

template <class State>
class SigmaPointFilter {
 public:
  using Scalar = typename State::Scalar;
  static constexpr int N = State::kDim;
  using Covariance = Eigen::Matrix<Scalar, N, N>;
  using ErrorVector = Eigen::Matrix<Scalar, N, 1>;

  SigmaPointFilter() = default;
  explicit SigmaPointFilter(const SigmaPointParams& p) : params_(p) {}
  explicit SigmaPointFilter(const UnscentedParams& u) : params_{u} {}

  void reset(const State& mean, const Covariance& cov) {
    mean_ = mean;
    if (&cov != &cov_) cov_ = cov;  // reset(x, covariance()) keeps the covariance
    symmetrise(cov_);
  }
  // A new mean, and a new covariance of the leading block [0, D) (symmetrised), in place: what a
  // predict that moves only the leading block needs, without two copies of the N x N matrix and
  // a pass over it. Its cross-covariance with the states after it is move_leading_cross's.
  template <int D>
  void reset_leading(const State& mean, const Eigen::Matrix<Scalar, D, D>& p_dd) {
    mean_ = mean;
    for (int j = 0; j < D; ++j)
      for (int i = j; i < D; ++i) cov_(i, j) = cov_(j, i) = Scalar(0.5) * (p_dd(i, j) + p_dd(j, i));
  }
  // A new mean, the covariance as it is (a predict whose covariance waits: CalibrationFilter).
  void set_mean(const State& mean) { mean_ = mean; }
  // The cross-covariance of the leading D states with the rest after those states moved by a
  // linear map F: P_cd <- P_cd F^T, where f.right_multiply_transposed(x, out) sets out = x F^T.
  template <int D, class Transition>
  void move_leading_cross(const Transition& f) {
    Eigen::Matrix<Scalar, N - D, D> moved;
    f.right_multiply_transposed(cov_.template bottomLeftCorner<N - D, D>(), moved);
    cov_.template bottomLeftCorner<N - D, D>() = moved;
    cov_.template topRightCorner<D, N - D>() = moved.transpose();
  }
  const State& mean() const { return mean_; }
  const Covariance& covariance() const { return cov_; }
  const SigmaPointParams& params() const { return params_; }
  // Bytes of thread_workspace an update of a block of L states by Z measurement rows uses.
  template <int L, int Z>
  static constexpr std::size_t update_workspace_bytes() {
    return sizeof(UpdateWorkspace<L, Z>);
  }

  // Propagates the state through f(State&), which may change only the error-state block
  // [B, B+L); Q is the process noise added on that block.
  template <int B, int L, class Propagate>
  FilterStatus predict(Propagate&& f, const Eigen::Matrix<Scalar, L, L>& q) {
    static_assert(B >= 0 && L > 0 && B + L <= N, "block out of range");
    using BlockMat = Eigen::Matrix<Scalar, L, L>;
    using BlockVec = Eigen::Matrix<Scalar, L, 1>;

    // Each L x L temporary takes L^2 scalars of stack (1.8 KB at L = 15, double), and Eigen
    // evaluates every product in an expression into a temporary of its own: so the Cholesky
    // factor is computed in place, a and b are formed directly, the products accumulate into
    // p_bb, and the regression matrix overwrites a. The results are those of the textbook
    // expressions bit for bit.
    BlockMat chol = cov_.template block<L, L>(B, B);
    Eigen::LLT<Eigen::Ref<BlockMat>> llt(chol);
    if (llt.info() != Eigen::Success) return FilterStatus::kCovarianceNotPositiveDefinite;
    chol.template triangularView<Eigen::StrictlyUpper>().setZero();
    const auto w = SigmaWeights<Scalar, L>::make(params_.unscented);

    State centre = mean_;
    f(centre);
    // With dev+-_j the deviations of the propagated sigma points +-j from the propagated centre
    // (the centre's own deviation is zero by construction), the transform's
    // a_j = (dev+_j - dev-_j) / 2 and b_j = (dev+_j + dev-_j) / 2.
    BlockMat a, b;
    for (int j = 0; j < L; ++j) {
      BlockVec dev[2];
      for (int sign = 0; sign < 2; ++sign) {
        State sp = mean_;
        const BlockVec d = (sign == 0 ? w.gamma : -w.gamma) * chol.col(j);
        sp.template boxplus_block<B, L>(d);
        f(sp);
        dev[sign] = sp.template boxminus_block<B, L>(centre);
      }
      a.col(j) = Scalar(0.5) * (dev[0] - dev[1]);
      b.col(j) = Scalar(0.5) * (dev[0] + dev[1]);
    }
    const BlockVec shift = w.inv_gamma2 * b.rowwise().sum();
    BlockMat p_bb = BlockMat::Zero();
    add_product(p_bb, a, a.transpose());
    add_product(p_bb, b, b.transpose());
    p_bb = w.inv_gamma2 * p_bb + w.mean_correction * shift.lazyProduct(shift.transpose()) + q;
    // Regression matrix F = (a / gamma) chol^-1 carries the cross-covariance with the constants.
    BlockMat& f_reg = a;
    f_reg.transposeInPlace();
    f_reg /= w.gamma;
    chol.transpose().template triangularView<Eigen::Upper>().solveInPlace(f_reg);
    f_reg.transposeInPlace();

    if (!p_bb.allFinite() || !f_reg.allFinite() || !shift.allFinite())
      return FilterStatus::kNonFinite;

    centre.template boxplus_block<B, L>(shift);
    mean_ = centre;
    if constexpr (B > 0) {
      Eigen::Matrix<Scalar, L, B> c = Eigen::Matrix<Scalar, L, B>::Zero();
      add_product(c, f_reg, cov_.template block<L, B>(B, 0));
      cov_.template block<L, B>(B, 0) = c;
      cov_.template block<B, L>(0, B) = c.transpose();
    }
    constexpr int kAfter = N - B - L;
    if constexpr (kAfter > 0) {
      Eigen::Matrix<Scalar, L, kAfter> c = Eigen::Matrix<Scalar, L, kAfter>::Zero();
      add_product(c, f_reg, cov_.template block<L, kAfter>(B, B + L));
      cov_.template block<L, kAfter>(B, B + L) = c;
      cov_.template block<kAfter, L>(B + L, B) = c.transpose();
    }
    cov_.template block<L, L>(B, B) = Scalar(0.5) * (p_bb + p_bb.transpose());
    return FilterStatus::kOk;
  }

  // Updates with a measurement of up to kBlocks independent blocks of kRows rows each; h reads
  // only the error-state block [B, B+L). active[b] says block b was measured; r_diag is the
  // measurement noise variance of each row. h(state, z, ok) writes the predicted measurement of
  // every active block and clears ok[b] where it cannot evaluate block b. Each block passes the
  // Mahalanobis gate (squared distance under its marginal innovation covariance) or is rejected.
  //
  // A measurement far more certain than the prediction (the first frames, with a 10 cm marker
  // prior) is applied progressively (Hanebeck's progressive Gaussian filtering): in steps with the
  // noise R / beta_k, sum beta_k = 1, each from sigma points redrawn around the last result, each
  // beta_k as large as keeps that step's spread ratio within spread_per_step. The spread shrinks
  // geometrically and the steps grow: a ratio of 2e4 (140 px of spread on 1 px of noise) takes 3
  // steps. For a linear model the steps are exactly one update; for a nonlinear one they follow
  // the measurement function instead of trusting one linearisation over the whole prior. (Equal
  // steps of R / K, used before, leave the first step almost all the work: a ratio of 1000 in 20
  // steps, and one paper run in 140 diverged after its first frame.)
  template <int B, int L, int kRows, int kBlocks, class Measure>
  UpdateResult update(Measure&& h, const Eigen::Matrix<Scalar, kRows * kBlocks, 1>& z,
                      const std::array<bool, kBlocks>& active,
                      const Eigen::Matrix<Scalar, kRows * kBlocks, 1>& r_diag, Scalar gate,
                      const State* linearise_at = nullptr) {
    static_assert(B >= 0 && L > 0 && B + L <= N, "block out of range");
    constexpr int Z = kRows * kBlocks;
    using ZVec = Eigen::Matrix<Scalar, Z, 1>;
    using ZMat = Eigen::Matrix<Scalar, Z, Z>;

    UpdateResult result;
    std::array<bool, kBlocks> ok = active;
    int n_active = 0;
    for (bool a : active) n_active += a ? 1 : 0;
    if (n_active == 0) return result;

    UpdateWorkspace<L, Z>& ws = thread_workspace<UpdateWorkspace<L, Z>>();
    MeasurementSample<L, Z>& ms = ws.ms;
    // Linearised at a reference (a trajectory the caller follows): the points are drawn around it
    // with this filter's spread, and the measurement is the regression's line through it.
    const State own = mean_;
    if (linearise_at != nullptr) mean_ = *linearise_at;
    bool sampled = false;
    for (int shrink = 0;; ++shrink) {
      ok = active;
      std::array<bool, kBlocks> centre_ok;
      const double alpha_scale = linearise_at != nullptr ? params_.linearised_alpha_scale : 1.0;
      ws.w = SigmaWeights<Scalar, L>::make(params_.unscented, std::ldexp(alpha_scale, -shrink));
      sampled = sample_measurement<B, L, kRows, kBlocks>(h, ok, ws, &centre_ok);
      if (!sampled || ok == centre_ok || shrink >= params_.max_shrinks) break;
    }
    if (sampled &&
        spread_ratio_of<kRows, kBlocks>(ms, ok, r_diag) > Scalar(params_.cross_terms_above)) {
      add_cross_terms<B, L, kRows, kBlocks>(h, ok, ws);
      result.cross_terms = true;
    }
    mean_ = own;
    if (!sampled) {
      result.status = FilterStatus::kCovarianceNotPositiveDefinite;
      return result;
    }
    for (int b = 0; b < kBlocks; ++b)
      if (active[b] && !ok[b]) ++result.invalid;

    // Gate each block on its own marginal innovation covariance.
    ZVec innovation = z - ms.z_centre;
    if (linearise_at != nullptr)  // z ~ h(ref) + A (x - ref), A = (P_bb^-1 P_bz)^T
      innovation.noalias() -=
          ms.reg.transpose().lazyProduct(own.template boxminus_block<B, L>(*linearise_at));
    ZMat& s = ws.s;
    s = ms.p_zz;
    s.diagonal() += r_diag;
    for (int b = 0; b < kBlocks; ++b) {
      if (!ok[b]) continue;
      const int r0 = b * kRows;
      const Eigen::Matrix<Scalar, kRows, 1> nu_b = innovation.template segment<kRows>(r0);
      Eigen::LLT<Eigen::Matrix<Scalar, kRows, kRows>> llt_b(s.template block<kRows, kRows>(r0, r0));
      const Scalar d2 =
          llt_b.info() == Eigen::Success ? nu_b.dot(llt_b.solve(nu_b)) : Scalar(INFINITY);
      if (!(d2 <= gate) || !std::isfinite(d2)) {  // also rejects NaN, and inf under an open gate
        ok[b] = false;
        ++result.gated;
        continue;
      }
      ++result.used;
    }
    if (result.used == 0) {
      result.status = FilterStatus::kNoMeasurement;
      return result;
    }
    {
      ZMat& s_used = ws.s_used;
      s_used = s;
      ZVec nu_used = innovation;
      make_inert<kRows, kBlocks>(ok, s_used, nu_used);
      Eigen::LLT<ZMat>& llt_s = ws.llt_s;
      llt_s.compute(s_used);
      if (llt_s.info() != Eigen::Success) {
        result.status = FilterStatus::kInnovationNotPositiveDefinite;
        return result;
      }
      result.nis = static_cast<double>(nu_used.dot(llt_s.solve(nu_used)));  // inert blocks add 0
      if (params_.noise_statistics) {
        // Inert rows have zero innovation and an identity in S: they add nothing below.
        const ZVec w = llt_s.solve(nu_used);
        ZVec unit = ZVec::Zero();
        for (int b = 0; b < kBlocks; ++b) {
          if (!ok[b]) continue;
          for (int i = b * kRows; i < (b + 1) * kRows; ++i) {
            result.noise_quadratic += static_cast<double>(r_diag(i) * w(i) * w(i));
            unit(i) = Scalar(1);  // (S^-1)_ii = |L^-1 e_i|^2
            llt_s.matrixL().solveInPlace(unit);
            result.noise_redundancy += static_cast<double>(r_diag(i) * unit.squaredNorm());
            unit.setZero();
          }
        }
      }
    }

    // A step that fails after others were applied must not leave them applied. A failed step
    // changes nothing (apply_update), so the covariance is kept only before a step that is not the
    // last: an ordinary update, one step, copies no N x N matrix.
    const State mean_before = mean_;
    bool kept = false;
    const auto restore = [&] {
      mean_ = mean_before;
      if (kept) cov_ = ws.cov_before;
    };
    Scalar remaining = 1;  // of the measurement's information
    int steps = 0;
    for (int k = 0; remaining > 0; ++k) {
      if (k > 0) {
        if (!sample_measurement<B, L, kRows, kBlocks>(h, ok, ws)) {
          restore();
          result.status = FilterStatus::kCovarianceNotPositiveDefinite;
          return result;
        }
        if (result.cross_terms) add_cross_terms<B, L, kRows, kBlocks>(h, ok, ws);
        innovation = z - ms.z_centre;
      }
      const Scalar ratio = spread_ratio_of<kRows, kBlocks>(ms, ok, r_diag);
      const Scalar most = Scalar(params_.spread_per_step) / ratio;  // inf for a zero spread
      const bool last =
          k + 1 >= params_.max_steps || !(most < remaining) || linearise_at != nullptr;
      const Scalar beta = last ? remaining : most;
      remaining -= beta;
      if (!last && !kept) {
        ws.cov_before = cov_;
        kept = true;
      }
      // One step with the whole measurement: S is s_used, factored above for the NIS.
      const bool factored = k == 0 && beta == Scalar(1);
      if (!factored) {
        s = ms.p_zz;
        s.diagonal() += r_diag / beta;
      }
      const FilterStatus st = apply_update<B, L, kRows, kBlocks>(ws, innovation, ok, factored);
      ++steps;
      if (st != FilterStatus::kOk) {
        restore();
        result.status = st;
        return result;
      }
    }
    result.steps = steps;
    result.status = FilterStatus::kOk;
    return result;
  }

 private:
  // m <- (m + m^T) / 2 in place, exactly symmetric. (m = 0.5 * (m + m.transpose()) reads entries
  // it has already overwritten, and leaves m asymmetric in the last bits.)
  static void symmetrise(Covariance& m) {
    for (int j = 0; j < N; ++j)
      for (int i = j + 1; i < N; ++i) m(i, j) = m(j, i) = Scalar(0.5) * (m(i, j) + m(j, i));
  }

  // dst += lhs * rhs by Eigen's product (from dst = 0, bit for bit what dst = lhs * rhs gives),
  // out of line: the packing buffers of a blocked product, 2 L^2 scalars, then take stack space
  // during the call only, instead of once for each product in the caller's frame.
  template <class Dst, class Lhs, class Rhs>
  EIGEN_DONT_INLINE static void add_product(Dst& dst, const Lhs& lhs, const Rhs& rhs) {
    dst.noalias() += lhs * rhs;
  }

  // The unscented transform of the measurement: its prediction h at the mean (z_centre), its
  // spread about it (without noise), the regression of the measurement on the sampled block
  // (P_bb^-1 P_bz, with P_bz the cross-covariance), and that block's Cholesky factorisation.
  template <int L, int Z>
  struct MeasurementSample {
    Eigen::Matrix<Scalar, Z, Z> p_zz;
    Eigen::Matrix<Scalar, L, Z> reg;
    Eigen::Matrix<Scalar, L, L> chol;      // lower Cholesky factor of the sampled block
    Eigen::Matrix<Scalar, Z, 1> z_centre;  // h at the centre
    Eigen::Matrix<Scalar, Z, L> z_plus;    // h at the + sigma points
  };

  // The update's matrices of the sampled block (L) and measurement (Z) sizes and of the state's,
  // in thread_workspace: the measurement sample, the transform's deviations, the innovation
  // covariance, the covariance kept for a multi-step update and the gain's factor W.
  template <int L, int Z>
  struct UpdateWorkspace {
    MeasurementSample<L, Z> ms;
    SigmaWeights<Scalar, L> w;            // of this update's sigma points
    Eigen::Matrix<Scalar, Z, L> z_minus;  // h at the - sigma points
    // The transform's a and b (see UnscentedParams) transposed: a column per measurement row, so
    // that the products read contiguous columns.
    Eigen::Matrix<Scalar, L, Z> a_t, b_t;
    Eigen::Matrix<Scalar, Z, L> reg_t;      // the regression transposed, as its solve runs
    Eigen::Matrix<Scalar, Z, Z> s, s_used;  // innovation covariance; with unused blocks inert
    Eigen::LLT<Eigen::Matrix<Scalar, Z, Z>> llt_s;
    Covariance cov_before;
    Eigen::Matrix<Scalar, L, Z> reg_w;  // the regression times L_S^-T
    Eigen::Matrix<Scalar, Z, N> w_t;    // W^T, W = P_xz L_S^-T
  };

  template <int B, int L, int kRows, int kBlocks, class Measure>
  bool sample_measurement(Measure& h, std::array<bool, kBlocks>& ok,
                          UpdateWorkspace<L, kRows * kBlocks>& ws,
                          std::array<bool, kBlocks>* centre_ok = nullptr) const {
    constexpr int Z = kRows * kBlocks;
    using BlockVec = Eigen::Matrix<Scalar, L, 1>;
    using ZVec = Eigen::Matrix<Scalar, Z, 1>;
    MeasurementSample<L, Z>& ms = ws.ms;
    ms.chol = cov_.template block<L, L>(B, B);
    if (!cholesky_in_place(ms.chol)) return false;
    const auto& chol = ms.chol;
    const SigmaWeights<Scalar, L>& w = ws.w;

    ZVec z0 = ZVec::Zero();
    h(mean_, z0, ok);
    if (centre_ok != nullptr) *centre_ok = ok;
    auto& z_plus = ms.z_plus;
    auto& z_minus = ws.z_minus;
    for (int j = 0; j < L; ++j) {
      for (int sign = 0; sign < 2; ++sign) {
        State sp = mean_;
        const BlockVec d = (sign == 0 ? w.gamma : -w.gamma) * chol.col(j);
        sp.template boxplus_block<B, L>(d);
        ZVec zj = ZVec::Zero();
        h(static_cast<const State&>(sp), zj, ok);
        (sign == 0 ? z_plus : z_minus).col(j) = zj;
      }
    }
    for (int b = 0; b < kBlocks; ++b) {
      if (ok[b]) continue;
      z0.template segment<kRows>(b * kRows).setZero();  // rows of unusable blocks stay inert
      z_plus.template middleRows<kRows>(b * kRows).setZero();
      z_minus.template middleRows<kRows>(b * kRows).setZero();
    }
    auto& a_t = ws.a_t;
    auto& b_t = ws.b_t;
    a_t = Scalar(0.5) * (z_plus - z_minus).transpose();
    b_t = (Scalar(0.5) * (z_plus + z_minus) - z0.replicate(1, L)).transpose();
    // The prediction is h at the mean, and p_zz the sigma points' mean square deviation from it:
    // inv_gamma2 (a a^T + b b^T). Not the transform's mean h0 + sum(b) / gamma^2: that shift is the
    // curvature of h averaged over the prior, right on average over draws of the truth but the same
    // error in every frame for one truth, and a filter that takes each frame as independent
    // evidence adds it up (from the truth with the random family's priors, marker errors of 3-5
    // sigma after two seconds of frames; see SigmaPointFilter's header).
    for (int j = 0; j < Z; ++j)  // symmetric: each pair once
      for (int i = j; i < Z; ++i)
        ms.p_zz(i, j) = ms.p_zz(j, i) =
            w.inv_gamma2 * (a_t.col(i).dot(a_t.col(j)) + b_t.col(i).dot(b_t.col(j)));
    // The cross-covariance is P_bz = sum of w (chi - x)(z - z0)^T = chol a^T / gamma, so the
    // regression P_bb^-1 P_bz = chol^-T a^T / gamma: one triangular solve, made on its transpose.
    auto& reg_t = ws.reg_t;
    reg_t = a_t.transpose() / w.gamma;
    solve_right_lower(chol, reg_t);
    ms.reg = reg_t.transpose();
    ms.z_centre = z0;
    return true;
  }

  // Adds to ms.p_zz what the unscented transform cannot see: the variance of the cross terms of
  // the measurement's second-order part. Sigma points lie on the axes of the Cholesky factor, so
  // a product of two deviations (a marker's offset along its ray times a rotation error) is zero
  // at every one of them; over a wide prior such a product moves the image by pixels, and an
  // update without it is confident where it should not be (with the paper's priors, a mean NEES
  // of ~300 instead of 15 after 60 s). For h ~ 1/2 xi^T H xi in whitened coordinates the cross
  // terms H_ij xi_i xi_j (i < j) are uncorrelated with variance H_ij^2, and gamma^2 H_ij is the
  // mixed second difference along columns i and j: L(L-1)/2 more evaluations of h.
  template <int B, int L, int kRows, int kBlocks, class Measure>
  void add_cross_terms(Measure& h, const std::array<bool, kBlocks>& ok,
                       UpdateWorkspace<L, kRows * kBlocks>& ws) const {
    using ZVec = Eigen::Matrix<Scalar, kRows * kBlocks, 1>;
    MeasurementSample<L, kRows* kBlocks>& ms = ws.ms;
    const auto& chol = ms.chol;
    const SigmaWeights<Scalar, L>& w = ws.w;
    for (int i = 0; i < L; ++i) {
      for (int j = i + 1; j < L; ++j) {
        State sp = mean_;
        const Eigen::Matrix<Scalar, L, 1> d = w.gamma * (chol.col(i) + chol.col(j));
        sp.template boxplus_block<B, L>(d);
        std::array<bool, kBlocks> ok_ij = ok;
        ZVec zij = ZVec::Zero();
        h(static_cast<const State&>(sp), zij, ok_ij);
        ZVec c = w.inv_gamma2 * (zij - ms.z_plus.col(i) - ms.z_plus.col(j) + ms.z_centre);
        for (int b = 0; b < kBlocks; ++b)  // a block h cannot evaluate there adds nothing
          if (!ok_ij[b]) c.template segment<kRows>(b * kRows).setZero();
        // The outer product added in place: each term c_i c_j is the one its temporary would hold.
        ms.p_zz.noalias() += c * c.transpose();
      }
    }
  }

  // How much more the prediction spreads than the noise: the largest ratio over the blocks in ok.
  template <int kRows, int kBlocks, class Sample, class ZVec>
  static Scalar spread_ratio_of(const Sample& ms, const std::array<bool, kBlocks>& ok,
                                const ZVec& r_diag) {
    Scalar worst = 0;
    for (int b = 0; b < kBlocks; ++b) {
      if (!ok[b]) continue;
      const Scalar ratio = ms.p_zz.diagonal().template segment<kRows>(b * kRows).sum() /
                           r_diag.template segment<kRows>(b * kRows).sum();
      worst = ratio > worst ? ratio : worst;
    }
    return worst;
  }

  // Rows of blocks not used get unit variance, no correlation and zero innovation.
  template <int kRows, int kBlocks, class ZMat, class ZVec>
  static void make_inert(const std::array<bool, kBlocks>& ok, ZMat& s, ZVec& innovation) {
    for (int b = 0; b < kBlocks; ++b) {
      if (ok[b]) continue;
      const int r0 = b * kRows;
      s.template middleRows<kRows>(r0).setZero();
      s.template middleCols<kRows>(r0).setZero();
      s.template block<kRows, kRows>(r0, r0).setIdentity();
      innovation.template segment<kRows>(r0).setZero();
    }
  }

  // One Kalman step with the innovation covariance in ws.s (factored into ws.llt_s already if
  // `factored`). With S = L_S L_S^T and W = P_xz L_S^-T, the gain is K = W L_S^-1, so
  // dx = W (L_S^-1 nu) and P - K P_xz^T = P - W W^T: one triangular solve of the regression's
  // Z columns, one product with the block's rows of P, and a symmetric rank-Z update of P in
  // place, each entry once (exactly symmetric, no copy). A step that fails changes nothing.
  template <int B, int L, int kRows, int kBlocks>
  FilterStatus apply_update(UpdateWorkspace<L, kRows * kBlocks>& ws,
                            Eigen::Matrix<Scalar, kRows * kBlocks, 1>& innovation,
                            const std::array<bool, kBlocks>& ok, bool factored) {
    MeasurementSample<L, kRows* kBlocks>& ms = ws.ms;
    make_inert<kRows, kBlocks>(ok, ws.s, innovation);
    for (int b = 0; b < kBlocks; ++b)
      if (!ok[b]) ms.reg.template middleCols<kRows>(b * kRows).setZero();
    auto& llt_s = ws.llt_s;
    if (!factored) {
      llt_s.compute(ws.s);
      if (llt_s.info() != Eigen::Success) return FilterStatus::kInnovationNotPositiveDefinite;
    }
    // P_xz = P[:, block] P_bb^-1 P_bz (the regression carries the rest of the state), so
    // W^T = (reg L_S^-T)^T P[block, :], P being symmetric.
    ws.reg_w = ms.reg;
    solve_right_lower_transposed(llt_s.matrixLLT(), ws.reg_w);  // its lower triangle is L_S
    auto& w_t = ws.w_t;
    // Each entry a dot product of two contiguous columns (Eigen's blocked product packs both).
    w_t.noalias() = ws.reg_w.transpose().lazyProduct(cov_.template middleRows<L>(B));
    llt_s.matrixL().solveInPlace(innovation);
    // Lazy, as the linearised innovation's product in update(): a dot product per row along
    // contiguous columns. Eigen's general matrix-vector kernel, which it picks from M = 4 on, drew
    // GCC's -Waggressive-loop-optimizations (an iteration count no fixed size reaches) at M = 12,
    // float; at M = 3 Eigen took this path already.
    const ErrorVector dx = w_t.transpose().lazyProduct(innovation);
    if (!dx.allFinite() || !w_t.allFinite()) return FilterStatus::kNonFinite;
    // Every variance must stay positive; then |W_i . W_j| < sqrt(P_ii P_jj) bounds every entry.
    for (int i = 0; i < N; ++i)
      if (!(cov_(i, i) - w_t.col(i).squaredNorm() > Scalar(0))) return FilterStatus::kNonFinite;
    mean_.template boxplus_block<0, N>(dx);
    for (int j = 0; j < N; ++j)
      for (int i = j; i < N; ++i) cov_(j, i) = cov_(i, j) -= w_t.col(i).dot(w_t.col(j));
    return FilterStatus::kOk;
  }

  SigmaPointParams params_{};
  State mean_{};
  Covariance cov_ = Covariance::Identity();
};

inline const char* to_string(FilterStatus s) {
  switch (s) {
    case FilterStatus::kOk:
      return "ok";
    case FilterStatus::kCovarianceNotPositiveDefinite:
      return "covariance not positive definite";
    case FilterStatus::kInnovationNotPositiveDefinite:
      return "innovation covariance not positive definite";
    case FilterStatus::kNoMeasurement:
      return "no measurement";
    case FilterStatus::kNonFinite:
      return "non-finite value";
  }
  return "unknown";
}

}  // namespace mirrorcal
