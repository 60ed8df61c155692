// The mirror calibration filter: the sigma-point filter bound to the mirror model. Predict takes
// two consecutive IMU samples, update one frame of marker reflections.
#pragma once

#include "mirrorcal/estimator/imu_transition.hpp"
#include "mirrorcal/estimator/marker_counts.hpp"
#include "mirrorcal/estimator/mirror_model.hpp"
#include "mirrorcal/estimator/sigma_point_filter.hpp"

namespace mirrorcal {

struct CalibrationConfig {
  Eigen::Vector3d gravity_n{0.0, -9.81, 0.0};  // wall mirror, y up
  ImuNoise imu{};
  double pixel_sigma = 1.0;  // px, 1-sigma per coordinate
  // Intrinsics used where the state does not estimate them (stage 1, and skew when NK = 4), in
  // pixels with the origin at the top-left pixel as everywhere else. No default camera: the caller
  // sets its own (left at zero, no marker projects into the image).
  Pinhole<double> intrinsics{};
  // Squared Mahalanobis distance (2 dof) above which a marker is rejected: 99.9 % for 2 dof.
  double gate_chi2 = 13.8155;
  // Frames before the gate applies. While the calibration is still far from its prior's
  // linearisation point the innovation covariance is not trustworthy, and gating then rejects the
  // very frames that would correct it (seen with 2.7-sigma marker guesses: locked in after 20
  // frames). After 10 s at 20 Hz the estimate is near enough for the gate to mean what it says
  // (the 200 frames were chosen at 20 Hz; at the paper scenario's 60 Hz they take 3.3 s).
  std::uint64_t gate_after_frames = 200;
  SigmaPointParams sigma_points{};
  // What the rig may do across an IMU gap (predict's gap_s), and after one too long to cross
  // (restart_motion).
  GapMotion gap{};
  MotionRange restart{};
};

// Running counts over the filter's life.
struct FilterCounters {
  std::uint64_t predicts = 0;
  std::uint64_t updates = 0;
  std::uint64_t markers_used = 0;
  std::uint64_t markers_gated = 0;
  std::uint64_t markers_invalid = 0;  // once the gate is on, as markers_gated
  std::uint64_t failures = 0;         // predicts or updates refused with a numerical status
  // The normalised innovation squared of the markers used once the gate is on, and its degrees of
  // freedom (2 per marker): a filter whose model and covariance are right sees nis_sum / nis_dof
  // near 1 (a little below: the gate cuts the tail).
  double nis_sum = 0.0;
  std::uint64_t nis_dof = 0;
  // With SigmaPointParams::noise_statistics, over every update (gate on or not): the sums of
  // UpdateResult's noise_quadratic and noise_redundancy, whose ratio times the pixel noise's
  // variance is Foerstner's estimate of that variance (calibration's noise_estimate.hpp).
  double pixel_noise_quadratic = 0.0;
  double pixel_noise_redundancy = 0.0;
};

template <typename S, int M, int NK, int NI = 0>
class CalibrationFilter {
 public:
  using State = MirrorState<S, M, NK, NI>;
  using Transition = ImuTransition<S, NI>;
  using Filter = SigmaPointFilter<State>;
  using Covariance = typename Filter::Covariance;
  static constexpr int kDim = State::kDim;

  explicit CalibrationFilter(const CalibrationConfig& config)
      : config_(config),
        filter_(config.sigma_points),
        gravity_(config.gravity_n.cast<S>()),
        fixed_(config.intrinsics.template cast<S>()) {}

  // A new estimate for the filter's present time (which reset leaves as it is).
  void reset(const State& x, const Covariance& p) {
    filter_.reset(x, p);
    unsettled_ = Transition::identity();
    if constexpr (NI > 0) unsettled_noise_.setZero();
    has_unsettled_ = false;
    imu_block_checked_ = false;
    imu_block_indefinite_ = false;
  }
  // The IMU signal at the time the estimate holds for: the loop's first sample, then every
  // predict's end. Until it is known, frames are taken at t_cam + t_d with the rig at rest
  // (Exposure is then the velocity alone).
  void start_at(const ImuSample& s) {
    now_ = s;
    gyro_rate_.setZero();
    timed_ = true;
  }
  // The states to linearise frames at (linearise_along): count() points, the k-th for the frame
  // stamped stamp(k), stamps increasing. The filter asks for them in increasing k only, so that
  // they can be read from a file as they are needed (calibration/src/run.cpp).
  class LinearisationPoints {
   public:
    virtual ~LinearisationPoints() = default;
    virtual std::size_t count() const = 0;
    virtual std::int64_t stamp(std::size_t k) = 0;
    virtual const State& state(std::size_t k) = 0;
    // The rig's body rate at the k-th point (rad/s, bias-free), if the trajectory knows it better
    // than the gyro's sample at the frame: a sigma point's time offset moves the pose by this
    // rate, so the offset's slope is as noisy as the rate. Where slow tilts are not much larger
    // than the gyro's per-sample noise, the sample's noise adds to the slope's square on average
    // and the filter claims information on the offset the data do not hold (random family, the
    // offset's sigma 0.4-0.6 ms: errors 1.5-2 times it; on data without gyro noise, its sigma is
    // the data's limit). false: use the sample.
    virtual bool body_rate(std::size_t k, Vec3<S>& rate) {
      (void)k;
      (void)rate;
      return false;
    }
  };
  // Linearise the measurement of the frame stamped points->stamp(k) at points->state(k) instead
  // of at the estimate (frames not listed, and all with nullptr, at the estimate): the filter
  // becomes the Kalman filter of the measurements linearised along that trajectory, whose final
  // estimate of the constant calibration is the batch solution of the linearised problem and
  // whose covariance is what the data hold along the trajectory, whatever estimates it passed
  // through (a Gauss-Newton step over the whole recording; calibration/run.hpp). points must
  // outlive the filter's updates.
  void linearise_along(LinearisationPoints* points) {
    along_ = points;
    along_arrays_ = false;
    along_next_ = 0;
  }
  // The same from arrays: states[k] for the frame stamped stamps_ns[k], k < count.
  void linearise_along(const State* states, const std::int64_t* stamps_ns, std::size_t count) {
    along_ = nullptr;
    along_next_ = 0;
    arrays_ = ArrayPoints(states, stamps_ns, count);
    along_arrays_ = states != nullptr;  // arrays_ by name: a copy of the filter uses its own
  }

  // Defined below the class: member functions defined in it would be inline, and an extern
  // template declaration does not stop inline functions from being instantiated in every unit
  // that calls them. gap_s > 0: s0 and s1 lie in an IMU gap that long, on the straight line
  // between its samples, and the process noise covers the signal the IMU did not give
  // (noise_across_gap).
  FilterStatus predict(const ImuSample& s0, const ImuSample& s1, const ImuSample* before = nullptr,
                       double gap_s = 0.0);
  // After an IMU gap too long to propagate across: the rig is taken to be where it was before the
  // gap, at rest, within config().restart (1-sigma, correlated with nothing), at s's time; the
  // biases and the calibration states keep their estimate and covariance.
  void restart_motion(const ImuSample& s);
  UpdateResult update(const MarkerFrame<M>& frame);

  const State& state() const { return filter_.mean(); }
  // The estimate the latest update started from: the state before its frame, which holds none of
  // that frame's noise (the point to linearise that frame at again: calibration/src/run.cpp).
  const State& predicted() const { return predicted_; }

  // What a smoother over a pass needs (calibration/src/run.cpp), kept when keep_motion_steps(true):
  // from the update before the latest to the latest, the motion block's transition (the product of
  // the predicts' F; zero across a restart) and its covariance before the latest update. Off by
  // default: the board's loop does not pay the 15x15 product per predict.
  static constexpr int kMotionDim = State::kDynamicDim;
  using MotionMatrix = Eigen::Matrix<S, kMotionDim, kMotionDim>;
  struct MotionStep {
    MotionMatrix transition = MotionMatrix::Identity();
    MotionMatrix predicted_covariance = MotionMatrix::Zero();
    std::uint64_t update = 0;  // how many updates the filter had made, the latest included
  };
  void keep_motion_steps(bool on) {
    keep_steps_ = on;
    since_update_ = Transition::identity();
    restarted_since_update_ = false;
  }
  const MotionStep& motion_step() const { return step_; }
  // A frame stamped t_cam_ns against the filter's time and the IMU signal there.
  Exposure<S> exposure(std::int64_t t_cam_ns) const;
  // The covariance, the predicts' cross-covariance of the IMU block with the calibration brought
  // up to date first (settle).
  const Covariance& covariance() const {
    settle();
    return filter_.covariance();
  }
  const CalibrationConfig& config() const { return config_; }
  const FilterCounters& counters() const { return counters_; }
  Pinhole<S> intrinsics() const { return intrinsics_of(filter_.mean(), fixed_); }
  // Bytes of thread_workspace (one per configuration and thread, outside the object) that update
  // and restart_motion use (predict changes the covariance in place).
  static constexpr std::size_t workspace_bytes() {
    return Filter::template update_workspace_bytes<State::kMeasuredDim, 2 * M>() +
           sizeof(RestartWorkspace);
  }

 private:
  // restart_motion's new covariance (kDim^2 scalars: 69 KB at M = 24, double) in
  // thread_workspace, off the stack.
  struct RestartWorkspace {
    Covariance next;
  };

  CalibrationConfig config_;
  // Mutable for settle: covariance() brings the deferred cross-covariance up to date when it is
  // read (the filter is used by one thread at a time).
  mutable Filter filter_;
  Vec3<S> gravity_;
  Pinhole<S> fixed_;
  FilterCounters counters_{};
  // The state to linearise the frame stamped t_ns at (linearise_along), or nullptr; and the body
  // rate there into exposed's gyro, when the points know it (LinearisationPoints::body_rate).
  const State* linearisation_point(std::int64_t t_ns, Exposure<S>& exposed);

  class ArrayPoints final : public LinearisationPoints {
   public:
    ArrayPoints() = default;
    ArrayPoints(const State* states, const std::int64_t* stamps_ns, std::size_t count)
        : states_(states), stamps_(stamps_ns), count_(count) {}
    std::size_t count() const override { return count_; }
    std::int64_t stamp(std::size_t k) override { return stamps_[k]; }
    const State& state(std::size_t k) override { return states_[k]; }

   private:
    const State* states_ = nullptr;
    const std::int64_t* stamps_ = nullptr;
    std::size_t count_ = 0;
  };
  LinearisationPoints* along_ = nullptr;
  ArrayPoints arrays_;
  bool along_arrays_ = false;
  std::size_t along_next_ = 0;
  State predicted_{};
  // Predict moves the IMU block's own covariance at every step, but its cross-covariance with the
  // calibration P_cd only when it is needed (an update, a restart, covariance()): the steps'
  // transitions since then compose (ImuTransition::followed_by, six 3x3 products) and P_cd F^T is
  // applied once, per frame instead of per IMU sample: a predict's cost then does not grow with M.
  mutable Transition unsettled_ = Transition::identity();
  mutable bool has_unsettled_ = false;
  // With the IMU's intrinsics (NI > 0) the IMU block's own covariance waits too. A step's
  // F P_dd F^T carries the intrinsics' columns (three times the ideal IMU's predict), yet only the
  // process noise changes from step to step: the steps' F compose in unsettled_ as for P_cd, the
  // noise they add accumulates on the 15 states it reaches (F Q F^T + Q a step, at the ideal
  // IMU's cost; the ideal IMU's layout), and settle applies P_dd <- F P_dd F^T + Q once.
  struct NoNoise {};
  using MotionNoise = std::conditional_t<(NI > 0), typename Transition::MotionNoise, NoNoise>;
  mutable MotionNoise unsettled_noise_{};
  void settle() const {
    if (!has_unsettled_) return;
    if constexpr (NI > 0) settle_imu_block();
    filter_.template move_leading_cross<State::kDynamicDim>(unsettled_);
    unsettled_ = Transition::identity();
    has_unsettled_ = false;
  }
  void settle_imu_block() const {
    if constexpr (NI > 0) {  // (an explicit instantiation makes every member, NI = 0's too)
      constexpr int D = State::kDynamicDim;
      // The predicts did not read P_dd, so its check (imu_block_checked_) is made here, where it
      // is read; a failure shows at the next predict or update.
      if (!imu_block_checked_) {
        imu_block_indefinite_ = !imu_block_positive_definite();
        imu_block_checked_ = true;
      }
      Eigen::Matrix<S, D, D> p_dd;
      unsettled_.sandwich(filter_.covariance().template topLeftCorner<D, D>(), p_dd);
      // The ideal IMU's [v, b_a, b_g | p, theta] are this block's [v, b_a, b_g | (intrinsics) p,
      // theta].
      const auto at = [](int i) { return i < State::kImu ? i : i + NI; };
      for (int j = 0; j < kImuMotionDim; ++j)
        for (int i = 0; i < kImuMotionDim; ++i) p_dd(at(i), at(j)) += unsettled_noise_(i, j);
      filter_.template reset_leading<D>(filter_.mean(), p_dd);
      unsettled_noise_.setZero();
    }
  }
  bool keep_steps_ = false;
  Transition since_update_ = Transition::identity();
  bool restarted_since_update_ = false;  // the motion before a restart says nothing of after it
  MotionStep step_{};
  ImuSample now_{};  // the IMU signal at the filter's time, if timed_
  // The gyro signal's derivative there: over the last predict's interval, whose end the signal's
  // parabola gave (imu_signal_at), so a short interval does not amplify the noise.
  Vec3<S> gyro_rate_ = Vec3<S>::Zero();
  bool timed_ = false;
  // Whether the covariance's IMU block is known positive definite: its reader (predict; with the
  // IMU's intrinsics, settle) checks it when anything else (reset, update, restart) changed the
  // covariance since its last check, not after the predicts' steps, which keep it so (F P F^T +
  // Q, Q positive definite).
  mutable bool imu_block_checked_ = false;
  mutable bool imu_block_indefinite_ = false;  // settle's check failed (NI > 0)
  bool imu_block_positive_definite() const {
    constexpr int D = State::kDynamicDim;
    Eigen::Matrix<S, D, D> factor = filter_.covariance().template topLeftCorner<D, D>();
    return cholesky_in_place</*kZeroUpper=*/false>(factor);
  }
};

template <typename S, int M, int NK, int NI>
const typename CalibrationFilter<S, M, NK, NI>::State*
CalibrationFilter<S, M, NK, NI>::linearisation_point(std::int64_t t_ns, Exposure<S>& exposed) {
  LinearisationPoints* points = along_arrays_ ? &arrays_ : along_;
  if (points == nullptr) return nullptr;
  const std::size_t count = points->count();
  while (along_next_ < count && points->stamp(along_next_) < t_ns) ++along_next_;
  if (along_next_ == count || points->stamp(along_next_) != t_ns) return nullptr;
  const std::size_t k = along_next_++;
  const State& point = points->state(k);
  Vec3<S> rate;
  // The exposure's gyro is raw: the model takes the sigma point's bias (the point's) off it.
  if (timed_ && points->body_rate(k, rate))
    exposed.gyro = point.gyro_sample(rate, point.specific_force(exposed.accel));
  return &point;
}

template <typename S, int M, int NK, int NI>
Exposure<S> CalibrationFilter<S, M, NK, NI>::exposure(std::int64_t t_cam_ns) const {
  Exposure<S> e;
  e.gravity_n = gravity_;
  if (!timed_) {  // at t_cam + t_d, at rest
    e.stamp_minus_filter_s = -filter_.mean().t_d;
    e.accel = -(filter_.mean().q_n_b.conjugate() * gravity_) + filter_.mean().b_a;
    e.gyro = filter_.mean().b_g;
    if constexpr (NI > 0) {  // the raw signals at rest read through the intrinsics
      const State& x = filter_.mean();
      e.accel = accel_reading(x.imu, x.b_a, Vec3<S>(-(x.q_n_b.conjugate() * gravity_)));
      e.gyro = x.gyro_sample(Vec3<S>::Zero(), x.specific_force(e.accel));
    }
    return e;
  }
  e.stamp_minus_filter_s = S(static_cast<double>(t_cam_ns - now_.t_ns) * 1e-9);
  e.gyro = now_.gyro.template cast<S>();
  e.gyro_rate = gyro_rate_;
  e.accel = now_.accel.template cast<S>();
  return e;
}

// Only the IMU block [0, 15 + NI) moves: the 6 + 3M (+ NK) calibration states are constants. The
// mean moves by propagate_imu (Runge-Kutta on the parabola through three samples when `before` is
// given); the covariance propagates with the Jacobian F of the integration at the estimate
// (imu_transition.hpp): P_dd <- F P_dd F^T + Q, P_dc <- F P_dc (deferred: settle; with the IMU's
// intrinsics P_dd too), P_cc unchanged. To first order this is what the sigma-point transform of
// the block computes (tests/estimator show both agree, the difference falling as the square of the
// spread), at a fraction of its 31 integrations; the paper campaigns (docs/campaign) are as
// consistent with it.
template <typename S, int M, int NK, int NI>
FilterStatus CalibrationFilter<S, M, NK, NI>::predict(const ImuSample& s0, const ImuSample& s1,
                                                      const ImuSample* before, double gap_s) {
  constexpr int D = State::kDynamicDim;
  static_assert(State::kDynamicBegin == 0, "the IMU block leads the error state");
  ++counters_.predicts;
  const Covariance& p = filter_.covariance();
  if constexpr (NI == 0) {
    if (!imu_block_checked_) imu_block_indefinite_ = !imu_block_positive_definite();
    imu_block_checked_ = true;
  }
  if (imu_block_indefinite_) {
    ++counters_.failures;
    return FilterStatus::kCovarianceNotPositiveDefinite;
  }
  const double dt = static_cast<double>(s1.t_ns - s0.t_ns) * 1e-9;
  const Transition f = imu_transition(filter_.mean(), s0, s1);
  State x = filter_.mean();
  propagate_imu(x, s0, s1, gravity_, before);
  const ImuNoise noise =
      gap_s > 0.0 ? noise_across_gap(config_.imu, config_.gap, gap_s) : config_.imu;
  const bool moved_finite = x.v.allFinite() && x.p.allFinite() && x.q_n_b.coeffs().allFinite();
  if constexpr (NI > 0) {  // P_dd waits with P_cd (settle_imu_block); the noise accumulates
    typename Transition::MotionNoise q;
    if (has_unsettled_)
      f.motion_sandwich(unsettled_noise_, q);
    else  // the first step since a settle: no noise has accumulated to carry
      q.setZero();
    add_imu_process_noise<S>(noise, dt, q);
    // Q is positive definite, so every entry of F's motion rows but the intrinsics' columns
    // shows on q's diagonal from the second step since a settle on (the first carries no noise:
    // its F is checked whole); those columns are checked themselves.
    const bool f_finite =
        has_unsettled_ ? f.imu.v.allFinite() && f.imu.p.allFinite() && f.imu.theta.allFinite()
                       : f.all_finite();
    if (!q.diagonal().allFinite() || !f_finite || !moved_finite) {
      ++counters_.failures;
      return FilterStatus::kNonFinite;
    }
    unsettled_noise_ = q;
    filter_.set_mean(x);
  } else {
    // P_dd' = F (P_dd F^T); P_cd' = P_cd F^T waits in unsettled_.
    Eigen::Matrix<S, D, D> pf_t, p_dd;
    f.right_multiply_transposed(p.template topLeftCorner<D, D>(), pf_t);
    f.left_multiply(pf_t, p_dd);
    add_imu_process_noise<S>(noise, dt, p_dd);  // its seven 3x3 blocks, not a 15x15 sum
    // P is finite, so a non-finite entry of F shows on the diagonal of F P F^T: every entry of
    // F's row i enters P_dd'(i, i); the transition P_cd waits for is then finite too.
    if (!p_dd.diagonal().allFinite() || !moved_finite) {
      ++counters_.failures;
      return FilterStatus::kNonFinite;
    }
    filter_.template reset_leading<D>(x, p_dd);
  }
  // The first step since a settle is the composition itself (identity().followed_by(f) is f).
  unsettled_ = has_unsettled_ ? unsettled_.followed_by(f) : f;
  has_unsettled_ = true;
  if (keep_steps_) since_update_ = since_update_.followed_by(f);
  now_ = s1;
  timed_ = true;
  if (dt > 0.0) gyro_rate_ = ((s1.gyro - s0.gyro) / dt).template cast<S>();
  return FilterStatus::kOk;
}

template <typename S, int M, int NK, int NI>
void CalibrationFilter<S, M, NK, NI>::restart_motion(const ImuSample& s) {
  State x = filter_.mean();
  x.v.setZero();
  Covariance& p = thread_workspace<RestartWorkspace>().next;
  p = covariance();
  const MotionRange& r = config_.restart;
  const auto restart = [&p](int begin, double sigma) {
    p.template middleRows<3>(begin).setZero();
    p.template middleCols<3>(begin).setZero();
    p.template block<3, 3>(begin, begin) = Mat3<S>::Identity() * S(sigma * sigma);
  };
  restart(State::kP, r.position);
  restart(State::kV, r.velocity);
  restart(State::kTheta, r.attitude);
  reset(x, p);
  restarted_since_update_ = true;
  start_at(s);
}

template <typename S, int M, int NK, int NI>
UpdateResult CalibrationFilter<S, M, NK, NI>::update(const MarkerFrame<M>& frame) {
  predicted_ = filter_.mean();
  settle();
  if (imu_block_indefinite_) {  // its reader's check failed: nothing sound to update
    UpdateResult refused;
    refused.status = FilterStatus::kCovarianceNotPositiveDefinite;
    ++counters_.updates;
    ++counters_.failures;
    return refused;
  }
  if (keep_steps_) {
    step_.transition =
        restarted_since_update_ ? MotionMatrix::Zero().eval() : since_update_.dense();
    step_.predicted_covariance =
        filter_.covariance().template topLeftCorner<kMotionDim, kMotionDim>();
    ++step_.update;
    since_update_ = Transition::identity();
    restarted_since_update_ = false;
  }
  Eigen::Matrix<S, 2 * M, 1> z = Eigen::Matrix<S, 2 * M, 1>::Zero();
  for (int i = 0; i < M; ++i)
    if (frame.seen[i]) z.template segment<2>(2 * i) = frame.uv[i].template cast<S>();
  const Eigen::Matrix<S, 2 * M, 1> r =
      Eigen::Matrix<S, 2 * M, 1>::Constant(S(config_.pixel_sigma * config_.pixel_sigma));
  const Pinhole<S> fixed = fixed_;
  Exposure<S> exposed = exposure(frame.t_ns);
  const State* point = linearisation_point(frame.t_ns, exposed);
  const std::array<S, M> readout = marker_readout_s(fixed, frame);
  const bool gate_on = counters_.updates >= config_.gate_after_frames;
  const UpdateResult res =
      filter_.template update<State::kMeasuredBegin, State::kMeasuredDim, 2, M>(
          [&](const State& x, Eigen::Matrix<S, 2 * M, 1>& zp, std::array<bool, M>& ok) {
            predict_markers(x, fixed, exposed, readout, zp, ok);
          },
          z, frame.seen, r, gate_on ? S(config_.gate_chi2) : S(INFINITY), point);
  if (res.status == FilterStatus::kOk) imu_block_checked_ = false;
  if (gate_on && res.status == FilterStatus::kOk) {
    counters_.nis_sum += res.nis;
    counters_.nis_dof += 2 * static_cast<std::uint64_t>(res.used);
  }
  if (res.status == FilterStatus::kOk && config_.sigma_points.noise_statistics) {
    // Once the gate is on, the markers it let through are those whose innovation fell inside it:
    // a 2-dof chi-square cut at c keeps 1 - (c/2) e^(-c/2) / (1 - e^(-c/2)) of its mean (0.993
    // at 99.9 %), and so of the quadratic's expectation (exactly so where the pixel noise
    // dominates S); uncorrected, the estimate read 0.35 % low, 1.2 of its sigmas RMS off.
    double kept = 1.0;
    if (gate_on && std::isfinite(config_.gate_chi2) && config_.gate_chi2 > 0.0) {
      const double tail = std::exp(-0.5 * config_.gate_chi2);
      kept = 1.0 - 0.5 * config_.gate_chi2 * tail / (1.0 - tail);
    }
    counters_.pixel_noise_quadratic += res.noise_quadratic;
    counters_.pixel_noise_redundancy += kept * res.noise_redundancy;
  }
  ++counters_.updates;
  counters_.markers_used += static_cast<std::uint64_t>(res.used);
  counters_.markers_gated += static_cast<std::uint64_t>(res.gated);
  // As the gate rejects nothing before it is on, neither does a prediction that fails then: from
  // loose priors, a pass's first second can place a reflection behind the camera that the
  // settled estimate predicts.
  if (gate_on) counters_.markers_invalid += static_cast<std::uint64_t>(res.invalid);
  if (res.status != FilterStatus::kOk && res.status != FilterStatus::kNoMeasurement)
    ++counters_.failures;
  return res;
}

// The configurations the product uses are compiled once, in units estimator/CMakeLists.txt
// generates for every built marker count and IMU model (marker_counts.hpp), and
// filter_stage1_float.cpp.
#define MIRRORCAL_EXTERN_FILTER_(M, NK, NI) \
  extern template class CalibrationFilter<double, M, NK, NI>;
MIRRORCAL_FOR_EACH_FILTER(MIRRORCAL_EXTERN_FILTER_)
#undef MIRRORCAL_EXTERN_FILTER_
extern template class CalibrationFilter<float, 3, 0>;

}  // namespace mirrorcal
