#include "live_feedback.hpp"

#include <cmath>

#include <Eigen/Eigenvalues>

namespace mirrorcal::app {

using namespace calibration;

namespace {

// The largest 1-sigma of a 3x3 block and its direction; with the prior's sigma along it.
GroupUncertainty worst_direction(const Eigen::Matrix3d& p, const Eigen::Matrix3d& p0) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(p);
  GroupUncertainty g;
  g.direction = eig.eigenvectors().col(2);  // eigenvalues ascend
  g.sigma = std::sqrt(std::max(0.0, eig.eigenvalues()(2)));
  g.prior_sigma = std::sqrt(std::max(0.0, g.direction.dot(p0 * g.direction)));
  return g;
}

// The markers the camera showed the filter: used, gated or not predictable.
template <class Filter>
std::uint64_t markers_seen(const Filter& filter) {
  const FilterCounters& c = filter.counters();
  return c.markers_used + c.markers_gated + c.markers_invalid;
}

int most_perpendicular_axis(const Eigen::Vector3d& d) {
  int axis = 0;
  for (int i = 1; i < 3; ++i)
    if (std::abs(d(i)) < std::abs(d(axis))) axis = i;
  return axis;
}

int largest_axis(const Eigen::Vector3d& d) {
  int axis = 0;
  d.cwiseAbs().maxCoeff(&axis);
  return axis;
}

// The IMU group of an intrinsic: D_a's entries the accelerometer's, D_g's the gyroscope's, T_s's
// the g-sensitivity's. Unused in a build with the ideal IMU's model only.
[[maybe_unused]] FeedbackGroup imu_group(ImuIntrinsics<double>::Matrix m) {
  return m == ImuIntrinsics<double>::kDa   ? FeedbackGroup::kAccelerometer
         : m == ImuIntrinsics<double>::kDg ? FeedbackGroup::kGyroscope
                                           : FeedbackGroup::kGSensitivity;
}

}  // namespace

template <int M, int NI>
CalibrationUncertainty calibration_uncertainty(
    const typename CalibrationFilter<double, M, 0, NI>::Covariance& p,
    const typename CalibrationFilter<double, M, 0, NI>::Covariance& p0,
    const Eigen::Quaterniond& q_b_c) {
  using State = typename CalibrationFilter<double, M, 0, NI>::State;
  using Covariance = typename CalibrationFilter<double, M, 0, NI>::Covariance;
  CalibrationUncertainty u;
  // p_b_c is in the IMU frame; the advice speaks of the camera's axes.
  const Eigen::Matrix3d r_c_b = q_b_c.toRotationMatrix().transpose();
  const auto in_camera = [&](const Covariance& c, int at) {
    return Eigen::Matrix3d(r_c_b * c.template block<3, 3>(at, at) * r_c_b.transpose());
  };
  u[0] = worst_direction(in_camera(p, State::kPbc), in_camera(p0, State::kPbc));
  // The rotation's error is R_b_c Exp(e): e is in the camera frame already.
  u[1] = worst_direction(p.template block<3, 3>(State::kPhi, State::kPhi),
                         p0.template block<3, 3>(State::kPhi, State::kPhi));
  for (int m = 0; m < M; ++m) {
    const int at = State::kPi + 3 * m;
    const GroupUncertainty g =
        worst_direction(p.template block<3, 3>(at, at), p0.template block<3, 3>(at, at));
    if (m == 0 || g.sigma > u[2].sigma) u[2] = g;
  }
  u[3].sigma = std::sqrt(std::max(0.0, p(State::kTd, State::kTd)));
  u[3].prior_sigma = std::sqrt(std::max(0.0, p0(State::kTd, State::kTd)));
  if constexpr (NI > 0) {
    // Each intrinsic against its own prior (scale factors and axis angles differ by tenfold).
    std::array<double, kMaxFeedbackGroups> worst{};
    ImuIntrinsics<double>::for_each_entry<NI>(
        [&](ImuIntrinsics<double>::Matrix m, int, int column, int j) {
          const int at = State::kImu + j;
          const double sigma = std::sqrt(std::max(0.0, p(at, at)));
          const double prior = std::sqrt(std::max(0.0, p0(at, at)));
          const auto g = static_cast<std::size_t>(imu_group(m));
          const double ratio = sigma / std::max(prior, 1e-300);
          if (ratio < worst[g]) return;
          worst[g] = ratio;
          u[g] = {sigma, prior, Eigen::Vector3d::Unit(column)};
        });
  }
  return u;
}

const char* motion_advice(FeedbackGroup group, const Eigen::Vector3d& direction) {
  static constexpr const char* kRotateAbout[3] = {
      "tilt the rig up and down (about the camera's x axis)",
      "turn the rig left and right (about the camera's y axis)",
      "roll the rig about the camera's optical axis"};
  static constexpr const char* kImuRate[3] = {"rotate the rig briskly about the IMU's x axis",
                                              "rotate the rig briskly about the IMU's y axis",
                                              "rotate the rig briskly about the IMU's z axis"};
  static constexpr const char* kImuUpDown[3] = {
      "hold the rig with the IMU's x axis pointing up, then down, a few seconds each",
      "hold the rig with the IMU's y axis pointing up, then down, a few seconds each",
      "hold the rig with the IMU's z axis pointing up, then down, a few seconds each"};
  static constexpr const char* kImuRateUpDown[3] = {
      "rotate the rig briskly with the IMU's x axis pointing up, then down",
      "rotate the rig briskly with the IMU's y axis pointing up, then down",
      "rotate the rig briskly with the IMU's z axis pointing up, then down"};
  switch (group) {
    case FeedbackGroup::kCameraPosition:
    case FeedbackGroup::kCameraRotation:
      return kRotateAbout[most_perpendicular_axis(direction)];
    case FeedbackGroup::kMarkers:
      return std::abs(direction.z()) > std::sqrt(0.5)
                 ? "move the rig towards and away from the mirror"
                 : "tilt the rig so that the markers sweep across the image";
    case FeedbackGroup::kTimeOffset:
      return "rotate the rig briskly back and forth";
    case FeedbackGroup::kGyroscope:
      return kImuRate[largest_axis(direction)];
    case FeedbackGroup::kAccelerometer:
      return kImuUpDown[largest_axis(direction)];
    case FeedbackGroup::kGSensitivity:
      return kImuRateUpDown[largest_axis(direction)];
  }
  return "";
}

const char* group_name(FeedbackGroup group) {
  switch (group) {
    case FeedbackGroup::kCameraPosition:
      return "camera position";
    case FeedbackGroup::kCameraRotation:
      return "camera rotation";
    case FeedbackGroup::kMarkers:
      return "markers";
    case FeedbackGroup::kTimeOffset:
      return "time offset";
    case FeedbackGroup::kGyroscope:
      return "gyroscope's intrinsics";
    case FeedbackGroup::kAccelerometer:
      return "accelerometer's intrinsics";
    case FeedbackGroup::kGSensitivity:
      return "gyroscope's g-sensitivity";
  }
  return "";
}

template <int M, int NI>
LiveFeedback<M, NI>::LiveFeedback(const typename Filter::Covariance& p0, std::FILE* out,
                                  bool every_window)
    : p0_(p0), out_(out), every_window_(every_window) {}

template <int M, int NI>
void LiveFeedback<M, NI>::publish(std::int64_t t_ns, const Filter& filter) {
  const Eigen::Quaterniond q = filter.state().q_n_b;
  if (!started_) {
    started_ = true;
    window_start_ns_ = t_ns;
    last_q_ = q;
    markers_at_window_start_ = markers_seen(filter);
    depth_low_ = depth_high_ = filter.state().p.z();
    return;
  }
  turned_rad_ += last_q_.angularDistance(q);
  last_q_ = q;
  depth_low_ = std::min(depth_low_, filter.state().p.z());
  depth_high_ = std::max(depth_high_, filter.state().p.z());
  if (static_cast<double>(t_ns - window_start_ns_) * 1e-9 < kWindowS) return;
  close_window(static_cast<double>(t_ns) * 1e-9, filter);
  window_start_ns_ = t_ns;
  turned_rad_ = 0.0;
  markers_at_window_start_ = markers_seen(filter);
  depth_low_ = depth_high_ = filter.state().p.z();
}

template <int M, int NI>
void LiveFeedback<M, NI>::close_window(double t_s, const Filter& filter) {
  const CalibrationUncertainty u =
      calibration_uncertainty<M, NI>(filter.covariance(), p0_, filter.state().q_b_c);
  std::array<bool, kMaxFeedbackGroups> settled{};
  // Once converged, a group must fall by twice as much to unsettle it again: sigmas that fall as
  // 1/sqrt(t) cross the threshold slowly, and the verdict should not flicker as they do.
  const double fall = verdict_ == Verdict::kConverged ? 2.0 * kSettledFall : kSettledFall;
  int advised = -1, weak = -1;
  double worst = 0.0, weakest = 0.0;
  for (int g = 0; g < kGroups; ++g) {
    const auto k = static_cast<std::size_t>(g);
    const double ratio = u[k].sigma / std::max(u[k].prior_sigma, 1e-300);
    const bool stopped = have_previous_ && u[k].sigma > (1.0 - fall) * previous_[k].sigma;
    // A direction the motion never excited does not fall either: settled also needs the data to
    // have told at least half of what the prior did not know. The IMU's intrinsics are the
    // exception: one the mirror's motion hardly sees settles near its prior, as weak.
    const bool imu = is_imu_group(static_cast<FeedbackGroup>(g));
    settled[k] = stopped && (ratio < kSettledRatio || imu);
    if (settled[k] && imu && ratio >= kSettledRatio && ratio >= weakest) {
      weakest = ratio;
      weak = g;
    }
    if (!settled[k] && ratio >= worst) {
      worst = ratio;
      advised = g;
    }
  }
  Verdict verdict = Verdict::kUncertain;
  if (markers_seen(filter) == markers_at_window_start_)
    verdict = Verdict::kNoMarkers;
  else if (turned_rad_ * 180.0 / M_PI < kMovedDeg && depth_high_ - depth_low_ < kMovedM)
    verdict = Verdict::kStill;
  else if (advised < 0)
    verdict = Verdict::kConverged;
  const bool changed = verdict != verdict_ || advised != advised_;
  if (changed || every_window_) print(t_s, verdict, advised, weak, u, settled);
  verdict_ = verdict;
  advised_ = advised;
  previous_ = u;
  have_previous_ = true;
}

template <int M, int NI>
void LiveFeedback<M, NI>::print(double t_s, Verdict verdict, int advised, int weak,
                                const CalibrationUncertainty& u,
                                const std::array<bool, kMaxFeedbackGroups>& settled) {
  if (out_ == nullptr) return;
  std::fprintf(out_, "live %.0f s: ", t_s);
  // Each group's sigma in the unit a user reads it in (the IMU's intrinsics in per cent), and its
  // share of the prior's.
  const auto figures = [&](bool only_unsettled) {
    static constexpr double kScale[kMaxFeedbackGroups] = {1e3,   180.0 / M_PI, 1e3,  1e3,
                                                          100.0, 100.0,        100.0};
    static constexpr const char* kUnit[kMaxFeedbackGroups] = {"mm", "deg", "mm", "ms",
                                                              "%",  "%",   "%"};
    const char* sep = "";
    for (int g = 0; g < kGroups; ++g) {
      const auto k = static_cast<std::size_t>(g);
      if (only_unsettled && settled[k]) continue;
      std::fprintf(out_, "%s%s %.3g %s (%.3g %% of prior)", sep,
                   group_name(static_cast<FeedbackGroup>(g)), kScale[k] * u[k].sigma, kUnit[k],
                   100.0 * u[k].sigma / std::max(u[k].prior_sigma, 1e-300));
      sep = ", ";
    }
  };
  const auto advice = [&](int g) {
    return motion_advice(static_cast<FeedbackGroup>(g), u[static_cast<std::size_t>(g)].direction);
  };
  switch (verdict) {
    case Verdict::kNoMarkers:
      std::fprintf(out_, "no markers seen for %.0f s: point the camera at the mirror\n", kWindowS);
      break;
    case Verdict::kStill:
      std::fprintf(out_, "the rig hardly moved: move it; ");
      figures(true);
      std::fprintf(out_, "\n");
      break;
    case Verdict::kUncertain:
      std::fprintf(out_, "still uncertain: ");
      figures(true);
      std::fprintf(out_, "; for the %s: %s\n", group_name(static_cast<FeedbackGroup>(advised)),
                   advice(advised));
      break;
    case Verdict::kConverged:
      std::fprintf(out_,
                   "converged (every sigma below %.0f %% of its prior%s, none fell by %.0f %% "
                   "over %.0f s of motion): ",
                   100.0 * kSettledRatio, weak >= 0 ? " but the weak intrinsics'" : "",
                   100.0 * kSettledFall, kWindowS);
      figures(false);
      if (weak >= 0)
        std::fprintf(out_,
                     "; the %s stay weak, near their prior (the report marks them): to inform "
                     "them, %s",
                     group_name(static_cast<FeedbackGroup>(weak)), advice(weak));
      std::fprintf(out_, "; you may stop\n");
      break;
    case Verdict::kNone:
      break;
  }
  std::fflush(out_);
}

#define MIRRORCAL_LIVE_FEEDBACK_(M, NI)                           \
  template class LiveFeedback<M, NI>;                             \
  template CalibrationUncertainty calibration_uncertainty<M, NI>( \
      const CalibrationFilter<double, M, 0, NI>::Covariance&,     \
      const CalibrationFilter<double, M, 0, NI>::Covariance&, const Eigen::Quaterniond&);
MIRRORCAL_FOR_EACH_STAGE1_FILTER(MIRRORCAL_LIVE_FEEDBACK_)
#undef MIRRORCAL_LIVE_FEEDBACK_

}  // namespace mirrorcal::app
