// Live feedback for `mirrorcal run`: while the user moves the rig, which calibration states are
// still uncertain, what motion would inform them, and when the calibration has converged. No other
// calibration tool tells the user this while the data are being taken; without it a user stops
// too early (a weak direction never excited) or moves for minutes after the data stopped helping.
#pragma once

#include <array>
#include <cstdint>
#include <cstdio>

#include <Eigen/Core>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/estimator/calibration_filter.hpp"
#include "mirrorcal/loop/loop.hpp"

namespace mirrorcal::app {

// The parts of the calibration a user's motion informs differently: the calibration's groups (the
// first four of CalibrationGroup: run's filter has no camera intrinsics) and, with the IMU's
// intrinsics estimated (NI > 0), the gyroscope's (D_g), the accelerometer's (D_a) and the gyro's
// g-sensitivity (T_s, NI = 24).
enum class FeedbackGroup : std::uint8_t {
  kCameraPosition,
  kCameraRotation,
  kMarkers,
  kTimeOffset,
  kGyroscope,
  kAccelerometer,
  kGSensitivity
};
static_assert(int(FeedbackGroup::kTimeOffset) == int(CalibrationGroup::kTimeOffset),
              "the calibration's groups come first, in CalibrationGroup's order");
constexpr int kMaxFeedbackGroups = 7;
template <int NI>
constexpr int kFeedbackGroups = NI == 0   ? 4
                                : NI < 24 ? 6
                                          : 7;
constexpr bool is_imu_group(FeedbackGroup g) {
  return int(g) > int(FeedbackGroup::kTimeOffset);
}

// One group's uncertainty: the 1-sigma of its least-known direction against the prior's there.
// The calibration's groups: SI units (m, rad, m, s), the direction in the camera frame (unit;
// unused for the time offset). The IMU's: its least-known intrinsic (a matrix entry, relative),
// the direction the IMU axis whose rate (gyroscope) or specific force (accelerometer,
// g-sensitivity) informs it: D_g's entry (r, c) multiplies the reading about axis c.
struct GroupUncertainty {
  double sigma = 0.0;
  double prior_sigma = 0.0;
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();
};

using CalibrationUncertainty = std::array<GroupUncertainty, kMaxFeedbackGroups>;

// The uncertainty of each group from a filter's covariance P and its prior's P0 (the live filter
// of M markers, NI IMU intrinsics and no camera intrinsics: run's filter). The markers' group is
// the worst of the M markers, an IMU group its intrinsic with the largest sigma against its prior.
template <int M, int NI = 0>
CalibrationUncertainty calibration_uncertainty(
    const typename CalibrationFilter<double, M, 0, NI>::Covariance& p,
    const typename CalibrationFilter<double, M, 0, NI>::Covariance& p0,
    const Eigen::Quaterniond& q_b_c);

// The motion that informs a group's least-known direction, as a user would be told it. For the
// camera's position and rotation: a rotation about the camera axis most nearly perpendicular to
// that direction (a rotation about an axis says nothing along it: the lever arm and the hand-eye
// rotation are seen only across it). For the markers: along the optical axis their depth trades
// against the mirror's distance, which only motion towards and away from the mirror separates.
// For the gyroscope: brisk rotation about the IMU axis named; for the accelerometer, that axis
// pointed up and then down (gravity is the largest specific force a hand-held rig sees, and both
// signs separate a scale factor from the bias).
const char* motion_advice(FeedbackGroup group, const Eigen::Vector3d& direction);

const char* group_name(FeedbackGroup group);

// The sink `run`'s live loop publishes to: every kWindowS of IMU time it compares each group's
// sigma with the window before and prints a line to `out` when the verdict changes (on a terminal
// also every window): the groups still uncertain and the motion for the worst of them, or that the
// calibration has converged (every sigma below kSettledRatio of its prior's, and none fell by more
// than kSettledFall over a window in which the rig moved and the markers were seen; twice that to
// leave the verdict again). Allocates nothing: it
// runs inside the loop.
// With the IMU's intrinsics a group of them that stops falling while still near its prior is
// weak: the motion leaves it to the prior (the report marks it), which does not hold back the
// verdict; the converged line names it and the motion that would inform it.
template <int M, int NI = 0>
class LiveFeedback final : public loop::EstimateSink<CalibrationFilter<double, M, 0, NI>> {
 public:
  using Filter = CalibrationFilter<double, M, 0, NI>;
  static constexpr int kGroups = kFeedbackGroups<NI>;
  static constexpr double kWindowS = 5.0;
  static constexpr double kSettledFall = 0.05;
  // And its sigma below this share of the prior's: a direction the motion never excited stays
  // near its prior and does not fall either, which must not read as converged.
  static constexpr double kSettledRatio = 0.5;
  // A window with less rotation than this (total angle turned, deg) cannot show convergence: a rig
  // held still gains nothing, and its sigmas stop falling for that reason alone.
  static constexpr double kMovedDeg = 20.0;
  // Or moved towards or away from the mirror by this much (m; the range of the distance, which
  // the mirror observes, unlike the position along it).
  static constexpr double kMovedM = 0.05;

  LiveFeedback(const typename Filter::Covariance& p0, std::FILE* out, bool every_window);
  void publish(std::int64_t t_ns, const Filter& filter) override;

 private:
  enum class Verdict : std::uint8_t { kNone, kNoMarkers, kStill, kUncertain, kConverged };
  void close_window(double t_s, const Filter& filter);
  void print(double t_s, Verdict verdict, int advised, int weak, const CalibrationUncertainty& u,
             const std::array<bool, kMaxFeedbackGroups>& settled);

  typename Filter::Covariance p0_;
  std::FILE* out_;
  bool every_window_;
  bool started_ = false;
  std::int64_t window_start_ns_ = 0;
  Eigen::Quaterniond last_q_ = Eigen::Quaterniond::Identity();
  double turned_rad_ = 0.0;
  double depth_low_ = 0.0, depth_high_ = 0.0;  // the IMU's distance from the mirror (n's z)
  std::uint64_t markers_at_window_start_ = 0;
  bool have_previous_ = false;
  CalibrationUncertainty previous_{};
  Verdict verdict_ = Verdict::kNone;
  int advised_ = -1;
};
// Compiled in live_feedback.cpp for every built M and IMU model.
#define MIRRORCAL_EXTERN_LIVE_FEEDBACK_(M, NI) extern template class LiveFeedback<M, NI>;
MIRRORCAL_FOR_EACH_STAGE1_FILTER(MIRRORCAL_EXTERN_LIVE_FEEDBACK_)
#undef MIRRORCAL_EXTERN_LIVE_FEEDBACK_

}  // namespace mirrorcal::app
