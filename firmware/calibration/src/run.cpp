#include "mirrorcal/calibration/run.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "mirrorcal/calibration/image_markers.hpp"
#include "mirrorcal/calibration/noise_estimate.hpp"
#include "mirrorcal/calibration/statistics.hpp"

namespace mirrorcal::calibration {

std::unique_ptr<hal::ImuSource> LoopData::open_imu() const {
  if (streams) return streams->open_imu();
  return std::make_unique<io::VectorImuSource>(imu);
}

template <int M>
std::unique_ptr<hal::MarkerSource<M>> LoopData::open_markers() const {
  if (streams && image_detection)
    return std::make_unique<ImageMarkers<M>>(streams->open_images(), width, height,
                                             image_detection.get(), leds, image_blobs.get(),
                                             led_naming.get());
  if (streams) return std::make_unique<io::StreamedMarkerSource<M>>(streams->open_frames());
  return std::make_unique<io::VectorMarkerSource<M>>(frames);
}
#define MIRRORCAL_OPEN_MARKERS_(M) \
  template std::unique_ptr<hal::MarkerSource<M>> LoopData::open_markers<M>() const;
MIRRORCAL_FOR_EACH_MARKER_COUNT(MIRRORCAL_OPEN_MARKERS_)
#undef MIRRORCAL_OPEN_MARKERS_

namespace {

// The estimates a pass published at its frames, to linearise another pass along: in a temporary
// file, read by the filter as its frames come.
template <int M, int NK, int NI>
struct TrajectoryPoint {
  typename CalibrationRun<M, NK, NI>::State state;
  std::int64_t t_ns = 0;
  Eigen::Vector3d body_rate = Eigen::Vector3d::Zero();  // rad/s, bias-free
  bool has_rate = false;
};
template <int M, int NK, int NI>
class Trajectory final : public CalibrationRun<M, NK, NI>::Filter::LinearisationPoints {
 public:
  using State = typename CalibrationRun<M, NK, NI>::State;
  std::size_t count() const override { return points_.size(); }
  std::int64_t stamp(std::size_t k) override { return at(k).t_ns; }
  const State& state(std::size_t k) override { return at(k).state; }
  bool body_rate(std::size_t k, Eigen::Vector3d& rate) override {
    rate = at(k).body_rate;
    return at(k).has_rate;
  }
  void set(std::size_t k, const State& state, std::int64_t t_ns) {
    points_.set(k, {state, t_ns});
    read_ = kNone;
  }
  // Each point's body rate from the attitudes of the points either side of it (one side at the
  // ends): the gyro's samples between them, averaged, and the smoother's corrections, centred so
  // that it does not lag the motion as a fit through past samples would (which biased the offset:
  // docs/campaign/random). None across a gap longer than kMaxRateSpanS (an IMU gap, a restart).
  void set_rates() {
    const std::size_t n = points_.size();
    for (std::size_t k = 0; k < n && n > 1; ++k) {
      const TrajectoryPoint<M, NK, NI> a = points_[k > 0 ? k - 1 : 0];
      const TrajectoryPoint<M, NK, NI> b = points_[std::min(k + 1, n - 1)];
      const double span_s = static_cast<double>(b.t_ns - a.t_ns) * 1e-9;
      TrajectoryPoint<M, NK, NI> p = points_[k];
      p.has_rate = span_s > 0.0 && span_s <= kMaxRateSpanS;
      if (p.has_rate) p.body_rate = so3::boxminus<double>(b.state.q_n_b, a.state.q_n_b) / span_s;
      points_.set(k, p);
    }
    read_ = kNone;
  }

 private:
  static constexpr std::size_t kNone = ~std::size_t{0};
  static constexpr double kMaxRateSpanS = 0.25;
  const TrajectoryPoint<M, NK, NI>& at(std::size_t k) {
    if (k != read_) {
      point_ = points_[k];
      read_ = k;
    }
    return point_;
  }
  RecordStore<TrajectoryPoint<M, NK, NI>> points_{"the smoothed trajectory"};
  TrajectoryPoint<M, NK, NI> point_{};
  std::size_t read_ = kNone;
};

// Every frame a pass's loop met, used or not: the same in every replay of the same data.
template <int M, int NK, int NI>
std::uint64_t frames_met(const CalibrationRun<M, NK, NI>& run) {
  const loop::LoopCounters& c = run.loop_counters;
  return c.frames + c.frames_before_filter + c.frames_after_imu;
}

// One pass of the loop over the data from (x0, p0).
template <int M, int NK, int NI>
CalibrationRun<M, NK, NI> run_pass(const CalibrationConfig& config,
                                   const typename CalibrationRun<M, NK, NI>::State& x0,
                                   const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0,
                                   const LoopData& data,
                                   const typename CalibrationRun<M, NK, NI>::State* truth,
                                   const std::function<void(double)>& progress,
                                   const LoopHooks<M>& input,
                                   Trajectory<M, NK, NI>* along = nullptr, bool keep_motion = false,
                                   const OutlierVeto<M>* veto = nullptr) {
  using Run = CalibrationRun<M, NK, NI>;
  using Filter = typename Run::Filter;
  Run run;
  if (truth != nullptr) run.truth = *truth;
  run.has_truth = truth != nullptr;
  // The filter on the heap, made before the loop starts: on the stack it and the loop took most
  // of this function's 62.8 KB at 6 markers with the lens estimated (the limit is 64 KiB).
  const std::unique_ptr<Filter> owned_filter = std::make_unique<Filter>(config);
  Filter& filter = *owned_filter;
  filter.reset(x0, p0);
  if (along != nullptr) filter.linearise_along(along);

  const std::unique_ptr<hal::ImuSource> imu = data.open_imu();
  const std::unique_ptr<hal::MarkerSource<M>> listed = data.open_markers<M>();
  // Markers found in images (calibrate from images) are labelled with the filter's prediction, as
  // those of rendered frames (sim --frames) and of the board's camera are.
  hal::MarkerRelabeler<M>* relabeler = input.relabeler;
  if (input.source == nullptr && relabeler == nullptr)
    relabeler = dynamic_cast<hal::MarkerRelabeler<M>*>(listed.get());
  FrameTap<M> markers(input.source != nullptr ? *input.source : *listed, relabeler);
  markers.veto(veto);
  HistorySink<Filter> sink(data.frame_count() + 1, truth != nullptr ? &run.truth : nullptr,
                           &markers);
  if (keep_motion) {
    filter.keep_motion_steps(true);
    sink.keep_motion();
  }
  loop::LoopConfig lc;
  lc.imu_period_ns = data.imu_period_ns;
  lc.profiler = input.profiler;
  // A pass linearised along a trajectory takes a first sighting as it comes: withheld there, a
  // pass from the prior can be left unable to predict most markers, and the refinement takes no
  // step (docs/estimator.md, "The update"). The passes linearised at their own estimate, which a
  // wrong first blob would carry off, confirm it.
  lc.screen.confirm_while_gate_open = along == nullptr;
  loop::CalibrationLoop<double, M, NK, NI> loop(filter, *imu, markers, lc, &sink);
  if (relabeler != nullptr) loop.set_identifier(&markers);
  markers.watch(&loop.screen());

  const std::size_t report_every = data.imu_samples() / 100 + 1;
  std::size_t n = 0;
  while (loop.step()) {
    if (progress && ++n % report_every == 0)
      progress(static_cast<double>(n) / static_cast<double>(data.imu_samples()));
  }
  loop.finish();

  run.history = sink.take_rows();
  run.motion = sink.take_motion();
  run.covariance = filter.covariance();
  run.result = make_result(filter, data.width, data.height);
  run.filter_counters = filter.counters();
  run.loop_counters = loop.counters();
  for (int i = 0; i < M; ++i)
    run.result.markers_screened.push_back(loop.screen().rejected(i) + markers.vetoed(i));
  run.imu_samples = data.imu_samples();
  run.frames = data.frame_count();
  return run;
}

// The IMU's residual over an interval (ImuResidual) from the smoothed motion's residual w there
// (the motion block's error state), the interval's transition f and the smoothed state at its end;
// none (dt_s 0) across a restart (f's position-velocity block zero).
template <class State, class Motion, class Transition>
ImuResidual imu_residual(const Motion& w, const Transition& f, const State& end,
                         std::int64_t t_ns) {
  ImuResidual r;
  r.t_ns = t_ns;
  const double dt_s = f(State::kP, State::kV);
  if (!(dt_s > 0.0) || !w.allFinite()) return r;
  r.dt_s = dt_s;
  // The rotation is perturbed on the right (in the body frame at the end), the velocity in n.
  r.gyro = w.template segment<3>(State::kTheta) / dt_s;
  r.accel = end.q_n_b.conjugate() * Eigen::Vector3d(w.template segment<3>(State::kV)) / dt_s;
  return r;
}

// The tracking pass's motion smoothed over the whole pass (Rauch-Tung-Striebel backwards over
// its frames, the calibration held at the pass's final estimate, as the pass held it): each
// frame's linearisation point then rests on every frame, not on those before it, and holds its
// own frame's noise no more than any other's. With it, the IMU's residual over each interval
// between updates (ImuResidual): to first order in the smoother's corrections c (smoothed minus
// filtered), the smoothed motion at k + 1 less the IMU's integration from the smoothed motion at k
// is d_{k+1} - F c_k, d_{k+1} the smoothed motion less the filter's prediction at k + 1 and F the
// transition between them, whose position-velocity block is the interval's length times I.
template <int M, int NK, int NI>
void smoothed_trajectory(const CalibrationRun<M, NK, NI>& track, Trajectory<M, NK, NI>& out,
                         RecordStore<ImuResidual>& residuals) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  constexpr int D = CalibrationRun<M, NK, NI>::Filter::kMotionDim;
  using MotionMatrix = Eigen::Matrix<double, D, D>;
  const std::size_t n = track.motion ? std::min(track.history.size(), track.motion->size()) : 0;
  if (n == 0) return;
  const RecordStore<MotionRow<typename CalibrationRun<M, NK, NI>::Filter>>& motion = *track.motion;
  // Backwards over the frames, reading each row and motion step once: what step k needs of k + 1
  // is carried over from the step before.
  const State final_estimate = track.history[n - 1].state;
  // The calibration held at the final estimate in every state.
  const auto held = [&](State s) {
    s.p_b_c = final_estimate.p_b_c;
    s.q_b_c = final_estimate.q_b_c;
    s.markers = final_estimate.markers;
    s.t_d = final_estimate.t_d;
    s.intrinsics = final_estimate.intrinsics;
    s.imu = final_estimate.imu;
    return s;
  };
  // The rows and matrices a step holds, on the heap: with the IMU's intrinsics (a motion block of
  // 27 states) they took 76 KB of stack at 3 markers.
  using Filter = typename CalibrationRun<M, NK, NI>::Filter;
  struct Step {
    HistoryRow<Filter> next_row, row;
    MotionRow<Filter> next, row_motion;
    MotionMatrix f_p, gain_t;
  };
  const std::unique_ptr<Step> w(new Step);
  w->next_row = track.history[n - 1];
  w->next = motion[n - 1];
  State next_smoothed = final_estimate;
  out.set(n - 1, held(final_estimate), w->next_row.t_ns);
  for (std::size_t k = n - 1; k-- > 0;) {
    w->row = track.history[k];
    w->row_motion = motion[k];
    State smoothed = w->row.state;
    ImuResidual residual;  // over the interval from this row to the next: none (dt_s 0) yet
    // A row that followed no update (the final one) says nothing new about the one before it.
    if (w->next.step.update != w->row_motion.step.update) {
      const Eigen::Matrix<double, D, 1> d =
          next_smoothed.template boxminus_block<0, D>(w->next_row.predicted);
      Eigen::Matrix<double, D, 1> step;
      if constexpr (NI > 0) {
        // Only C d is needed: P_k F^T (P_{k+1|k}^-1 d), one solve where the gain takes D of them
        // (at NI = 12 the smoother had been a sixth of a calibration's cost). The ideal IMU keeps
        // the gain's form below, to the last digit of its published figures.
        const Eigen::Matrix<double, D, 1> y = w->next.step.predicted_covariance.ldlt().solve(d);
        step = w->row_motion.covariance * (w->next.step.transition.transpose() * y);
      } else {
        // C = P_k F^T P_{k+1|k}^-1, so C^T = P_{k+1|k}^-1 F P_k (both covariances symmetric).
        w->f_p = w->next.step.transition * w->row_motion.covariance;
        w->gain_t = w->next.step.predicted_covariance.ldlt().solve(w->f_p);
        step = w->gain_t.transpose() * d;
      }
      if (step.allFinite()) {
        smoothed.template boxplus_block<0, D>(step);
        residual = imu_residual<State>(d - w->next.step.transition * step, w->next.step.transition,
                                       next_smoothed, w->next_row.t_ns);
      }
    }
    residuals.set(k, residual);
    out.set(k, held(smoothed), w->row.t_ns);
    next_smoothed = smoothed;
    w->next_row = w->row;
    w->next = w->row_motion;
  }
  out.set_rates();
}

// The first stretch of the data, for imu_start_from(): from the first IMU sample to the one after
// the kImuStartFrames-th frame with markers, at most kImuStartMaxS long. Empty if it holds fewer
// than two such frames.
template <int M>
LoopData first_stretch(const LoopData& data) {
  LoopData out;
  const std::unique_ptr<hal::ImuSource> imu = data.open_imu();
  const std::unique_ptr<hal::MarkerSource<M>> markers = data.open_markers<M>();
  ImuSample s;
  if (imu->next(s) != hal::SourceStatus::kOk) return out;
  const std::int64_t latest = s.t_ns + static_cast<std::int64_t>(kImuStartMaxS * 1e9);
  int with_markers = 0;
  std::int64_t end = latest;
  MarkerFrame<M> f;
  while (markers->poll(f) == hal::SourceStatus::kOk) {
    if (f.t_ns > latest) break;
    io::ObservedFrame& kept = out.frames.emplace_back(io::ObservedFrame{f.t_ns, {}});
    for (int i = 0; i < M; ++i)
      if (f.seen[std::size_t(i)])
        kept.markers.push_back({i, f.uv[std::size_t(i)].x(), f.uv[std::size_t(i)].y()});
    if (!kept.markers.empty() && ++with_markers == kImuStartFrames) {
      end = f.t_ns;
      break;
    }
  }
  if (with_markers < 2) return {};
  do {
    out.imu.push_back(s);
  } while (s.t_ns <= end && imu->next(s) == hal::SourceStatus::kOk);
  out.imu_period_ns = data.imu_period_ns;
  out.width = data.width;
  out.height = data.height;
  return out;
}

// The prior's covariance with the calibration block replaced by a pass's (and no correlation
// between the two blocks): a pass from it holds the calibration near that pass's estimate.
template <int M, int NK, int NI>
void hold_calibration(const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0,
                      const CalibrationRun<M, NK, NI>& pass,
                      typename CalibrationRun<M, NK, NI>::Filter::Covariance& p) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  constexpr int B = State::kCalibrationBegin, L = State::kCalibrationDim;
  p = p0;
  p.template block<L, State::kDim>(B, 0).setZero();
  p.template block<State::kDim, L>(0, B).setZero();
  p.template block<L, L>(B, B) = pass.covariance.template block<L, L>(B, B);
}
template <int M, int NK, int NI>
typename CalibrationRun<M, NK, NI>::Filter::Covariance calibration_held(
    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0,
    const CalibrationRun<M, NK, NI>& pass) {
  typename CalibrationRun<M, NK, NI>::Filter::Covariance p;
  hold_calibration<M, NK, NI>(p0, pass, p);
  return p;
}

// The prior's covariance with the calibration block shrunk to kFrozenCalibration of it: a pass
// from it holds the calibration at its guesses and fits the motion alone. On the heap: the
// largest filters' covariance is 29 KB.
template <int M, int NK, int NI>
std::unique_ptr<typename CalibrationRun<M, NK, NI>::Filter::Covariance> calibration_frozen(
    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  constexpr int B = State::kCalibrationBegin, L = State::kCalibrationDim;
  auto p = std::make_unique<typename CalibrationRun<M, NK, NI>::Filter::Covariance>(p0);
  p->template block<L, State::kDim>(B, 0) *= std::sqrt(kFrozenCalibration);
  p->template block<State::kDim, L>(0, B) *= std::sqrt(kFrozenCalibration);
  return p;
}

// Where a pass starts the IMU: the first stretch of the data calibrated from the calibration
// `calibration` holds, under `held` (the prior's motion block, the calibration's block of the
// pass it comes from), and x's IMU guess, which pins the rig's distance from the mirror, its tilt
// and their rates within a fraction of a second, then integrated back to the first IMU sample.
// False (x unchanged) if the stretch has too few frames or the run fails.
template <int M, int NK, int NI>
bool imu_start_from(const CalibrationConfig& config,
                    const typename CalibrationRun<M, NK, NI>::State& calibration,
                    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& held,
                    const LoopData& data, typename CalibrationRun<M, NK, NI>::State& x) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  const LoopData stretch = first_stretch<M>(data);
  if (stretch.imu.size() < 2) return false;
  State start = calibration;
  start.p = x.p;
  start.v = x.v;
  start.q_n_b = x.q_n_b;
  start.b_a = x.b_a;
  start.b_g = x.b_g;
  const CalibrationRun<M, NK, NI> fit =
      run_pass<M, NK, NI>(config, start, held, stretch, nullptr, {}, LoopHooks<M>{});
  if (fit.history.empty() || fit.filter_counters.failures > 0) return false;
  State back = fit.history.back().state;
  for (std::size_t k = stretch.imu.size() - 1; k > 0; --k)  // the samples in reverse
    propagate_imu(back, stretch.imu[k], stretch.imu[k - 1], config.gravity_n);
  if (!back.p.allFinite() || !back.v.allFinite()) return false;
  x.p = back.p;
  x.v = back.v;
  x.q_n_b = back.q_n_b;
  return true;
}

// The IMU's start from pass's calibration, held near its estimate by its own covariance.
template <int M, int NK, int NI>
bool imu_start_from(const CalibrationConfig& config, const CalibrationRun<M, NK, NI>& pass,
                    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0,
                    const LoopData& data, typename CalibrationRun<M, NK, NI>::State& x) {
  // The held covariance on the heap: beside the stretch's run, the largest filters' (M = 6 with the
  // lens and the IMU's intrinsics) outgrew the 64 KiB a stack frame is held to.
  const auto held = std::make_unique<typename CalibrationRun<M, NK, NI>::Filter::Covariance>();
  hold_calibration<M, NK, NI>(p0, pass, *held);
  return imu_start_from<M, NK, NI>(config, pass.history.back().state, *held, data, x);
}

std::uint64_t markers_in(const LoopData& data) {
  if (data.streams) return data.stats.markers;
  std::uint64_t n = 0;
  for (const auto& f : data.frames) n += f.markers.size();
  return n;
}

// For the self-check: the calibration state the final estimate lies furthest from its prior guess,
// in the prior's sigmas (rotations as the error vector, R = R_guess Exp(e)).
template <int M, int NK, int NI>
void record_prior_offset(const typename CalibrationRun<M, NK, NI>::State& x0,
                         const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0,
                         CalibrationRun<M, NK, NI>& run) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  constexpr int B = State::kCalibrationBegin, L = State::kCalibrationDim;
  const auto d = run.history.back().state.template boxminus_block<B, L>(x0);
  CalibrationResult& r = run.result;
  for (int j = 0; j < L && std::size_t(j) < r.params.size(); ++j) {
    const double sigmas = std::abs(double(d(j))) / std::sqrt(double(p0(B + j, B + j)));
    if (!(sigmas <= r.prior_offset_sigmas)) {
      r.prior_offset_sigmas = sigmas;
      r.prior_offset_state = r.params[std::size_t(j)].name;
    }
  }
  if constexpr (NI > 0) {  // and the IMU's intrinsics, from the ideal IMU in their tolerances
    const auto di = run.history.back().state.template boxminus_block<State::kImu, NI>(x0);
    const std::vector<std::string> names = imu_intrinsic_names(State::kImuModel);
    for (int j = 0; j < NI; ++j) {
      const double sigmas =
          std::abs(double(di(j))) / std::sqrt(double(p0(State::kImu + j, State::kImu + j)));
      if (!(sigmas <= r.imu.prior_offset_sigmas)) {
        r.imu.prior_offset_sigmas = sigmas;
        r.imu.prior_offset_name = names[std::size_t(j)];
      }
    }
  }
}

// For the self-check: the pair of markers whose labels look swapped in the most frames of the
// last pass (CalibrationResult::LabelSwap), from the measurements alone, so that a calibration the
// swaps carried off still names them: from one frame to the next each marker's reflection moves a
// few pixels, far less than the markers lie apart. A frame counts for (i, j), both seen in it and
// in the frame before, when i's reflection lies where j's was and j's where i's was: the swapped
// labels' squared steps under a tenth of the own ones, which exceed twice (kSwapResidualSigmas
// pixel sigmas)^2.
template <int M, int NK, int NI>
void record_label_swaps(double pixel_sigma, CalibrationRun<M, NK, NI>& run) {
  std::array<std::array<std::uint64_t, M>, M> swapped{}, both{};
  const double own_floor = 2.0 * std::pow(kSwapResidualSigmas * pixel_sigma, 2);
  std::array<bool, M> seen_before{};
  std::array<Eigen::Vector2d, M> before{};
  for (const auto& row : run.history) {
    for (int i = 0; i < M; ++i)
      for (int j = i + 1; j < M; ++j) {
        const auto a = std::size_t(i), b = std::size_t(j);
        if (!row.seen[a] || !row.seen[b] || !seen_before[a] || !seen_before[b]) continue;
        ++both[a][b];
        const double own = (row.measured[a] - before[a]).squaredNorm() +
                           (row.measured[b] - before[b]).squaredNorm();
        const double swap = (row.measured[a] - before[b]).squaredNorm() +
                            (row.measured[b] - before[a]).squaredNorm();
        if (own > own_floor && swap < 0.1 * own) ++swapped[a][b];
      }
    if (row.markers_seen == 0) continue;  // the final row, or a frame without markers
    seen_before = row.seen;
    before = row.measured;
  }
  CalibrationResult::LabelSwap& worst = run.result.label_swap;
  for (int i = 0; i < M; ++i)
    for (int j = i + 1; j < M; ++j) {
      const auto a = std::size_t(i), b = std::size_t(j);
      if (swapped[a][b] > worst.frames) worst = {i, j, swapped[a][b], both[a][b]};
    }
}

// The first frame's markers (row) as state x predicts them (at its exposure): how many the frame
// showed, how many x predicts, how many of those land within an image's size of the image, and
// their median distance from the measured.
template <int M, class Row, class State>
CalibrationResult::PriorFit first_frame_fit(const CalibrationConfig& config, const Row& row,
                                            const State& x, double width, double height) {
  std::array<bool, M> ok = row.seen;
  Eigen::Matrix<double, 2 * M, 1> z = Eigen::Matrix<double, 2 * M, 1>::Zero();
  Exposure<double> at_state;
  at_state.stamp_minus_filter_s = -x.t_d;
  at_state.gravity_n = config.gravity_n;
  predict_markers(x, config.intrinsics, at_state, std::array<double, M>{}, z, ok);
  CalibrationResult::PriorFit fit;
  std::array<double, M> distance{};
  for (int i = 0; i < M; ++i) {
    const auto k = std::size_t(i);
    if (!row.seen[k]) continue;
    ++fit.seen;
    if (!ok[k]) continue;
    const Eigen::Vector2d uv = z.template segment<2>(2 * i);
    distance[std::size_t(fit.predictable++)] = (uv - row.measured[k]).norm();
    if (uv.x() > -width && uv.x() < 2.0 * width && uv.y() > -height && uv.y() < 2.0 * height)
      ++fit.near_image;
  }
  if (fit.predictable > 0) {
    const auto mid = distance.begin() + fit.predictable / 2;
    std::nth_element(distance.begin(), mid, distance.begin() + fit.predictable);
    fit.median_px = *mid;
  }
  return fit;
}

// For the self-check: the first frame's markers against the priors' guess there (the first
// pass's prediction at that frame), and against the same guess with q_b_c read as the
// conventions users mistake read it (CalibrationResult::PriorFit).
template <int M, int NK, int NI>
void record_prior_fit(const CalibrationConfig& config, CalibrationRun<M, NK, NI>& run) {
  const auto& row = run.first_frame;
  const double w = run.result.width, h = run.result.height;
  CalibrationResult::PriorFit& fit = run.result.prior_fit;
  fit = first_frame_fit<M>(config, row, row.predicted, w, h);
  // The four numbers the priors gave as w, x, y, z, read as x, y, z, w; and R_c_b for R_b_c.
  const Eigen::Quaterniond q = row.predicted.q_b_c;
  const Eigen::Quaterniond xyzw = Eigen::Quaterniond(q.z(), q.w(), q.x(), q.y()).normalized();
  const std::pair<const char*, Eigen::Quaterniond> readings[] = {
      {"as x, y, z, w", xyzw},
      {"conjugated (as R_c_b)", q.conjugate()},
      {"as x, y, z, w and conjugated", xyzw.conjugate()}};
  for (const auto& [name, other] : readings) {
    auto x = row.predicted;
    x.q_b_c = other;
    const double median = first_frame_fit<M>(config, row, x, w, h).median_px;
    if (median < std::min(fit.median_px, fit.better_median_px)) {
      fit.better_reading = name;
      fit.better_median_px = median;
    }
  }
}

// How far a refinement step moved the calibration from the estimate it started at, in the step's
// own sigmas (Mahalanobis distance under its covariance): the self-check's convergence test.
template <int M, int NK, int NI>
double step_sigmas(const CalibrationRun<M, NK, NI>& after,
                   const CalibrationRun<M, NK, NI>& before) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  constexpr int B = State::kCalibrationBegin, L = State::kCalibrationDim;
  const Eigen::Matrix<double, L, 1> d =
      after.history.back().state.template boxminus_block<B, L>(before.history.back().state);
  const Eigen::Matrix<double, L, L> p = after.covariance.template block<L, L>(B, B);
  return std::sqrt(d.dot(p.ldlt().solve(d)));
}

// The start of the pass after run: the calibration parameters at its estimate, and the IMU's start.
// noise_scale: the pixel noise of run's pass over the true one (kAnnealedPixelNoise after a
// restart), whose square its covariance is larger than what the data hold.
template <int M, int NK, int NI>
void carry_estimate(const CalibrationConfig& config, const CalibrationRun<M, NK, NI>& run,
                    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0,
                    const LoopData& data, typename CalibrationRun<M, NK, NI>::State& start,
                    double noise_scale = 1.0) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  // The next pass starts the calibration parameters at this pass's estimate, with the prior's
  // covariance: the data are linearised about a far better guess (see run.hpp). Only where
  // the prior no longer weighs in, though: a prior as informative as the data (stage 1's result
  // in stage 2) keeps its own mean, or the data would count twice.
  const State& est = run.history.back().state;
  const auto prior_negligible = [&](int begin, int dim) {
    for (int i = begin; i < begin + dim; ++i)
      if (!(run.covariance(i, i) < kNegligiblePriorWeight * noise_scale * noise_scale * p0(i, i)))
        return false;
    return true;
  };
  if (prior_negligible(State::kPbc, 3)) start.p_b_c = est.p_b_c;
  if (prior_negligible(State::kTd, 1)) start.t_d = est.t_d;
  if (prior_negligible(State::kPhi, 3)) start.q_b_c = est.q_b_c;
  for (int m = 0; m < M; ++m)
    if (prior_negligible(State::kPi + 3 * m, 3))
      start.markers.template segment<3>(3 * m) = est.markers.template segment<3>(3 * m);
  if (NK > 0 && prior_negligible(State::kK, NK)) start.intrinsics = est.intrinsics;
  // The IMU's intrinsics one by one: the motion leaves some of them weak.
  if constexpr (NI > 0) {
    Eigen::Matrix<double, NI, 1> d = est.template boxminus_block<State::kImu, NI>(start);
    for (int j = 0; j < NI; ++j)
      if (!prior_negligible(State::kImu + j, 1)) d(j) = 0.0;
    start.template boxplus_block<State::kImu, NI>(d);
  }
  // And the IMU's start, which every pass otherwise begins from the prior's guess (10 cm and
  // 5 deg off for a user's hand-held start): the frames of the first seconds would pull the
  // calibration towards that guess again.
  imu_start_from<M, NK, NI>(config, run, p0, data, start);
}

// The free passes: passes.min of them, and more while the last gated too many (Passes); each
// after the first starts where the one before ended (carry_estimate), and so would the next.
// Not inlined, nor are refine and check_ideal_imu: inlined into run_loop, their matrices shared
// one stack frame (clang: 52.8 KB at M = 3; the stack_frames test holds every frame within 64 KiB).
template <int M, int NK, int NI>
[[gnu::noinline]] CalibrationRun<M, NK, NI> free_passes(
    const CalibrationConfig& config,
    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0, const LoopData& data,
    const typename CalibrationRun<M, NK, NI>::State* truth,
    const std::function<void(double)>& progress, const std::function<LoopHooks<M>(int pass)>& hooks,
    Passes passes, typename CalibrationRun<M, NK, NI>::State& start) {
  const typename CalibrationRun<M, NK, NI>::State guess = start;
  CalibrationRun<M, NK, NI> run;
  HistoryRow<typename CalibrationRun<M, NK, NI>::Filter> first_frame;
  int restarted = 0;
  // Where the first restart led, kept while the second tries (on the heap: a run holds a
  // covariance of up to 29 KB): a second that is still suspect leaves the first's standing.
  std::unique_ptr<CalibrationRun<M, NK, NI>> first_restart;
  typename CalibrationRun<M, NK, NI>::State first_restart_start;
  for (int pass = 0; pass < passes.max; ++pass) {
    const bool after_restart = restarted > 0 && restarted == pass;  // wants the true noise next
    // A pass whose detection labelled few of the markers it saw rests on a handful of them, perhaps
    // mislabelled while the prediction was vague: as suspect as one that gated too many.
    if (pass >= passes.min && !after_restart && !suspect(run.result) &&
        !identification_failed(run.result))
      break;
    const int planned = std::max(passes.min, pass + 1);
    const auto pass_progress = [&](double f) {
      if (progress) progress((pass + f) / planned);
    };
    // Still suspect after the default passes, with a pass left to follow: locked on (run.hpp).
    // Still suspect after that restart and the pass that followed it: the guessed motion locked it
    // on, and the second restart starts the IMU from the first frames instead.
    const bool second_restart = pass == passes.min + 2;
    const bool restart = (pass == passes.min || second_restart) && pass + 1 < passes.max;
    CalibrationConfig pass_config = config;
    if (second_restart && restart) {
      first_restart = std::make_unique<CalibrationRun<M, NK, NI>>(std::move(run));
      first_restart_start = start;
    }
    if (restart) {
      start = guess;
      pass_config.pixel_sigma *= kAnnealedPixelNoise;
      restarted = pass + 1;
      if (second_restart)
        imu_start_from<M, NK, NI>(pass_config, guess, *calibration_frozen<M, NK, NI>(p0), data,
                                  start);
    }
    const LoopHooks<M> pass_hooks = hooks ? hooks(pass) : LoopHooks<M>{};
    run = run_pass<M, NK, NI>(pass_config, start, p0, data, truth, pass_progress, pass_hooks);
    if (pass_hooks.detection)
      run.result.detection = detection_counts(pass_hooks.detection());
    else if (data.image_detection)  // written by the pass's image source as it closed
      run.result.detection = detection_counts(*data.image_detection);
    run.result.passes = pass + 1;
    run.result.restarted_pass = restarted;
    if (pass == 0 && !run.history.empty()) first_frame = run.history.front();
    run.first_frame = first_frame;
    if (run.history.empty()) break;
    carry_estimate<M, NK, NI>(config, run, p0, data, start, restart ? kAnnealedPixelNoise : 1.0);
  }
  if (first_restart &&
      (run.history.empty() || suspect(run.result) || identification_failed(run.result))) {
    const int made = run.result.passes;
    run = std::move(*first_restart);
    start = first_restart_start;
    run.result.passes = made;  // the refinement's passes number on from every pass made
  }
  return run;
}

// What a Gauss-Newton step linearised along: the smoothed trajectory and the start of its
// linearised pass.
template <int M, int NK, int NI>
struct Linearisation {
  std::unique_ptr<Trajectory<M, NK, NI>> trajectory;
  std::shared_ptr<RecordStore<ImuResidual>> imu_residuals;  // along the trajectory
  typename CalibrationRun<M, NK, NI>::State start;
};

// The markers of a tracking pass (its estimate near the converged solution, the calibration held
// there) whose residual after their frame's update lies beyond kOutlierSigmas of the pixel noise,
// added to veto (kept in time order); whether it found any. The noise is the larger of the stated
// one and the pass's own robust estimate (the residuals' median length over 1.1774, a 2-D
// normal's), so that noise stated too small vetoes nothing. A wrong blob the frame's screen let
// through (within its tolerance of the common step, 25 px and more) lies tens of sigmas off; in
// a 2-D normal 6 sigmas come once in 6.6e7 residuals. The markers the screen withheld are not
// the filter's, and not judged. A marker beyond it in more than kOutlierMaxShare of its frames
// is not sporadically wrong: its own model is (an estimate not converged puts it off in every
// frame), and none of its frames is vetoed.
template <int M, int NK, int NI>
bool find_outliers(const CalibrationRun<M, NK, NI>& track, double pixel_sigma,
                   OutlierVeto<M>& veto) {
  const auto judged = [](const auto& row, std::size_t i) {
    return row.residual_valid[i] && !row.withheld[i];
  };
  std::vector<double> lengths;
  std::array<std::size_t, M> frames{}, beyond{};
  for (const auto& row : track.history)
    for (std::size_t i = 0; i < std::size_t(M); ++i)
      if (judged(row, i)) {
        lengths.push_back(row.residual[i].norm());
        ++frames[i];
      }
  if (lengths.empty()) return false;
  const auto mid = lengths.begin() + std::ptrdiff_t(lengths.size() / 2);
  std::nth_element(lengths.begin(), mid, lengths.end());
  const double limit = kOutlierSigmas * std::max(pixel_sigma, *mid / 1.1774);
  const auto outlier = [&](const auto& row, std::size_t i) {
    return judged(row, i) && row.residual[i].norm() > limit;
  };
  for (const auto& row : track.history)
    for (std::size_t i = 0; i < std::size_t(M); ++i) beyond[i] += outlier(row, i) ? 1 : 0;
  std::array<bool, M> sporadic{};
  for (std::size_t i = 0; i < std::size_t(M); ++i)
    sporadic[i] = double(beyond[i]) <= kOutlierMaxShare * double(frames[i]);
  OutlierVeto<M> found;
  for (const auto& row : track.history) {
    VetoedFrame<M> v{row.t_ns, {}};
    bool any = false;
    for (std::size_t i = 0; i < std::size_t(M); ++i)
      if (sporadic[i] && outlier(row, i)) any = v.markers[i] = true;
    if (any) found.push_back(v);
  }
  if (found.empty()) return false;
  OutlierVeto<M> merged;
  std::merge(veto.begin(), veto.end(), found.begin(), found.end(), std::back_inserter(merged),
             [](const VetoedFrame<M>& a, const VetoedFrame<M>& b) { return a.t_ns < b.t_ns; });
  veto.clear();
  for (const VetoedFrame<M>& v : merged) {
    if (!veto.empty() && veto.back().t_ns == v.t_ns) {
      for (std::size_t i = 0; i < std::size_t(M); ++i) veto.back().markers[i] |= v.markers[i];
    } else {
      veto.push_back(v);
    }
  }
  return true;
}

// One Gauss-Newton step from the estimate from, the calibration held near it by held: a tracking
// pass from there, smoothed, and a pass from the prior (x0, p0) linearised along it, which it
// returns; track and at get the tracking pass and what the step linearised along. Each pass asks
// next_hooks() for its hooks as it starts (a source of rendered frames replaces the one before).
// Both passes drop the markers in veto; outliers the tracking pass finds (find_outliers) join it,
// and the tracking pass is made again without them.
template <int M, int NK, int NI>
std::unique_ptr<CalibrationRun<M, NK, NI>> gauss_newton_step(
    const CalibrationConfig& c, const typename CalibrationRun<M, NK, NI>::State& x0,
    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0, const LoopData& data,
    const typename CalibrationRun<M, NK, NI>::State* truth,
    const typename CalibrationRun<M, NK, NI>::State& from,
    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& held,
    const std::function<LoopHooks<M>()>& next_hooks,
    std::unique_ptr<CalibrationRun<M, NK, NI>>& track, Linearisation<M, NK, NI>& at,
    OutlierVeto<M>& veto) {
  // The two runs a step makes live on the heap: on the stack they took 80 KB at 6 markers with
  // the lens estimated. (A new-expression builds each in place from run_pass's result.)
  const auto tracking_pass = [&] {
    track.reset(new CalibrationRun<M, NK, NI>(
        run_pass<M, NK, NI>(c, from, held, data, nullptr, {}, next_hooks(), nullptr, true, &veto)));
  };
  tracking_pass();
  if (find_outliers(*track, c.pixel_sigma, veto)) tracking_pass();
  // Each frame is linearised at the track smoothed over the whole pass, never at the track's
  // estimate after that frame's update: an estimate that holds the frame's own noise moves the
  // linearisation with that noise, and where the rig's motion leaves a direction weak (slow
  // sweeps: the markers' scale against the mirror's distance), the measurement's slope along it
  // grows with that offset, so every frame adds information the data do not hold
  // (docs/estimator.md, "Passes and refinement", measures the three linearisation points).
  at.trajectory = std::make_unique<Trajectory<M, NK, NI>>();
  at.imu_residuals = std::make_shared<RecordStore<ImuResidual>>("the IMU's residuals");
  smoothed_trajectory<M, NK, NI>(*track, *at.trajectory, *at.imu_residuals);
  // From the prior's guesses, so that the data count once: the calibration, and the IMU's start
  // position and velocity. Where slow sweeps hardly excite the accelerometer, the start's prior
  // holds much of what fixes the markers' scale against the mirror's distance, and a start taken
  // from the data under the estimate's scale would hold the scale where it is. The attitude
  // starts where the trajectory has it: the filter propagates along its own estimate, and a start
  // a degree off the trajectory bends the linearised pass, where the prior's degree is nothing
  // beside the camera's hold on the attitude (docs/estimator.md, "Passes and refinement").
  at.start = x0;
  at.start.q_n_b = from.q_n_b;
  return std::unique_ptr<CalibrationRun<M, NK, NI>>(
      new CalibrationRun<M, NK, NI>(run_pass<M, NK, NI>(
          c, at.start, p0, data, truth, {}, next_hooks(), at.trajectory.get(), false, &veto)));
}

// Gauss-Newton over the whole recording, the filter its linear solver: a pass from the estimate
// with the calibration held near it by its own covariance gives a trajectory, and a pass from
// the prior with every measurement linearised along that trajectory
// (CalibrationFilter::linearise_along) is the Kalman filter of the linearised problem, whose
// final estimate of the constant calibration is that problem's batch solution and whose
// covariance is the inverse of the information along the trajectory. The free passes
// linearised along the estimates they passed through, and where those were far off, their
// covariance holds information the data do not (random family: sigmas down to a third of the
// linearised one's) and their estimate lies further from the truth than the data allow. How
// much smaller the free passes' sigmas were is the self-check's sigma_ratio (result.hpp).
template <int M, int NK, int NI>
[[gnu::noinline]] void refine(const CalibrationConfig& config,
                              const typename CalibrationRun<M, NK, NI>::State& x0,
                              const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0,
                              const LoopData& data,
                              const typename CalibrationRun<M, NK, NI>::State* truth,
                              const std::function<LoopHooks<M>(int pass)>& hooks,
                              typename CalibrationRun<M, NK, NI>::State& start,
                              CalibrationRun<M, NK, NI>& run) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  constexpr int B = State::kCalibrationBegin;
  // The free passes' variances, for sigma_ratio (the diagonal alone: a covariance is 29 KB at M =
  // 6).
  const Eigen::Matrix<double, State::kDim, 1> own = run.covariance.diagonal();
  const int free_passes = run.result.passes;
  // Their markers come from where the passes' did (rendered frames through detection with
  // sim --frames): hooks numbered on from the passes'.
  int hook = free_passes;
  const std::function<LoopHooks<M>()> next_hooks = [&] {
    return hooks ? hooks(hook++) : LoopHooks<M>{};
  };
  // The outliers the steps find at their solutions, dropped from every later pass.
  OutlierVeto<M> veto = run.veto;
  // One Gauss-Newton step from run's estimate, linearised as c says; false if not taken.
  const auto step = [&](const CalibrationConfig& c) {
    State from = run.history.back().state;
    from.p = start.p;
    from.v = start.v;
    from.q_n_b = start.q_n_b;
    Linearisation<M, NK, NI> at;
    std::unique_ptr<CalibrationRun<M, NK, NI>> track;
    const std::unique_ptr<CalibrationRun<M, NK, NI>> refined = gauss_newton_step<M, NK, NI>(
        c, x0, p0, data, truth, from, calibration_held<M, NK, NI>(p0, run), next_hooks, track, at,
        veto);
    // A replay that did not meet the same frames (a source that ran dry) refines nothing.
    if (frames_met(*refined) != frames_met(run) || frames_met(*track) != frames_met(run) ||
        refined->filter_counters.failures > 0)
      return false;
    // A step that makes a good fit bad is not taken, as Levenberg-Marquardt rejects a step that
    // raises the cost (a lens's rig lost its markers in one: docs/cameras.md).
    if (suspect(refined->result) && !suspect(run.result)) return false;
    refined->result.refinement_step_sigmas = step_sigmas<M, NK, NI>(*refined, run);
    refined->first_frame = run.first_frame;
    refined->result.passes = free_passes;
    refined->result.restarted_pass = run.result.restarted_pass;
    refined->veto = veto;
    refined->imu_residuals = at.imu_residuals;
    run = std::move(*refined);
    imu_start_from<M, NK, NI>(config, run, p0, data, start);
    return true;
  };
  bool taken = true;
  int steps = 0;
  for (int it = 0; it < kMaxRefinements && taken; ++it) {
    taken = step(config);
    steps += taken ? 1 : 0;
    if (run.result.refinement_step_sigmas < kConvergedStepSigmas) break;
  }
  // Not one step taken: the free passes' estimate and covariance stand, the very ones the
  // refinement is there to correct, and sigma_ratio cannot be measured.
  run.result.refinement_refused = steps == 0;
  // The last step at the measurement's Jacobian (kTangentAlphaScale): its length is the
  // self-check's refinement_step.
  CalibrationConfig tangent = config;
  tangent.sigma_points.linearised_alpha_scale = kTangentAlphaScale;
  if (taken) step(tangent);
  double lowest = INFINITY;
  for (int i = B; i < State::kDim; ++i)
    lowest = std::min(lowest, std::sqrt(own(i) / run.covariance(i, i)));
  run.result.sigma_ratio = lowest;
}

// The same rig's state in a model of NI2 intrinsics: the common members copied, the intrinsics
// (if it has them) those of an ideal IMU.
template <int NI2, int M, int NK, int NI>
MirrorState<double, M, NK, NI2> in_imu_model(const MirrorState<double, M, NK, NI>& x) {
  MirrorState<double, M, NK, NI2> y;
  y.v = x.v;
  y.b_a = x.b_a;
  y.b_g = x.b_g;
  y.p = x.p;
  y.q_n_b = x.q_n_b;
  y.p_b_c = x.p_b_c;
  y.q_b_c = x.q_b_c;
  y.markers = x.markers;
  y.t_d = x.t_d;
  y.intrinsics = x.intrinsics;
  return y;
}

// A covariance of the ideal IMU's state with the intrinsics' block inserted where MirrorState puts
// it (after the biases), uncorrelated, with 1-sigma sigma.
template <int NI, int M, int NK>
typename CalibrationRun<M, NK, NI>::Filter::Covariance with_imu_prior(
    const typename CalibrationRun<M, NK, 0>::Filter::Covariance& p,
    const std::array<double, NI>& sigma) {
  constexpr int K = CalibrationRun<M, NK, 0>::State::kImu;
  constexpr int R = CalibrationRun<M, NK, 0>::State::kDim - K;
  typename CalibrationRun<M, NK, NI>::Filter::Covariance out;
  out.setZero();
  out.template topLeftCorner<K, K>() = p.template topLeftCorner<K, K>();
  out.template block<K, R>(0, K + NI) = p.template block<K, R>(0, K);
  out.template block<R, K>(K + NI, 0) = p.template block<R, K>(K, 0);
  out.template bottomRightCorner<R, R>() = p.template bottomRightCorner<R, R>();
  for (int j = 0; j < NI; ++j) out(K + j, K + j) = sigma[std::size_t(j)] * sigma[std::size_t(j)];
  return out;
}

// The Wald statistic of the intrinsics a pass of the scale-misalignment model ended with (check,
// from x under the prior p) into out; false, out not made, if the pass lost its way.
template <int M, int NI>
bool wald_statistic(const CalibrationRun<M, 0, NI>& check,
                    const typename CalibrationRun<M, 0, NI>::State& x,
                    const typename CalibrationRun<M, 0, NI>::Filter::Covariance& p,
                    IdealImuCheck& out) {
  constexpr int K = CalibrationRun<M, 0, NI>::State::kImu;
  out = IdealImuCheck{};
  if (check.history.empty() || check.filter_counters.failures > 0) return false;
  // In the prior's sigmas, z = d / s0 and B = S0^-1 P S0^-1 (P the posterior). With the truth at
  // the prior's guess (an ideal IMU), the estimate is the data's part alone, P H^T R^-1 y, whose
  // covariance is P - P P0^-1 P: B (I - B) in these units. Along each eigenvector of B with
  // eigenvalue mu, z scatters with variance mu (1 - mu); the data took 1 - mu of the prior's.
  const auto& end = check.history.back().state;
  const Eigen::Matrix<double, NI, 1> d = end.template boxminus_block<K, NI>(x);
  const Eigen::Matrix<double, NI, NI> post = check.covariance.template block<NI, NI>(K, K);
  const Eigen::Matrix<double, NI, 1> s0 = p.template block<NI, NI>(K, K).diagonal().cwiseSqrt();
  const Eigen::Matrix<double, NI, 1> z = d.cwiseQuotient(s0);
  // A pass that lost its way says nothing: intrinsics beyond kPriorContradictedSigmas of their
  // tolerance are no part's.
  if (suspect(check.result) || !(z.cwiseAbs().maxCoeff() <= kPriorContradictedSigmas)) return false;
  const Eigen::Matrix<double, NI, NI> b =
      s0.cwiseInverse().asDiagonal() * post * s0.cwiseInverse().asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, NI, NI>> eig(b);
  for (int k = 0; k < NI; ++k) {
    const double mu = eig.eigenvalues()(k);
    if (!(1.0 - mu >= kImuCheckMinInformation) || !(mu > 0.0)) continue;
    const double u = eig.eigenvectors().col(k).dot(z);
    out.statistic += u * u / (mu * (1.0 - mu));
    ++out.dof;
  }
  if (out.dof == 0) return false;
  out.made = true;
  out.bound = chi2_quantile(kImuCheckQuantile, out.dof);
  ImuResult found;
  found.model = ImuModel::kScaleMisalignment;
  found.intrinsics = end.imu;
  const std::vector<double> values = imu_intrinsic_values(found);
  const std::vector<std::string> names = imu_intrinsic_names(found.model);
  double furthest = -1.0;
  for (int j = 0; j < NI; ++j) {
    const double sigma = std::sqrt(post(j, j));
    if (!(std::abs(d(j)) / sigma > furthest)) continue;
    furthest = std::abs(d(j)) / sigma;
    out.largest_name = names[std::size_t(j)];
    out.largest_value = values[std::size_t(j)];
    out.largest_sigma = sigma;
  }
  return true;
}

// The ideal-IMU check (Passes::check_imu; imu_result.hpp, IdealImuCheck) of a calibration that
// assumed an ideal IMU: one more Gauss-Newton step from its final estimate (as the refinement's
// last, at the measurement's Jacobian) with the scale-misalignment model's intrinsics added at the
// ideal IMU, and the Wald statistic of those it finds. A free pass (its covariance
// over-confident) and a pass along the ideal model's own trajectory (which loses its way) were
// worse (docs/estimator.md, "The IMU's intrinsics").
template <int M>
[[gnu::noinline]] void check_ideal_imu(
    const CalibrationConfig& config, const typename CalibrationRun<M, 0, 0>::State& x0,
    const typename CalibrationRun<M, 0, 0>::Filter::Covariance& p0,
    const CalibrationRun<M, 0, 0>& run, const typename CalibrationRun<M, 0, 0>::State& start,
    const LoopData& data, const std::function<LoopHooks<M>(int pass)>& hooks,
    const ImuIntrinsicsSigma& tolerances, IdealImuCheck& out) {
  constexpr int NI = imu_intrinsics_dim(ImuModel::kScaleMisalignment);
  using Run = CalibrationRun<M, 0, NI>;
  typename CalibrationRun<M, 0, 0>::State from = run.history.back().state;
  from.p = start.p;
  from.v = start.v;
  from.q_n_b = start.q_n_b;
  const std::array<double, NI> sigma = imu_intrinsics_sigmas<NI>(tolerances);
  const typename Run::Filter::Covariance p = with_imu_prior<NI, M, 0>(p0, sigma);
  CalibrationConfig tangent = config;
  tangent.sigma_points.linearised_alpha_scale = kTangentAlphaScale;
  int hook = kImuCheckPass;
  const std::function<LoopHooks<M>()> next_hooks = [&] {
    return hooks ? hooks(hook++) : LoopHooks<M>{};
  };
  std::unique_ptr<Run> track;
  Linearisation<M, 0, NI> at;
  OutlierVeto<M> veto = run.veto;
  const std::unique_ptr<const Run> check = gauss_newton_step<M, 0, NI>(
      tangent, in_imu_model<NI>(x0), p, data, nullptr, in_imu_model<NI>(from),
      with_imu_prior<NI, M, 0>(calibration_held<M, 0, 0>(p0, run), sigma), next_hooks, track, at,
      veto);
  if (wald_statistic<M, NI>(*check, at.start, p, out)) return;
  // That step lost its way: a free pass from the same start judges instead, over-confident but
  // rare as a fallback (docs/estimator.md, "The IMU's intrinsics").
  const std::unique_ptr<const Run> free(new Run(run_pass<M, 0, NI>(
      config, in_imu_model<NI>(from), p, data, nullptr, {}, next_hooks(), nullptr, false, &veto)));
  wald_statistic<M, NI>(*free, in_imu_model<NI>(from), p, out);
}

}  // namespace

template <int M, int NK, int NI>
CalibrationRun<M, NK, NI> run_loop(const CalibrationConfig& config,
                                   const typename CalibrationRun<M, NK, NI>::State& x0,
                                   const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0,
                                   const LoopData& data,
                                   const typename CalibrationRun<M, NK, NI>::State* truth,
                                   const std::function<void(double)>& progress,
                                   const std::function<LoopHooks<M>(int pass)>& hooks,
                                   Passes passes) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  State start = x0;  // where the last pass started the IMU, for the ideal-IMU check
  const auto calibrate = [&](const CalibrationConfig& c) {
    start = x0;
    CalibrationRun<M, NK, NI> run =
        free_passes<M, NK, NI>(c, p0, data, truth, progress, hooks, passes, start);
    if (passes.refine && !run.history.empty())
      refine<M, NK, NI>(c, x0, p0, data, truth, hooks, start, run);
    return run;
  };
  CalibrationRun<M, NK, NI> run;
  CalibrationConfig used = config;
  if (passes.estimate_noise && passes.refine) {
    // The noise levels from the data (noise_estimate.hpp): the IMU's white-noise densities from
    // its samples, once; the pixel noise by Foerstner's estimate from the refinement's last pass,
    // and the calibration made again with it until it settles.
    NoiseEstimate noise;
    noise.estimated = true;
    noise.told = config.imu;
    noise.told_pixel_sigma = config.pixel_sigma;
    noise.imu = config.imu;
    noise.imu_rate_hz = 1e9 / static_cast<double>(data.imu_period_ns);
    noise.imu_model = State::kImuModel;
    noise.imu_tolerances = passes.imu_tolerances;
    ImuWhiteNoise white;
    if (imu_white_noise(*data.open_imu(), data.imu_period_ns, white)) {
      noise.imu_differences = white.differences;
      noise.gyro_stride2_ratio = white.gyro_stride2_ratio;
      noise.accel_stride2_ratio = white.accel_stride2_ratio;
      noise.gyro_estimated = ImuWhiteNoise::white(white.gyro_stride2_ratio);
      noise.accel_estimated = ImuWhiteNoise::white(white.accel_stride2_ratio);
      if (noise.gyro_estimated) {
        noise.imu.gyro_noise_density = white.gyro_density;
        noise.gyro_density_sigma = white.gyro_sigma;
      }
      if (noise.accel_estimated) {
        noise.imu.accel_noise_density = white.accel_density;
        noise.accel_density_sigma = white.accel_sigma;
      }
    }
    used.imu = noise.imu;
    used.sigma_points.noise_statistics = true;
    used.pixel_sigma = kNoiseStartScale * config.pixel_sigma;
    for (int k = 0; k < kMaxNoiseRuns; ++k) {
      run = calibrate(used);
      noise.refinements = k + 1;
      if (run.history.empty()) break;
      double estimate = 0.0, sigma = 0.0;
      const FilterCounters& c = run.filter_counters;
      if (!pixel_noise_estimate(c.pixel_noise_quadratic, c.pixel_noise_redundancy, used.pixel_sigma,
                                estimate, sigma))
        break;
      noise.pixel_sigma = estimate;
      noise.pixel_sigma_sigma = sigma;
      noise.pixel_redundancy = c.pixel_noise_redundancy;
      noise.converged = std::abs(estimate / used.pixel_sigma - 1.0) < kNoiseConvergedFraction;
      if (noise.converged) break;
      if (k + 1 < kMaxNoiseRuns) used.pixel_sigma = estimate;
    }
    run.result.noise = noise;
  } else {
    run = calibrate(config);
  }
  if constexpr (NK == 0 && NI == 0 && imu_model_built(12)) {
    if (passes.check_imu && passes.refine && !run.history.empty())
      check_ideal_imu<M>(used, x0, p0, run, start, data, hooks, passes.imu_tolerances,
                         run.result.imu.ideal_check);
  }
  run.result.markers_observed = markers_in(data);
  if (!run.history.empty()) record_prior_offset<M, NK, NI>(x0, p0, run);
  record_label_swaps(used.pixel_sigma, run);
  record_prior_fit(used, run);
  for (int i = State::kCalibrationBegin; i < State::kDim; ++i)
    run.prior_sigma.push_back(std::sqrt(p0(i, i)));
  for (int i = State::kImu; i < State::kImu + NI; ++i)
    run.result.imu.prior_sigma.push_back(std::sqrt(p0(i, i)));
  run.result.imu.rate_hz = 1e9 / double(data.imu_period_ns);
  run.pixel_sigma = used.pixel_sigma;
  run.gate_after_frames = config.gate_after_frames;
  return run;
}

template <int M, int NK, int NI>
CalibrationRun<M, NK, NI> run_single_pass(
    const CalibrationConfig& config, const typename CalibrationRun<M, NK, NI>::State& x0,
    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0, const LoopData& data,
    const typename CalibrationRun<M, NK, NI>::State* truth) {
  return run_pass<M, NK, NI>(config, x0, p0, data, truth, {}, LoopHooks<M>{});
}
#define MIRRORCAL_INSTANTIATE_RUN_LOOP_(M, NK, NI) template MIRRORCAL_RUN_LOOP(M, NK, NI);
MIRRORCAL_FOR_EACH_FILTER(MIRRORCAL_INSTANTIATE_RUN_LOOP_)
#undef MIRRORCAL_INSTANTIATE_RUN_LOOP_
#define MIRRORCAL_INSTANTIATE_RUN_SINGLE_PASS_(M, NI) template MIRRORCAL_RUN_SINGLE_PASS(M, NI);
MIRRORCAL_FOR_EACH_STAGE1_FILTER(MIRRORCAL_INSTANTIATE_RUN_SINGLE_PASS_)
#undef MIRRORCAL_INSTANTIATE_RUN_SINGLE_PASS_

io::CalibrationStart calibration_start(const CalibrationResult& earlier) {
  io::CalibrationStart s;
  s.p_b_c = earlier.p_b_c;
  s.q_b_c = earlier.q_b_c;
  s.features_c = earlier.markers;
  s.has_t_d = true;
  s.t_d = earlier.t_d;
  const int n = s.layout().size();
  s.covariance = earlier.covariance.topLeftCorner(n, n);
  s.trusted = consistent(earlier);
  s.imu_model = earlier.imu.model;
  const Eigen::MatrixXd& imu = earlier.imu.covariance;  // columns: the whole block, then theirs
  if (earlier.imu.estimated() && imu.cols() == earlier.covariance.cols() + imu.rows()) {
    s.imu_intrinsics = earlier.imu.intrinsics;
    s.imu_covariance.resize(imu.rows(), n + imu.rows());
    s.imu_covariance << imu.leftCols(n), imu.rightCols(imu.rows());
  }
  return s;
}

void note_start(const io::CalibrationStart& earlier, CalibrationResult& r) {
  r.from_untrusted = !earlier.trusted;
  r.from_imu_model = earlier.imu_model;
}

}  // namespace mirrorcal::calibration
