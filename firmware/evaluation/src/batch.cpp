#include "mirrorcal/evaluation/batch.hpp"

#include <algorithm>
#include <cmath>
#include <memory>

#include <time.h>  // clock_gettime (POSIX)

#include "mirrorcal/calibration/history.hpp"
#include "mirrorcal/estimator/imu_transition.hpp"
#include "mirrorcal/evaluation/batch_factors.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/loop/loop.hpp"

namespace mirrorcal::evaluation {

using namespace batch;

namespace {

using Motion = std::array<double, kMotionSize>;
using Attitude = std::array<double, kQuatSize>;
using Vec3d = Eigen::Vector3d;
constexpr double kNsToS = 1e-9;
// The first full solve's stretch of data (s); later ones follow each growth by kFullSolveGrowth.
constexpr double kFirstSolveS = 3.0;
constexpr double kFullSolveGrowth = 1.5;
// The frames' IMU times follow the time offset's estimate until it moves by less than this (s):
// the model extrapolates from a state's time to the exposure at second order, exact enough over
// a fraction of a millisecond, not over a guess's tens (docs/estimator.md, "The batch
// reference").
constexpr double kRetimeS = 2e-4;
// A slow rig's offset is weakly seen, and each whole solve of the growing trajectory may move it by
// milliseconds: a cap reached too soon leaves the last solve extrapolating that far, off its
// optimum (docs/estimator.md, "The batch reference").
constexpr int kMaxRetimings = 16;
// Levenberg-Marquardt stops when a step changes the cost by less than this share of it. The
// in-plane position of the rig, which the mirror does not see, drifts along the IMU's integration
// with next to no cost, and the iteration creeps along it for a hundred steps while the
// calibration hardly moves; the final tolerance keeps it within a few hundredths of its sigmas
// of a far tighter one's solution (docs/estimator.md, "The batch reference").
constexpr double kGrowthTolerance = 1e-6, kFinalTolerance = 1e-8;

// The IMU's signal cut at the states' times, as the loop's filter integrates it.
class ImuStream {
 public:
  explicit ImuStream(const std::vector<ImuSample>& imu) : imu_(imu) {
    std::vector<std::int64_t> steps;
    for (std::size_t j = 1; j < imu.size(); ++j) steps.push_back(imu[j].t_ns - imu[j - 1].t_ns);
    std::nth_element(steps.begin(), steps.begin() + static_cast<long>(steps.size() / 2),
                     steps.end());
    period_ns_ = steps.empty() ? 1 : std::max<std::int64_t>(1, steps[steps.size() / 2]);
    gap_ns_ =
        static_cast<std::int64_t>(loop::LoopConfig{}.gap_periods * static_cast<double>(period_ns_));
  }
  std::int64_t first_ns() const { return imu_.front().t_ns; }
  std::int64_t last_ns() const { return imu_.back().t_ns; }

  // The pieces from t0 to t1 (first_ns() <= t0 < t1 <= last_ns()), the gap each lies in beside it
  // (s; 0 outside gaps).
  void pieces(std::int64_t t0, std::int64_t t1, std::vector<ImuPiece>& out,
              std::vector<double>& gaps) const {
    out.clear();
    gaps.clear();
    for (std::size_t j = interval_at(t0); j + 1 < imu_.size() && imu_[j].t_ns < t1; ++j) {
      const std::int64_t a = std::max(t0, imu_[j].t_ns), b = std::min(t1, imu_[j + 1].t_ns);
      if (b <= a) continue;
      const bool gap = is_gap(j);
      // Across a gap, steps of one nominal period on the straight line (as the loop crosses one).
      const std::int64_t step = gap ? period_ns_ : b - a;
      for (std::int64_t t = a; t < b; t += step) {
        ImuPiece p;
        const ImuSample* before = before_of(j);
        p.s0 = imu_signal_at(before, imu_[j], imu_[j + 1], t);
        p.s1 = imu_signal_at(before, imu_[j], imu_[j + 1], std::min(b, t + step));
        p.has_before = before != nullptr;
        if (before != nullptr) p.before = *before;
        out.push_back(p);
        gaps.push_back(gap ? static_cast<double>(imu_[j + 1].t_ns - imu_[j].t_ns) * kNsToS : 0.0);
      }
    }
  }

  // The IMU signal at t and the gyro's rate of change there.
  FrameExposure exposure_at(std::int64_t t_ns) const {
    const std::size_t j = std::min(interval_at(t_ns), imu_.size() - 2);
    const ImuSample s = imu_signal_at(before_of(j), imu_[j], imu_[j + 1], t_ns);
    FrameExposure e;
    e.gyro = s.gyro;
    e.accel = s.accel;
    const double dt = static_cast<double>(imu_[j + 1].t_ns - imu_[j].t_ns) * kNsToS;
    if (dt > 0.0) e.gyro_rate = (imu_[j + 1].gyro - imu_[j].gyro) / dt;
    return e;
  }

 private:
  // The interval [j, j + 1] that holds t (the last one at or before it).
  std::size_t interval_at(std::int64_t t) const {
    const auto it = std::upper_bound(imu_.begin(), imu_.end(), t,
                                     [](std::int64_t v, const ImuSample& s) { return v < s.t_ns; });
    return static_cast<std::size_t>(std::max<long>(0, (it - imu_.begin()) - 1));
  }
  bool is_gap(std::size_t j) const { return imu_[j + 1].t_ns - imu_[j].t_ns > gap_ns_; }
  // The sample before interval j for the parabola, unless a gap lies next to it.
  const ImuSample* before_of(std::size_t j) const {
    if (j == 0 || is_gap(j) || is_gap(j - 1)) return nullptr;
    return &imu_[j - 1];
  }

  const std::vector<ImuSample>& imu_;
  std::int64_t period_ns_ = 1, gap_ns_ = 1;
};

// One state's frame: its markers.
struct StateFrame {
  std::int64_t t_cam_ns = 0;
  std::vector<io::ObservedMarker> markers;
  double anchor_row = 0.0;  // the mean row of its markers, which its state's time is taken at
};

using MotionState = MirrorState<double, 1, 0>;

class BatchSolver {
 public:
  BatchSolver(const BatchInput& in, const BatchOptions& options)
      : in_(in), options_(options), imu_(*in.imu), m_(in.priors.features_c.size()) {}

  bool solve(calibration::CalibrationResult& result, BatchReport& report, std::string& error);

 private:
  bool select_frames(std::string& error);
  void start_parameters();
  // The states' IMU times for the time offset t_d: frames whose time falls outside the IMU's span,
  // or not after the state before, are left out.
  void place_states(double t_d);
  MotionState state(std::size_t k) const {
    return motion_state(motion_[k].data(), attitude_[k].data());
  }
  void set_state(std::size_t k, const MotionState& x);
  void step(MotionState& x, const ImuPiece& piece) const {
    propagate_imu(x, piece.s0, piece.s1, in_.config.gravity_n,
                  piece.has_before ? &piece.before : nullptr);
  }
  MotionState integrate(MotionState x, const std::vector<ImuPiece>& pieces) const {
    for (const ImuPiece& piece : pieces) step(x, piece);
    return x;
  }
  // State k integrated on from the state before it, and its factors made.
  void make_state(std::size_t k);
  void make_factors(std::size_t k, std::vector<ImuPiece> pieces, const std::vector<double>& gaps);
  // The problem over states [a, b] (a held unless it is the first), the calibration free or held.
  void build_problem(ceres::Problem& problem, std::size_t a, std::size_t b, bool calibration_free);
  void add_calibration(ceres::Problem& problem, bool free);
  bool solve_range(std::size_t a, std::size_t b, bool calibration_free, std::string& error);
  // The trajectory grown stretch by stretch (BatchOptions::window_s) and solved whole as it grows
  // by kFullSolveGrowth, the states' times following the time offset's estimate (retime).
  bool solve_trajectory(std::string& error);
  // The states' times moved to the time offset's estimate: those within the solved span (states
  // [0, solved]) integrated from the old ones; returns the last new state that span holds.
  std::size_t retime(std::size_t solved);
  bool covariance(calibration::CalibrationResult& result, std::string& error);
  void fill_result(calibration::CalibrationResult& result);
  void say(const std::string& line) const {
    if (options_.progress) options_.progress(line);
  }
  double seconds_into(std::size_t k) const {
    return static_cast<double>(times_[k] - times_[0]) * kNsToS;
  }
  std::vector<const double*> calibration_blocks() const;
  // The parameter blocks of state k's IMU factor (from state k - 1) and of its r-th
  // reprojection, in their factors' order.
  std::vector<double*> imu_factor_blocks(std::size_t k) {
    std::vector<double*> b = {motion_[k - 1].data(), attitude_[k - 1].data(), motion_[k].data(),
                              attitude_[k].data()};
    if (ni_ > 0) b.push_back(imu_intrinsics_.data());
    return b;
  }
  std::vector<double*> reprojection_blocks(std::size_t k, std::size_t r) {
    const auto marker = static_cast<std::size_t>(frames_[k - 1].markers[r].id);
    std::vector<double*> b = {motion_[k].data(), attitude_[k].data(),     p_b_c_.data(),
                              q_b_c_.data(),     markers_[marker].data(), &t_d_,
                              camera_.data()};
    if (ni_ > 0) b.push_back(imu_intrinsics_.data());
    return b;
  }

  const BatchInput& in_;
  BatchOptions options_;
  ImuStream imu_;
  std::size_t m_;
  int nk_ = 0;
  Pinhole<double> camera_model_;        // the lens model and shutter; the rest is the camera block
  std::vector<StateFrame> all_frames_;  // with markers
  std::vector<StateFrame> frames_;      // [k - 1]: state k's (within the IMU's span)
  // State 0 at the first IMU sample, state k >= 1 at frame k - 1.
  std::vector<std::int64_t> times_;
  std::vector<Motion> motion_;
  std::vector<Attitude> attitude_;
  std::vector<std::unique_ptr<ceres::CostFunction>> imu_factors_;  // [k]: k - 1 to k (k >= 1)
  std::vector<std::vector<std::unique_ptr<ceres::CostFunction>>> reprojections_;  // [k]
  std::unique_ptr<ceres::CostFunction> start_prior_;
  std::vector<std::unique_ptr<ceres::CostFunction>> calibration_priors_;
  // The calibration.
  std::array<double, 3> p_b_c_{};
  Attitude q_b_c_{};
  std::vector<std::array<double, 3>> markers_;
  double t_d_ = 0.0, t_d_anchor_ = 0.0;
  std::array<double, kCameraSize> camera_{};
  // The IMU's intrinsics (ni_ of the block's 24 estimated; none for the ideal IMU's model).
  int ni_ = 0;
  std::array<double, kImuIntrinsicsSize> imu_intrinsics_{};
  RightQuaternionManifold quaternion_manifold_;
  std::unique_ptr<ceres::Manifold> camera_manifold_, imu_manifold_;
  BatchReport report_;
};

// The calling thread's CPU time (s): the solver runs on it alone (num_threads 1), and a campaign
// runs other calibrations on other threads of the process meanwhile.
double thread_cpu_s() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

Attitude attitude_of(const Eigen::Quaterniond& q) {
  const Eigen::Quaterniond n = q.normalized();
  return {n.x(), n.y(), n.z(), n.w()};
}

bool BatchSolver::select_frames(std::string& error) {
  for (const io::ObservedFrame& f : *in_.frames) {
    StateFrame s;
    s.t_cam_ns = f.t_ns;
    for (const io::ObservedMarker& mk : f.markers) {
      if (mk.id < 0 || static_cast<std::size_t>(mk.id) >= m_) continue;
      s.markers.push_back(mk);
      s.anchor_row += mk.v;
    }
    if (s.markers.empty()) continue;
    s.anchor_row /= static_cast<double>(s.markers.size());
    all_frames_.push_back(std::move(s));
  }
  if (all_frames_.empty() || in_.imu->size() < 3) {
    error = "nothing to solve: no frame with markers, or fewer than 3 IMU samples";
    return false;
  }
  return true;
}

void BatchSolver::start_parameters() {
  const io::RecordingPriors& pr = in_.priors;
  nk_ = in_.camera_parameters;
  camera_model_ = nk_ > 0 ? pr.intrinsics_guess : in_.config.intrinsics;
  camera_model_.distortion = in_.config.intrinsics.distortion;
  camera_model_.line_delay_s = in_.config.intrinsics.line_delay_s;
  camera_model_.exposure_s = in_.config.intrinsics.exposure_s;
  const Pinhole<double>& k = camera_model_;
  camera_ = {k.fu, k.fv, k.cu, k.cv, k.skew, k.coeffs[0], k.coeffs[1], k.coeffs[2], k.coeffs[3]};
  for (int j = 0; j < 3; ++j) p_b_c_[static_cast<std::size_t>(j)] = pr.p_b_c(j);
  q_b_c_ = attitude_of(pr.q_b_c);
  markers_.resize(m_);
  for (std::size_t i = 0; i < m_; ++i)
    for (int j = 0; j < 3; ++j) markers_[i][static_cast<std::size_t>(j)] = pr.features_c[i](j);
  t_d_ = t_d_anchor_ = pr.t_d;

  // The camera parameters not estimated are held (fu fv cu cv are estimated with any).
  std::vector<int> held;
  for (int j = 0; j < kCameraSize; ++j) {
    const bool estimated = nk_ > 0 && (j < 4 || (j == 4 && nk_ == 5) || (j >= 5 && nk_ == 8));
    if (!estimated) held.push_back(j);
  }
  if (nk_ > 0) camera_manifold_ = std::make_unique<ceres::SubsetManifold>(kCameraSize, held);

  calibration_priors_.clear();
  const Vec3d sp = pr.sigma_p_b_c;
  calibration_priors_.emplace_back(vector_prior(p_b_c_.data(), sp.data(), 3));
  calibration_priors_.emplace_back(RotationPrior::create(pr.q_b_c.normalized(), pr.sigma_rot_b_c));
  for (std::size_t i = 0; i < m_; ++i) {
    const Vec3d s = pr.sigma_features_c[i];
    calibration_priors_.emplace_back(vector_prior(markers_[i].data(), s.data(), 3));
  }
  calibration_priors_.emplace_back(vector_prior(&t_d_, &pr.sigma_t_d, 1));
  if (nk_ > 0) {
    std::array<double, kCameraSize> sigma{};
    for (std::size_t j = 0; j < 5; ++j) sigma[j] = pr.sigma_intrinsics[j];
    for (std::size_t j = 0; j < 4; ++j) sigma[5 + j] = pr.sigma_distortion[j];
    for (const int j : held) sigma[static_cast<std::size_t>(j)] = 0.0;
    calibration_priors_.emplace_back(vector_prior(camera_.data(), sigma.data(), kCameraSize));
  }
  // The IMU's intrinsics: the model's first ni_ entries of the block (for_each_entry's order),
  // the rest held at the guess's (an ideal IMU's beyond the model).
  ni_ = imu_intrinsics_dim(in_.imu_model);
  imu_intrinsics_ = imu_block_of(in_.imu_guess);
  if (ni_ > 0) {
    std::vector<int> held_imu;
    for (int j = ni_; j < kImuIntrinsicsSize; ++j) held_imu.push_back(j);
    if (!held_imu.empty())
      imu_manifold_ = std::make_unique<ceres::SubsetManifold>(kImuIntrinsicsSize, held_imu);
    const std::array<double, kImuIntrinsicsSize> all =
        imu_intrinsics_sigmas<kImuIntrinsicsSize>(in_.imu_tolerances);
    std::array<double, kImuIntrinsicsSize> sigma{};
    for (std::size_t j = 0; j < static_cast<std::size_t>(ni_); ++j) sigma[j] = all[j];
    calibration_priors_.emplace_back(
        vector_prior(imu_intrinsics_.data(), sigma.data(), kImuIntrinsicsSize));
  }

  // The first state: the priors' guess at the first IMU sample, where the filter starts.
  MotionState x;
  x.p = pr.p_n_b;
  x.v = pr.v_n_b;
  x.b_a = pr.b_a;
  x.b_g = pr.b_g;
  x.q_n_b = pr.q_n_b.normalized();
  motion_.assign(1, Motion{});
  attitude_.assign(1, Attitude{});
  set_state(0, x);
  Eigen::Matrix<double, kImuResiduals, 1> sigma;
  sigma << pr.sigma_p_n_b, pr.sigma_v_n_b, pr.sigma_b_a, pr.sigma_b_g, pr.sigma_rot_n_b;
  start_prior_.reset(StartPrior::create(motion_[0].data(), x.q_n_b, sigma));
}

void BatchSolver::place_states(double t_d) {
  times_.assign(1, imu_.first_ns());
  frames_.clear();
  for (const StateFrame& f : all_frames_) {
    const double anchor_s = t_d + camera_model_.line_delay_s * f.anchor_row;
    const std::int64_t t = f.t_cam_ns + static_cast<std::int64_t>(std::llround(anchor_s * 1e9));
    if (t <= times_.back() || t >= imu_.last_ns()) continue;
    times_.push_back(t);
    frames_.push_back(f);
  }
  const std::size_t n = times_.size();
  motion_.resize(n);
  attitude_.resize(n);
  imu_factors_.clear();
  imu_factors_.resize(n);
  reprojections_.clear();
  reprojections_.resize(n);
}

void BatchSolver::set_state(std::size_t k, const MotionState& x) {
  const Vec3d parts[4] = {x.p, x.v, x.b_a, x.b_g};
  for (std::size_t b = 0; b < 4; ++b)
    for (std::size_t j = 0; j < 3; ++j) motion_[k][3 * b + j] = parts[b](static_cast<long>(j));
  attitude_[k] = attitude_of(x.q_n_b);
}

void BatchSolver::make_state(std::size_t k) {
  std::vector<ImuPiece> pieces;
  std::vector<double> gaps;
  imu_.pieces(times_[k - 1], times_[k], pieces, gaps);
  set_state(k, integrate(state(k - 1), pieces));
  make_factors(k, std::move(pieces), gaps);
}

void BatchSolver::make_factors(std::size_t k, std::vector<ImuPiece> pieces,
                               const std::vector<double>& gaps) {
  // The integration's covariance over the pieces, at the estimate it starts from.
  MotionState x = state(k - 1);
  using Cov = Eigen::Matrix<double, kImuResiduals, kImuResiduals>;
  Cov p = Cov::Zero();
  for (std::size_t j = 0; j < pieces.size(); ++j) {
    const ImuPiece& piece = pieces[j];
    const Cov f = imu_transition(x, piece.s0, piece.s1).dense();
    const ImuNoise noise =
        gaps[j] > 0.0 ? noise_across_gap(in_.config.imu, in_.config.gap, gaps[j]) : in_.config.imu;
    const double dt = static_cast<double>(piece.s1.t_ns - piece.s0.t_ns) * kNsToS;
    p = f * p * f.transpose() + imu_process_noise<double, kImuResiduals>(noise, dt);
    step(x, piece);
  }
  const ImuSqrtInformation sqrt_information = Eigen::LLT<Cov>(p).matrixL().solve(Cov::Identity());
  imu_factors_[k].reset(
      ImuFactor::create(std::move(pieces), in_.config.gravity_n, sqrt_information, ni_ > 0));

  const StateFrame& frame = frames_[k - 1];
  FrameExposure e = imu_.exposure_at(times_[k]);
  e.stamp_minus_state_s = static_cast<double>(frame.t_cam_ns - times_[k]) * kNsToS;
  reprojections_[k].clear();
  for (const io::ObservedMarker& mk : frame.markers) {
    const double readout_s = camera_model_.line_delay_s * mk.v;
    reprojections_[k].emplace_back(
        ReprojectionFactor::create(e, Eigen::Vector2d(mk.u, mk.v), readout_s, camera_model_,
                                   in_.config.gravity_n, in_.config.pixel_sigma, ni_ > 0));
  }
}

std::vector<const double*> BatchSolver::calibration_blocks() const {
  std::vector<const double*> blocks = {p_b_c_.data(), q_b_c_.data()};
  for (const auto& mk : markers_) blocks.push_back(mk.data());
  blocks.push_back(&t_d_);
  if (nk_ > 0) blocks.push_back(camera_.data());
  if (ni_ > 0) blocks.push_back(imu_intrinsics_.data());
  return blocks;
}

void BatchSolver::add_calibration(ceres::Problem& problem, bool free) {
  problem.AddParameterBlock(p_b_c_.data(), 3);
  problem.AddParameterBlock(q_b_c_.data(), kQuatSize, &quaternion_manifold_);
  for (auto& mk : markers_) problem.AddParameterBlock(mk.data(), 3);
  problem.AddParameterBlock(&t_d_, 1);
  problem.AddParameterBlock(camera_.data(), kCameraSize, camera_manifold_.get());
  if (ni_ > 0)
    problem.AddParameterBlock(imu_intrinsics_.data(), kImuIntrinsicsSize, imu_manifold_.get());
  if (!free || nk_ == 0) problem.SetParameterBlockConstant(camera_.data());
  if (!free) {
    for (const double* b : calibration_blocks())
      problem.SetParameterBlockConstant(const_cast<double*>(b));
    return;
  }
  // The priors, in calibration_blocks()'s order.
  const std::vector<const double*> blocks = calibration_blocks();
  for (std::size_t j = 0; j < blocks.size(); ++j)
    problem.AddResidualBlock(calibration_priors_[j].get(), nullptr, const_cast<double*>(blocks[j]));
}

ceres::Problem::Options problem_options() {
  ceres::Problem::Options o;
  o.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  return o;
}

void BatchSolver::build_problem(ceres::Problem& problem, std::size_t a, std::size_t b,
                                bool calibration_free) {
  add_calibration(problem, calibration_free);
  for (std::size_t k = a; k <= b; ++k) {
    problem.AddParameterBlock(motion_[k].data(), kMotionSize);
    problem.AddParameterBlock(attitude_[k].data(), kQuatSize, &quaternion_manifold_);
  }
  if (a == 0) {
    problem.AddResidualBlock(start_prior_.get(), nullptr, motion_[0].data(), attitude_[0].data());
  } else {
    problem.SetParameterBlockConstant(motion_[a].data());
    problem.SetParameterBlockConstant(attitude_[a].data());
  }
  for (std::size_t k = a + 1; k <= b; ++k) {
    problem.AddResidualBlock(imu_factors_[k].get(), nullptr, imu_factor_blocks(k));
    for (std::size_t r = 0; r < reprojections_[k].size(); ++r) {
      const std::vector<double*> blocks = reprojection_blocks(k, r);
      // A marker the estimate puts behind the camera cannot start a solve (Ceres refuses a
      // problem it cannot evaluate at its start): it waits for a later solve from a better one.
      double residual[2];
      if (!reprojections_[k][r]->Evaluate(blocks.data(), residual, nullptr)) continue;
      problem.AddResidualBlock(reprojections_[k][r].get(), nullptr, blocks);
    }
  }
}

bool BatchSolver::solve_range(std::size_t a, std::size_t b, bool calibration_free,
                              std::string& error) {
  const bool last = calibration_free && a == 0 && b + 1 == times_.size();
  ceres::Problem problem(problem_options());
  build_problem(problem, a, b, calibration_free);
  ceres::Solver::Options o;
  o.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  o.max_num_iterations = options_.max_iterations;
  o.num_threads = 1;  // bit-identical results
  // A step that puts a marker behind the camera is rejected as it should be, without a WARNING
  // line on stderr for each.
  o.logging_type = ceres::SILENT;
  o.function_tolerance = last ? kFinalTolerance : kGrowthTolerance;
  o.gradient_tolerance = 1e-12;
  o.parameter_tolerance = 1e-10;
  ceres::Solver::Summary summary;
  ceres::Solve(o, &problem, &summary);
  ++report_.solves;
  report_.iterations += static_cast<int>(summary.iterations.size());
  if (!summary.IsSolutionUsable()) {
    error = "the solver failed: " + summary.message;
    return false;
  }
  if (last) {
    report_.final_iterations = static_cast<int>(summary.iterations.size());
    report_.converged = summary.termination_type == ceres::CONVERGENCE;
  }
  return true;
}

bool BatchSolver::solve_trajectory(std::string& error) {
  std::size_t done = 0;  // states solved
  double solved_s = 0.0;
  for (;;) {
    const bool first = done == 0;
    if (done + 1 < times_.size()) {
      // The next stretch, integrated on from the last state solved.
      const double until_s = seconds_into(done) + (first ? kFirstSolveS : options_.window_s);
      std::size_t end = done + 1;
      make_state(end);
      while (end + 1 < times_.size() && seconds_into(end + 1) <= until_s) make_state(++end);
      if (!first) {
        // Solved with the stretch before it, the calibration held.
        std::size_t from = done;
        while (from > 0 && seconds_into(done) - seconds_into(from - 1) <= options_.window_s) --from;
        if (!solve_range(from, end, false, error)) return false;
      }
      done = end;
    }
    const bool all = done + 1 == times_.size();
    if (!first && !all && seconds_into(done) < kFullSolveGrowth * solved_s) continue;
    if (!solve_range(0, done, true, error)) return false;
    solved_s = seconds_into(done);
    say("batch: solved the first " + std::to_string(static_cast<int>(solved_s)) + " s (" +
        std::to_string(done) + " frames)");
    if (std::abs(t_d_ - t_d_anchor_) > kRetimeS && report_.retimings < kMaxRetimings) {
      done = retime(done);  // and solved again, with the rest, from there
      say("batch: the frames moved to the time offset's estimate, " + std::to_string(t_d_ * 1e3) +
          " ms");
      continue;
    }
    if (all) {
      // Converged only where the states' times are the offset's estimate too.
      report_.converged = report_.converged && std::abs(t_d_ - t_d_anchor_) <= kRetimeS;
      return true;
    }
  }
}

std::size_t BatchSolver::retime(std::size_t solved) {
  // The states solved at the old times, to integrate the new ones on from.
  const std::vector<std::int64_t> old_times(times_.begin(),
                                            times_.begin() + static_cast<long>(solved) + 1);
  const std::vector<Motion> old_motion = motion_;
  const std::vector<Attitude> old_attitude = attitude_;
  t_d_anchor_ = t_d_;
  place_states(t_d_anchor_);
  motion_[0] = old_motion[0];
  attitude_[0] = old_attitude[0];
  std::vector<ImuPiece> pieces;
  std::vector<double> gaps;
  std::size_t last = 0;
  for (std::size_t k = 1; k < times_.size() && times_[k] <= old_times.back(); last = k++) {
    // From the latest old state at or before the new time.
    const auto j = static_cast<std::size_t>(
        std::upper_bound(old_times.begin(), old_times.end(), times_[k]) - old_times.begin() - 1);
    const MotionState x = motion_state(old_motion[j].data(), old_attitude[j].data());
    if (times_[k] > old_times[j]) imu_.pieces(old_times[j], times_[k], pieces, gaps);
    set_state(k, times_[k] > old_times[j] ? integrate(x, pieces) : x);
  }
  for (std::size_t k = 1; k <= last; ++k) {
    imu_.pieces(times_[k - 1], times_[k], pieces, gaps);
    make_factors(k, pieces, gaps);
  }
  ++report_.retimings;
  return last;
}

bool BatchSolver::covariance(calibration::CalibrationResult& result, std::string& error) {
  ceres::Problem problem(problem_options());
  build_problem(problem, 0, times_.size() - 1, true);
  ceres::Covariance::Options o;
  o.algorithm_type = ceres::SPARSE_QR;
  o.num_threads = 1;
  ceres::Covariance covariance(o);
  const std::vector<const double*> blocks = calibration_blocks();
  std::vector<std::pair<const double*, const double*>> pairs;
  for (std::size_t i = 0; i < blocks.size(); ++i)
    for (std::size_t j = i; j < blocks.size(); ++j) pairs.emplace_back(blocks[i], blocks[j]);
  if (!covariance.Compute(pairs, &problem)) {
    error = "the information matrix is singular: the data and priors do not fix the calibration";
    return false;
  }
  // The calibration block, then the IMU's intrinsics (as the filter's result keeps them apart).
  const int dim = calibration_layout(static_cast<int>(m_), nk_).size();
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> c(dim + ni_, dim + ni_);
  if (!covariance.GetCovarianceMatrixInTangentSpace(blocks, c.data())) {
    error = "the covariance could not be read";
    return false;
  }
  result.covariance = c.topLeftCorner(dim, dim);
  result.sigma.clear();
  for (int j = 0; j < dim; ++j) result.sigma.push_back(std::sqrt(c(j, j)));
  if (ni_ > 0) {
    result.imu.covariance = c.bottomRows(ni_);
    result.imu.sigma.clear();
    for (int j = dim; j < dim + ni_; ++j) result.imu.sigma.push_back(std::sqrt(c(j, j)));
  }
  return true;
}

void BatchSolver::fill_result(calibration::CalibrationResult& r) {
  r.p_b_c = Vec3d(p_b_c_[0], p_b_c_[1], p_b_c_[2]);
  r.q_b_c = Eigen::Quaterniond(q_b_c_[3], q_b_c_[0], q_b_c_[1], q_b_c_[2]).normalized();
  r.markers.clear();
  for (const auto& mk : markers_) r.markers.emplace_back(mk[0], mk[1], mk[2]);
  r.t_d = t_d_;
  r.intrinsics = camera_of(camera_model_, camera_.data());
  r.estimated_intrinsics = nk_;
  r.width = in_.width;
  r.height = in_.height;
  r.params = calibration::calibration_params(static_cast<int>(m_), nk_, camera_model_.distortion);
  // The reprojections' fit, as the filter's normalised innovations.
  double squares = 0.0;
  std::size_t used = 0;
  for (std::size_t s = 1; s < times_.size(); ++s)
    for (std::size_t j = 0; j < reprojections_[s].size(); ++j) {
      const std::vector<double*> blocks = reprojection_blocks(s, j);
      double res[2] = {0.0, 0.0};
      if (!reprojections_[s][j]->Evaluate(blocks.data(), res, nullptr)) continue;
      squares += res[0] * res[0] + res[1] * res[1];
      ++used;
    }
  r.markers_used = used;
  r.markers_observed = 0;
  for (const StateFrame& f : all_frames_) r.markers_observed += f.markers.size();
  r.nis_dof = 2 * used;
  r.nis_per_dof = used > 0 ? squares / static_cast<double>(r.nis_dof) : 0.0;
  report_.reprojections = used;
  report_.reprojection_rms_px = used > 0 ? in_.config.pixel_sigma * std::sqrt(r.nis_per_dof) : 0.0;
  r.passes = 1;
  const MotionState last = state(times_.size() - 1);
  r.imu.model = in_.imu_model;
  if (ni_ > 0) r.imu.intrinsics = imu_intrinsics_of(imu_intrinsics_.data());
  r.imu.noise = in_.config.imu;
  r.imu.accel_bias = last.b_a;
  r.imu.gyro_bias = last.b_g;
  r.imu.gravity_n = in_.config.gravity_n;
}

bool BatchSolver::solve(calibration::CalibrationResult& result, BatchReport& report,
                        std::string& error) {
  const double start = thread_cpu_s();
  if (!select_frames(error)) return false;
  start_parameters();
  place_states(t_d_anchor_);
  if (times_.size() < 2) {
    error = "nothing to solve: no frame with markers lies within the IMU's data";
    return false;
  }
  say("batch: " + std::to_string(times_.size() - 1) + " frames with markers, " +
      std::to_string(in_.imu->size()) + " IMU samples");
  if (!solve_trajectory(error)) return false;
  fill_result(result);
  if (!covariance(result, error)) return false;
  report_.frames = times_.size() - 1;
  report_.cpu_s = thread_cpu_s() - start;
  report = report_;
  return true;
}

}  // namespace

BatchInput simulated_batch_input(const sim::Scenario& s, const sim::SimData& data,
                                 const io::RecordingPriors& priors, int camera_parameters,
                                 ImuModel imu_model) {
  BatchInput in;
  in.imu = &data.imu;
  in.frames = &data.frames;
  in.config = scenario_config(s);
  in.priors = priors;
  in.camera_parameters = camera_parameters;
  in.imu_model = imu_model;
  in.imu_tolerances = s.priors.imu_intrinsics;  // about the ideal IMU, as simulation_prior
  in.width = s.truth.width;
  in.height = s.truth.height;
  return in;
}

TruthError truth_error(const calibration::CalibrationResult& r, const io::RecordingTruth& truth) {
  const CalibrationLayout layout = r.layout();
  TruthError t;
  t.error = Eigen::VectorXd::Zero(layout.size());
  t.error.segment<3>(layout[CalibrationGroup::kCameraPosition].begin) = r.p_b_c - truth.p_b_c;
  t.error.segment<3>(layout[CalibrationGroup::kCameraRotation].begin) =
      so3::boxminus<double>(r.q_b_c, truth.q_b_c);
  const int markers = layout[CalibrationGroup::kMarkers].begin;
  for (std::size_t i = 0; i < r.markers.size() && i < truth.features_c.size(); ++i)
    t.error.segment<3>(markers + 3 * static_cast<int>(i)) = r.markers[i] - truth.features_c[i];
  t.error(layout[CalibrationGroup::kTimeOffset].begin) = r.t_d - truth.t_d;
  const int camera = layout[CalibrationGroup::kIntrinsics].begin;
  for (int j = 0; j < r.estimated_intrinsics; ++j) {
    calibration::CalibrationResult true_camera;
    true_camera.intrinsics = truth.intrinsics;
    true_camera.estimated_intrinsics = r.estimated_intrinsics;
    t.error(camera + j) = calibration::estimated_camera_parameter(r, j) -
                          calibration::estimated_camera_parameter(true_camera, j);
  }
  if (r.covariance.rows() == layout.size())
    t.nees = t.error.dot(r.covariance.ldlt().solve(t.error));
  return t;
}

bool solve_batch(const BatchInput& input, const BatchOptions& options,
                 calibration::CalibrationResult& result, BatchReport& report, std::string& error) {
  BatchSolver solver(input, options);
  return solver.solve(result, report, error);
}

}  // namespace mirrorcal::evaluation
