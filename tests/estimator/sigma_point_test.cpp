// The block-structured sigma-point filter on a linear-Gaussian system equals the Kalman filter:
// the unscented transform is exact for linear maps, so mean and full covariance (including the
// cross-covariances carried by the regression) must match a textbook KF on the full state.
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <Eigen/QR>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include "mirrorcal/estimator/sigma_point_filter.hpp"

namespace mirrorcal {
namespace {

constexpr int N = 8;
constexpr int kPredB = 0, kPredL = 4;  // the dynamics change x[0, 4); x[4, 8) are constants
constexpr int kMeasB = 2, kMeasL = 6;  // the measurement reads x[2, 8)
constexpr int kRows = 2, kBlocks = 3, Z = kRows * kBlocks;

using State = EuclideanState<double, N>;
using Filter = SigmaPointFilter<State>;
using VecN = Eigen::Matrix<double, N, 1>;
using MatN = Eigen::Matrix<double, N, N>;
using VecZ = Eigen::Matrix<double, Z, 1>;
using Active = std::array<bool, kBlocks>;

struct LinearSystem {
  Eigen::Matrix4d a;
  Eigen::Vector4d u;  // constant input: x_b' = A x_b + u
  Eigen::Matrix4d q;
  Eigen::Matrix<double, Z, kMeasL> h;  // z = H x[2, 8) + v
  VecZ r;                              // variance of each row of v

  static LinearSystem make(std::mt19937_64& rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    LinearSystem s;
    // A damped rotation (spectral radius 0.97) mixes all four dynamic states and keeps the
    // covariance bounded over many steps.
    Eigen::Matrix4d g;
    for (int i = 0; i < 16; ++i) g(i) = n(rng);
    const Eigen::Matrix4d rot = Eigen::HouseholderQR<Eigen::Matrix4d>(g).householderQ();
    s.a = 0.97 * rot;
    for (int i = 0; i < 4; ++i) s.u(i) = 0.1 * n(rng);
    Eigen::Matrix4d l;
    for (int i = 0; i < 16; ++i) l(i) = 0.1 * n(rng);
    s.q = l * l.transpose() + 0.01 * Eigen::Matrix4d::Identity();  // correlated process noise
    for (int i = 0; i < Z * kMeasL; ++i) s.h(i) = n(rng);
    for (int i = 0; i < Z; ++i) s.r(i) = 0.05 + 0.1 * std::abs(n(rng));
    return s;
  }

  MatN f_full() const {
    MatN f = MatN::Identity();
    f.block<4, 4>(kPredB, kPredB) = a;
    return f;
  }
  Eigen::Matrix<double, Z, N> h_full() const {
    Eigen::Matrix<double, Z, N> hf = Eigen::Matrix<double, Z, N>::Zero();
    hf.middleCols<kMeasL>(kMeasB) = h;
    return hf;
  }
};

// Textbook Kalman filter on the whole state, with a dynamic choice of measurement rows.
struct KalmanFilter {
  VecN x;
  MatN p;
  double nis = 0.0;

  void predict(const LinearSystem& s) {
    const MatN f = s.f_full();
    VecN u = VecN::Zero();
    u.segment<4>(kPredB) = s.u;
    MatN q = MatN::Zero();
    q.block<4, 4>(kPredB, kPredB) = s.q;
    x = f * x + u;
    p = f * p * f.transpose() + q;
  }
  void update(const LinearSystem& s, const VecZ& z, const Active& use) {
    std::vector<int> rows;
    for (int b = 0; b < kBlocks; ++b)
      if (use[b])
        for (int i = 0; i < kRows; ++i) rows.push_back(b * kRows + i);
    const int m = static_cast<int>(rows.size());
    const Eigen::Matrix<double, Z, N> hf = s.h_full();
    Eigen::MatrixXd h(m, N), r = Eigen::MatrixXd::Zero(m, m);
    Eigen::VectorXd nu(m);
    for (int i = 0; i < m; ++i) {
      h.row(i) = hf.row(rows[i]);
      r(i, i) = s.r(rows[i]);
      nu(i) = z(rows[i]) - hf.row(rows[i]).dot(x);
    }
    const Eigen::MatrixXd sm = h * p * h.transpose() + r;
    const Eigen::MatrixXd k = p * h.transpose() * sm.inverse();
    x += k * nu;
    const MatN i_kh = MatN::Identity() - k * h;
    p = i_kh * p * i_kh.transpose() + k * r * k.transpose();  // Joseph form
    nis = nu.dot(sm.inverse() * nu);
  }
};

auto measure(const LinearSystem& s) {
  return [&s](const State& st, VecZ& z, Active& /*ok*/) { z = s.h * st.x.segment<kMeasL>(kMeasB); };
}

auto propagate(const LinearSystem& s) {
  return
      [&s](State& st) { st.x.segment<kPredL>(kPredB) = s.a * st.x.segment<kPredL>(kPredB) + s.u; };
}

FilterStatus predict(Filter& f, const LinearSystem& s) {
  return f.predict<kPredB, kPredL>(propagate(s), s.q);
}

template <class Measure>
UpdateResult update(Filter& f, Measure&& h, const VecZ& z, const Active& active, const VecZ& r,
                    double gate) {
  return f.update<kMeasB, kMeasL, kRows, kBlocks>(h, z, active, r, gate);
}

MatN correlated_covariance(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  MatN m;
  for (int i = 0; i < N * N; ++i) m(i) = n(rng);
  return 0.3 * m * m.transpose() + 0.1 * MatN::Identity();
}

double max_abs(const MatN& m) {
  return m.cwiseAbs().maxCoeff();
}

struct Settings {
  const char* name;
  SigmaPointParams params;
  bool expect_progressive;  // whether some updates must be split into several steps
};

// How gtest prints a parameter in its output (by default a dump of the struct's bytes).
void PrintTo(const Settings& s, std::ostream* os) {
  *os << s.name;
}

class LinearGaussian : public ::testing::TestWithParam<Settings> {};

TEST_P(LinearGaussian, EqualsKalmanFilterOverManyCycles) {
  std::mt19937_64 rng(100);
  std::normal_distribution<double> n(0.0, 1.0);
  const LinearSystem sys = LinearSystem::make(rng);
  const MatN p0 = correlated_covariance(rng);
  VecN x0;
  for (int i = 0; i < N; ++i) x0(i) = n(rng);

  Filter ukf(GetParam().params);
  State s0;
  s0.x = x0;
  ukf.reset(s0, p0);
  KalmanFilter kf{x0, p0};

  // The truth evolves with the model's noise; the filters see noisy measurements of it.
  VecN truth = x0 + p0.llt().matrixL() * VecN::NullaryExpr([&] { return n(rng); });
  const Eigen::Matrix4d lq = sys.q.llt().matrixL();
  double worst_mean = 0.0, worst_cov = 0.0;
  int max_steps = 0;
  for (int cycle = 0; cycle < 60; ++cycle) {
    for (int k = 0; k < 1 + cycle % 3; ++k) {
      truth.segment<4>(kPredB) = sys.a * truth.segment<4>(kPredB) + sys.u +
                                 lq * Eigen::Vector4d::NullaryExpr([&] { return n(rng); });
      ASSERT_EQ(predict(ukf, sys), FilterStatus::kOk);
      kf.predict(sys);
    }
    VecZ z = sys.h * truth.segment<kMeasL>(kMeasB);
    for (int i = 0; i < Z; ++i) z(i) += std::sqrt(sys.r(i)) * n(rng);
    const Active all{true, true, true};
    const UpdateResult res = update(ukf, measure(sys), z, all, sys.r, 1e12);
    kf.update(sys, z, all);
    ASSERT_EQ(res.status, FilterStatus::kOk);
    EXPECT_EQ(res.used, 3);
    EXPECT_EQ(res.gated, 0);
    EXPECT_NEAR(res.nis, kf.nis, 1e-9 * (1.0 + kf.nis));
    EXPECT_GE(res.steps, 1);
    EXPECT_LE(res.steps, GetParam().params.max_steps);
    max_steps = std::max(max_steps, res.steps);
    worst_mean = std::max(worst_mean, (ukf.mean().x - kf.x).cwiseAbs().maxCoeff());
    worst_cov = std::max(worst_cov, max_abs(ukf.covariance() - kf.p));
  }
  // Scale: the state and covariance entries are O(0.1 .. 1); 1e-9 leaves ~1e6 ulps for the
  // different operation order (Cholesky, regression, Joseph form) over 60 cycles.
  EXPECT_LT(worst_mean, 1e-9);
  EXPECT_LT(worst_cov, 1e-9);
  EXPECT_LT(max_abs(ukf.covariance() - ukf.covariance().transpose()), 1e-15);
  // A split update (K steps with K times the noise) is one update for a linear model.
  if (GetParam().expect_progressive) {
    EXPECT_GT(max_steps, 1);
  }
  std::printf("%s: largest split %d, worst mean difference %.2e, covariance %.2e\n",
              GetParam().name, max_steps, worst_mean, worst_cov);
  // The run was informative: the covariance shrank well below the prior.
  EXPECT_LT(ukf.covariance().trace(), 0.5 * p0.trace());
}

SigmaPointParams settings(UnscentedParams u, double spread_per_step, int max_steps = 20) {
  SigmaPointParams p;
  p.unscented = u;
  p.spread_per_step = spread_per_step;
  p.max_steps = max_steps;
  return p;
}

INSTANTIATE_TEST_SUITE_P(
    Weights, LinearGaussian,
    ::testing::Values(Settings{"Default", SigmaPointParams{}, false},
                      Settings{"CubatureOneStep", settings({1.0, 2.0, 0.0}, 1e300), false},
                      // alpha = 0.5, kappa = 1: a negative centre weight.
                      Settings{"NegativeCentreSplit", settings({0.5, 2.0, 1.0}, 1.0), true},
                      Settings{"KappaSplitCapped", settings({1.0, 0.0, 3.0}, 0.01, 7), true}),
    [](const ::testing::TestParamInfo<Settings>& info) {
      return std::string(info.param.name);
    });  // kappa > 0

// A filter and a KF that have both seen a few cycles, so the prior is correlated.
struct Pair {
  LinearSystem sys;
  Filter ukf;
  KalmanFilter kf;
};

Pair make_filter_pair(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Pair p{LinearSystem::make(rng), Filter{}, KalmanFilter{}};
  const MatN p0 = correlated_covariance(rng);
  State s0;
  for (int i = 0; i < N; ++i) s0.x(i) = std::normal_distribution<double>(0.0, 1.0)(rng);
  p.ukf.reset(s0, p0);
  p.kf = KalmanFilter{s0.x, p0};
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(predict(p.ukf, p.sys), FilterStatus::kOk);
    p.kf.predict(p.sys);
  }
  return p;
}

void expect_same(const Filter& ukf, const KalmanFilter& kf) {
  EXPECT_LT((ukf.mean().x - kf.x).cwiseAbs().maxCoeff(), 1e-11);
  EXPECT_LT(max_abs(ukf.covariance() - kf.p), 1e-11);
}

constexpr double kGate = 13.8155;  // chi^2, 2 dof, 99.9 %

TEST(SigmaPointGate, RejectsGrossOutlierBlockAndUsesTheRest) {
  Pair p = make_filter_pair(200);
  // The predicted measurement plus a small offset, except block 1, which is off by ~100 sigma.
  VecZ z = p.sys.h * p.kf.x.segment<kMeasL>(kMeasB);
  z += 0.1 * VecZ::Ones();
  z.segment<2>(2) += Eigen::Vector2d(120.0, -90.0);
  const UpdateResult res =
      update(p.ukf, measure(p.sys), z, Active{true, true, true}, p.sys.r, kGate);
  EXPECT_EQ(res.status, FilterStatus::kOk);
  EXPECT_EQ(res.gated, 1);
  EXPECT_EQ(res.used, 2);
  EXPECT_EQ(res.invalid, 0);
  p.kf.update(p.sys, z, Active{true, false, true});
  expect_same(p.ukf, p.kf);
  EXPECT_NEAR(res.nis, p.kf.nis, 1e-9);
}

TEST(SigmaPointGate, NanBlockIsGatedNotSpread) {
  Pair p = make_filter_pair(201);
  VecZ z = p.sys.h * p.kf.x.segment<kMeasL>(kMeasB) + 0.2 * VecZ::Ones();
  z(4) = std::nan("");
  const UpdateResult res =
      update(p.ukf, measure(p.sys), z, Active{true, true, true}, p.sys.r, kGate);
  EXPECT_EQ(res.status, FilterStatus::kOk);
  EXPECT_EQ(res.gated, 1);
  EXPECT_EQ(res.used, 2);
  EXPECT_TRUE(p.ukf.mean().x.allFinite());
  EXPECT_TRUE(p.ukf.covariance().allFinite());
  p.kf.update(p.sys, z, Active{true, true, false});
  expect_same(p.ukf, p.kf);
}

TEST(SigmaPointGate, AllBlocksGatedLeavesFilterUnchanged) {
  Pair p = make_filter_pair(202);
  const State before = p.ukf.mean();
  const MatN cov_before = p.ukf.covariance();
  const VecZ z = p.sys.h * p.kf.x.segment<kMeasL>(kMeasB) + 1e3 * VecZ::Ones();
  const UpdateResult res =
      update(p.ukf, measure(p.sys), z, Active{true, true, true}, p.sys.r, kGate);
  EXPECT_EQ(res.status, FilterStatus::kNoMeasurement);
  EXPECT_EQ(res.gated, 3);
  EXPECT_EQ(res.used, 0);
  EXPECT_EQ(p.ukf.mean().x, before.x);
  EXPECT_EQ(p.ukf.covariance(), cov_before);
}

TEST(SigmaPointUpdate, InactiveBlockMatchesKalmanFilterOnActiveRows) {
  Pair p = make_filter_pair(300);
  std::mt19937_64 rng(301);
  std::normal_distribution<double> n(0.0, 1.0);
  VecZ z = VecZ::NullaryExpr([&] { return n(rng); });
  z.segment<2>(2).setConstant(std::nan(""));  // whatever an unseen block holds must not matter
  const UpdateResult res =
      update(p.ukf, measure(p.sys), z, Active{true, false, true}, p.sys.r, 1e12);
  EXPECT_EQ(res.status, FilterStatus::kOk);
  EXPECT_EQ(res.used, 2);
  EXPECT_EQ(res.gated, 0);
  EXPECT_EQ(res.invalid, 0);
  p.kf.update(p.sys, z, Active{true, false, true});
  expect_same(p.ukf, p.kf);
  EXPECT_NEAR(res.nis, p.kf.nis, 1e-9 * (1.0 + p.kf.nis));
}

// A block the model cannot evaluate at the mean is counted and dropped; the other blocks update as
// the Kalman filter does on their rows.
TEST(SigmaPointUpdate, BlockTheModelCannotEvaluateIsCountedAndDropped) {
  Pair p = make_filter_pair(400);
  std::mt19937_64 rng(401);
  std::normal_distribution<double> n(0.0, 1.0);
  const VecZ z = VecZ::NullaryExpr([&] { return n(rng); });
  const LinearSystem& sys = p.sys;
  const auto h = [&](const State& st, VecZ& zp, Active& ok) {
    zp = sys.h * st.x.segment<kMeasL>(kMeasB);
    ok[0] = false;  // nowhere
  };
  const UpdateResult res = update(p.ukf, h, z, Active{true, true, true}, sys.r, 1e12);
  EXPECT_EQ(res.status, FilterStatus::kOk);
  EXPECT_EQ(res.invalid, 1);
  EXPECT_EQ(res.used, 2);
  p.kf.update(p.sys, z, Active{false, true, true});
  expect_same(p.ukf, p.kf);
}

// A block the model cannot evaluate at one sigma point only (a camera drawn behind the mirror
// from a wide prior on its distance) is sampled again closer to the mean, and used: for a linear
// model the narrower transform is still the Kalman update.
TEST(SigmaPointUpdate, SigmaPointOutsideTheDomainIsDrawnAgainCloser) {
  Pair p = make_filter_pair(400);
  std::mt19937_64 rng(401);
  std::normal_distribution<double> n(0.0, 1.0);
  const VecZ z = VecZ::NullaryExpr([&] { return n(rng); });
  const LinearSystem& sys = p.sys;
  int calls = 0;
  const auto h = [&](const State& st, VecZ& zp, Active& ok) {
    zp = sys.h * st.x.segment<kMeasL>(kMeasB);
    if (++calls == 5) ok[0] = false;  // fails at one sigma point of the first transform
  };
  const UpdateResult res = update(p.ukf, h, z, Active{true, true, true}, sys.r, 1e12);
  EXPECT_GT(calls, 2 * kMeasL + 1) << "the transform was not drawn again";
  EXPECT_EQ(res.status, FilterStatus::kOk);
  EXPECT_EQ(res.invalid, 0);
  EXPECT_EQ(res.used, 3);
  p.kf.update(p.sys, z, Active{true, true, true});
  expect_same(p.ukf, p.kf);
}

// A split update that fails in a later step must not leave the earlier steps applied: a refused
// update leaves the filter unchanged, whichever step refused it.
TEST(SigmaPointUpdate, FailureInALaterStepLeavesFilterUnchanged) {
  std::mt19937_64 rng(450);
  const LinearSystem sys = LinearSystem::make(rng);
  SigmaPointParams params;
  params.spread_per_step = 1e-3;        // always split, into max_steps steps
  params.cross_terms_above = INFINITY;  // so that the first step is exactly 2L+1 calls
  Filter f(params);
  State s0;
  s0.x.setLinSpaced(-1.0, 1.0);
  f.reset(s0, correlated_covariance(rng));
  const State before = f.mean();
  const MatN cov_before = f.covariance();
  int calls = 0;
  const auto h = [&](const State& st, VecZ& zp, Active&) {
    zp = sys.h * st.x.segment<kMeasL>(kMeasB);
    if (++calls > 2 * kMeasL + 1) zp(0) = std::nan("");  // breaks down from the second step on
  };
  const VecZ z = sys.h * s0.x.segment<kMeasL>(kMeasB) + 0.3 * VecZ::Ones();
  const UpdateResult res = update(f, h, z, Active{true, true, true}, sys.r, 1e12);
  EXPECT_GT(calls, 2 * kMeasL + 1) << "the update was not split";
  EXPECT_NE(res.status, FilterStatus::kOk);
  EXPECT_EQ(f.mean().x, before.x);
  EXPECT_EQ(f.covariance(), cov_before);
}

// A bilinear measurement z = x1 x2 + v of independent Gaussians: the sigma points lie on the axes,
// where x1 x2 is linear, so the transform alone sees Var = mu2^2 s1^2 + mu1^2 s2^2 and misses
// s1^2 s2^2. With the cross terms the innovation variance is exact, and so are the gain, the
// posterior covariance and the NIS of the moment-matched Gaussian update.
TEST(SigmaPointUpdate, CrossTermsMakeABilinearInnovationExact) {
  using S2 = EuclideanState<double, 2>;
  const double mu1 = 0.7, mu2 = -1.3, s1 = 0.9, s2 = 0.6, r = 0.05, z = 0.4;
  for (const bool cross : {false, true}) {
    SigmaPointParams params;
    params.cross_terms_above = cross ? 0.0 : INFINITY;
    params.spread_per_step = 1e9;  // one step, so the result is the single update in closed form
    SigmaPointFilter<S2> f(params);
    S2 x0;
    x0.x << mu1, mu2;
    f.reset(x0, Eigen::Vector2d(s1 * s1, s2 * s2).asDiagonal());
    const auto h = [](const S2& st, Eigen::Matrix<double, 1, 1>& zp, std::array<bool, 1>&) {
      zp(0) = st.x(0) * st.x(1);
    };
    const UpdateResult res = f.update<0, 2, 1, 1>(h, Eigen::Matrix<double, 1, 1>(z), {true},
                                                  Eigen::Matrix<double, 1, 1>(r), INFINITY);
    ASSERT_EQ(res.status, FilterStatus::kOk);
    EXPECT_EQ(res.cross_terms, cross);
    const double var_h =
        mu2 * mu2 * s1 * s1 + mu1 * mu1 * s2 * s2 + (cross ? s1 * s1 * s2 * s2 : 0);
    const double s_innov = var_h + r;
    const Eigen::Vector2d p_xz(mu2 * s1 * s1, mu1 * s2 * s2);  // exact E[(x - mu)(h - E h)]
    const double innov = z - mu1 * mu2;                        // E h = mu1 mu2: no mean shift
    EXPECT_NEAR(res.nis, innov * innov / s_innov, 1e-12);
    const Eigen::Vector2d mean = Eigen::Vector2d(mu1, mu2) + p_xz * innov / s_innov;
    const Eigen::Matrix2d cov = Eigen::Matrix2d(Eigen::Vector2d(s1 * s1, s2 * s2).asDiagonal()) -
                                p_xz * p_xz.transpose() / s_innov;
    EXPECT_LT((f.mean().x - mean).norm(), 1e-12);
    EXPECT_LT((f.covariance() - cov).norm(), 1e-12);
  }
}

// A pinhole pixel u = f x / d of a point whose lateral offset x and depth d have a wide prior (the
// first frame of a marker with a 10 cm prior, 70 cm away): 1 px of noise against about 140 px of
// predicted spread. The exact posterior mean, by quadrature on a grid, is matched far better by the
// progressive update than by one linearisation over the whole prior.
TEST(SigmaPointUpdate, ProgressiveStepsFollowAStronglyNonlinearMeasurement) {
  using S2 = EuclideanState<double, 2>;
  const double f = 833.0, r = 1.0, mx = 0.02, md = 0.7, sx = 0.1, sd = 0.1;
  const double z = f * 0.14 / 0.62;  // a point 1.2 and 0.8 sigma from the prior mean
  // The posterior mean and standard deviations on a 1201 x 1201 grid over +-6 prior sigma.
  double w_sum = 0, ex = 0, ed = 0, exx = 0, edd = 0;
  const int n = 1200;
  for (int i = 0; i <= n; ++i) {
    for (int j = 0; j <= n; ++j) {
      const double x = mx + sx * (-6.0 + 12.0 * i / n), d = md + sd * (-6.0 + 12.0 * j / n);
      const double e = z - f * x / d;
      const double w = std::exp(-0.5 * (((x - mx) / sx) * ((x - mx) / sx) +
                                        ((d - md) / sd) * ((d - md) / sd) + e * e / r));
      w_sum += w;
      ex += w * x;
      ed += w * d;
      exx += w * x * x;
      edd += w * d * d;
    }
  }
  ex /= w_sum;
  ed /= w_sum;
  const double post_sx = std::sqrt(exx / w_sum - ex * ex),
               post_sd = std::sqrt(edd / w_sum - ed * ed);

  const auto posterior_error = [&](double spread_per_step, int& steps) {
    SigmaPointParams params;
    params.spread_per_step = spread_per_step;
    SigmaPointFilter<S2> filter(params);
    S2 x0;
    x0.x << mx, md;
    filter.reset(x0, Eigen::Vector2d(sx * sx, sd * sd).asDiagonal());
    const auto h = [&](const S2& st, Eigen::Matrix<double, 1, 1>& zp, std::array<bool, 1>&) {
      zp(0) = f * st.x(0) / st.x(1);
    };
    const UpdateResult res = filter.template update<0, 2, 1, 1>(
        h, Eigen::Matrix<double, 1, 1>(z), std::array<bool, 1>{true},
        Eigen::Matrix<double, 1, 1>(r), 1e12);
    EXPECT_EQ(res.status, FilterStatus::kOk);
    steps = res.steps;
    // The error of the mean in posterior standard deviations, the worse of the two states.
    return std::max(std::abs(filter.mean().x(0) - ex) / post_sx,
                    std::abs(filter.mean().x(1) - ed) / post_sd);
  };
  int steps_one = 0, steps_progressive = 0;
  const double one = posterior_error(1e300, steps_one);
  const double progressive = posterior_error(SigmaPointParams{}.spread_per_step, steps_progressive);
  std::printf("posterior mean error: one step %.3f sigma, %d progressive steps %.3f sigma\n", one,
              steps_progressive, progressive);
  EXPECT_EQ(steps_one, 1);
  EXPECT_GT(steps_progressive, 1);
  EXPECT_LT(progressive, 0.5 * one);
  EXPECT_LT(progressive, 0.1);
}

// For a linear model the line through any point is the model itself: an update linearised at a
// reference far from the mean is the Kalman update.
TEST(SigmaPointUpdate, LinearisedAtAnyReferenceIsTheKalmanUpdateForALinearModel) {
  Pair p = make_filter_pair(700);
  std::mt19937_64 rng(701);
  std::normal_distribution<double> n(0.0, 1.0);
  const VecZ z = VecZ::NullaryExpr([&] { return n(rng); });
  State ref = p.ukf.mean();
  for (int i = 0; i < N; ++i) ref.x(i) += 3.0 * n(rng);
  const UpdateResult res = p.ukf.update<kMeasB, kMeasL, 2, 3>(
      measure(p.sys), z, Active{true, true, true}, p.sys.r, 1e12, &ref);
  EXPECT_EQ(res.status, FilterStatus::kOk);
  EXPECT_EQ(res.used, 3);
  p.kf.update(p.sys, z, Active{true, true, true});
  expect_same(p.ukf, p.kf);
  EXPECT_NEAR(res.nis, p.kf.nis, 1e-9 * (1.0 + p.kf.nis));
}

// Linearised at a reference with the points drawn close (linearised_alpha_scale, the refinement's
// last step), the update is the extended Kalman filter's at that reference: the measurement's
// Jacobian there, the same slope for the mean and the covariance. With the points over the whole
// spread of a wide prior, the regression's slopes differ from the Jacobian (here by 0.5 %). (The
// second-order cross terms, which widen the innovation covariance of a frame whose prediction
// spreads far wider than its noise whatever the points' spread, are left out of both.)
TEST(SigmaPointUpdate, LinearisedWithPointsDrawnCloseIsTheJacobianUpdateAtTheReference) {
  using S2 = EuclideanState<double, 2>;
  const double f = 833.0, r = 1.0, z = 40.0;
  S2 mean, ref;
  mean.x << 0.05, 0.7;
  ref.x << 0.04, 0.65;
  Eigen::Matrix2d p0;
  p0 << 0.01, 0.002, 0.002, 0.01;  // 10 cm on a depth of 70 cm
  const auto h = [&](const S2& st, Eigen::Matrix<double, 1, 1>& zp, std::array<bool, 1>&) {
    zp(0) = f * st.x(0) / st.x(1);
  };
  const auto update = [&](double alpha_scale) {
    SigmaPointParams params;
    params.linearised_alpha_scale = alpha_scale;
    params.cross_terms_above = INFINITY;
    SigmaPointFilter<S2> filter(params);
    filter.reset(mean, p0);
    const UpdateResult res = filter.template update<0, 2, 1, 1>(
        h, Eigen::Matrix<double, 1, 1>(z), std::array<bool, 1>{true},
        Eigen::Matrix<double, 1, 1>(r), 1e12, &ref);
    EXPECT_EQ(res.status, FilterStatus::kOk);
    return filter;
  };
  // The extended Kalman filter linearised at ref, by hand.
  const Eigen::RowVector2d jac(f / ref.x(1), -f * ref.x(0) / (ref.x(1) * ref.x(1)));
  const double s = jac * p0 * jac.transpose() + r;
  const Eigen::Vector2d gain = p0 * jac.transpose() / s;
  const double nu = z - f * ref.x(0) / ref.x(1) - jac * (mean.x - ref.x);
  const Eigen::Vector2d ekf_mean = mean.x + gain * nu;
  const Eigen::Matrix2d ekf_cov = p0 - gain * s * gain.transpose();

  const SigmaPointFilter<S2> close = update(1.0 / 64.0);
  EXPECT_LT((close.mean().x - ekf_mean).norm(), 1e-4 * (ekf_mean - mean.x).norm());
  EXPECT_LT((close.covariance() - ekf_cov).norm(), 1e-4 * ekf_cov.norm());
  const SigmaPointFilter<S2> spread = update(1.0);
  EXPECT_GT((spread.covariance() - ekf_cov).norm(), 1e-3 * ekf_cov.norm());
}

TEST(SigmaPointUpdate, NoActiveBlockIsNoMeasurement) {
  Pair p = make_filter_pair(500);
  const State before = p.ukf.mean();
  const UpdateResult res =
      update(p.ukf, measure(p.sys), VecZ::Zero(), Active{false, false, false}, p.sys.r, kGate);
  EXPECT_EQ(res.status, FilterStatus::kNoMeasurement);
  EXPECT_EQ(res.used, 0);
  EXPECT_EQ(p.ukf.mean().x, before.x);
}

TEST(SigmaPointFailure, NonPositiveDefiniteBlockIsRefusedAndFilterUnchanged) {
  std::mt19937_64 rng(600);
  const LinearSystem sys = LinearSystem::make(rng);
  MatN p0 = correlated_covariance(rng);
  State s0;
  s0.x.setLinSpaced(1.0, 8.0);
  // Indefinite in the predicted block [0, 4): a 2x2 minor with |correlation| > 1.
  MatN bad = p0;
  bad(0, 1) = bad(1, 0) = 2.0 * std::sqrt(bad(0, 0) * bad(1, 1));
  // Unchanged means bit for bit what the filter held before; not `bad` itself, which reset()
  // symmetrises and which is symmetric only to rounding where m m^T is computed with fused
  // multiply-adds (aarch64).
  Filter f;
  f.reset(s0, bad);
  Filter before = f;
  EXPECT_EQ(predict(f, sys), FilterStatus::kCovarianceNotPositiveDefinite);
  EXPECT_EQ(f.mean().x, before.mean().x);
  EXPECT_EQ(f.covariance(), before.covariance());
  // Indefinite in the measured block [2, 8): a negative variance.
  bad = p0;
  bad(6, 6) = -0.1;
  f.reset(s0, bad);
  before = f;
  const UpdateResult res =
      update(f, measure(sys), VecZ::Zero(), Active{true, true, true}, sys.r, 1e12);
  EXPECT_EQ(res.status, FilterStatus::kCovarianceNotPositiveDefinite);
  EXPECT_EQ(f.mean().x, before.mean().x);
  EXPECT_EQ(f.covariance(), before.covariance());
  // The predict does not sample x[6], so it still works and only touches what it may.
  EXPECT_EQ(predict(f, sys), FilterStatus::kOk);
  EXPECT_EQ(f.covariance()(6, 6), -0.1);
}

}  // namespace
}  // namespace mirrorcal
