// FilterOps for one configuration; included by the filter_ops_m*.cpp units only.
#pragma once

#include <cmath>

#include "filter_ops.hpp"
#include "mirrorcal/estimator/calibration_filter.hpp"
#include "mirrorcal/estimator/prior.hpp"
#include "textbook_ukf.hpp"

namespace mirrorcal::bench {

// NK > 0: stage 2 (double, M = 3: the configurations the product builds) through EuRoC cam0's
// radtan lens, NK = 4 with the lens known, NK = 8 with its coefficients estimated. kTextbook: the
// operations are the textbook UKF's (textbook_ukf.hpp) on the same inputs. NI > 0: stage 1 with
// the IMU's intrinsics (an ideal IMU's, known to 1e-4 like the rest).
template <typename S, int M, int NK = 0, bool kTextbook = false, int NI = 0>
class FilterOpsOf final : public FilterOps {
 public:
  using Filter = CalibrationFilter<S, M, NK, NI>;
  using State = typename Filter::State;

  FilterOpsOf() : prepared_(config()), filter_(config()) {
    // The IMU 45 cm in front of a wall mirror (the mirror plane is z = 0 of n, the camera looks
    // along body x): body x along -z of n, body z up along n's y.
    State x;
    Eigen::Matrix3d r_n_b;
    r_n_b << 0, 1, 0, 0, 0, 1, -1, 0, 0;
    r_n_b.transposeInPlace();
    r_n_b = Eigen::Matrix3d(Eigen::Quaterniond(r_n_b).normalized());
    x.q_n_b = Eigen::Quaterniond(r_n_b).cast<S>();
    x.p = Vec3<S>(S(0), S(0), S(0.45));
    x.v = Vec3<S>(S(0.05), S(-0.02), S(0.01));
    x.p_b_c = Vec3<S>(S(0.01), S(-0.05), S(0.10));
    Eigen::Matrix3d r_b_c;  // optical axis along body x, image x along body -y
    r_b_c << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    x.q_b_c = Eigen::Quaterniond(r_b_c).cast<S>();
    for (int i = 0; i < M; ++i) {  // markers spread around the lens, a few cm off
      const double a = 2.0 * 3.14159265358979 * i / M;
      x.markers.template segment<3>(3 * i) =
          Vec3<S>(S(0.06 * std::cos(a)), S(0.06 * std::sin(a)), S(-0.01 * (i % 3)));
    }
    if constexpr (NK > 0) {
      const std::array<double, NK> k = camera_parameters<NK>(config().intrinsics);
      for (int j = 0; j < NK; ++j) x.intrinsics(j) = S(k[static_cast<std::size_t>(j)]);
    }
    typename Filter::Covariance p = Filter::Covariance::Zero();
    p.diagonal().setConstant(S(1e-8));  // converged: one plain step per update
    prepared_.reset(x, p);
    // The frame: every marker where the estimate sees it, a pixel off.
    frame_.t_ns = 0;
    Eigen::Matrix<S, 2 * M, 1> z;
    std::array<bool, M> ok;
    ok.fill(true);
    predict_markers(x, config().intrinsics.template cast<S>(), prepared_.exposure(frame_.t_ns),
                    std::array<S, M>{}, z, ok);
    for (int i = 0; i < M; ++i) {
      frame_.seen[i] = ok[i];
      frame_.uv[i] = z.template segment<2>(2 * i).template cast<double>() + Eigen::Vector2d(1, -1);
    }
    s0_.t_ns = 0;
    s1_.t_ns = 5'000'000;
    s0_.gyro = Eigen::Vector3d(0.1, -0.2, 0.3);
    s1_.gyro = Eigen::Vector3d(0.12, -0.19, 0.28);
    s0_.accel = Eigen::Vector3d(0.2, 9.81, -0.1);
    s1_.accel = Eigen::Vector3d(0.25, 9.79, -0.12);
    exposed_ = prepared_.exposure(frame_.t_ns);
    q_.setZero();
    q_.template topLeftCorner<15, 15>() = imu_process_noise<S>(config().imu, 0.005);
    restore();
  }

  int markers() const override { return M; }
  int dim() const override { return Filter::kDim; }
  std::size_t filter_bytes() const override { return sizeof(Filter); }
  std::size_t workspace_bytes() const override { return Filter::workspace_bytes(); }
  void restore() override {
    if constexpr (kTextbook)
      textbook_.reset(prepared_.state(), prepared_.covariance());
    else
      filter_ = prepared_;
  }
  bool predict() override {
    if constexpr (kTextbook) {
      const Vec3<S> gravity = config().gravity_n.template cast<S>();
      return textbook_.predict([&](State& x) { propagate_imu(x, s0_, s1_, gravity); }, q_);
    } else {
      return filter_.predict(s0_, s1_) == FilterStatus::kOk;
    }
  }
  bool update() override {
    if constexpr (kTextbook) {
      Eigen::Matrix<S, 2 * M, 1> z;
      for (int i = 0; i < M; ++i) z.template segment<2>(2 * i) = frame_.uv[i].template cast<S>();
      const Pinhole<S> intrinsics = config().intrinsics.template cast<S>();
      const auto measure = [&](const State& x, Eigen::Matrix<S, 2 * M, 1>& zp, bool& ok) {
        std::array<bool, M> seen;
        seen.fill(true);
        predict_markers(x, intrinsics, exposed_, std::array<S, M>{}, zp, seen);
        for (const bool b : seen) ok = ok && b;
      };
      return textbook_.template update<2 * M>(measure, z,
                                              S(config().pixel_sigma * config().pixel_sigma));
    } else {
      return filter_.update(frame_).status == FilterStatus::kOk;
    }
  }
  double settle() override { return covariance()(Filter::kDim - 1, 0); }
  std::vector<double> estimate() override {
    const auto offset = state().template boxminus_block<0, Filter::kDim>(prepared_.state());
    std::vector<double> out(offset.data(), offset.data() + offset.size());
    const auto& p = covariance();
    out.insert(out.end(), p.data(), p.data() + p.size());
    return out;
  }

 private:
  static CalibrationConfig config() {
    CalibrationConfig c;
    c.intrinsics = Pinhole<double>{833.33, 833.33, 322.0, 248.0, 0.0};
    if (NK > 0) {
      c.intrinsics.distortion = Distortion::kRadtan;
      c.intrinsics.coeffs = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05};
    }
    return c;
  }
  const State& state() const {
    if constexpr (kTextbook) return textbook_.state();
    return filter_.state();
  }
  const typename Filter::Covariance& covariance() const {
    if constexpr (kTextbook) return textbook_.covariance();
    return filter_.covariance();
  }

  Filter prepared_, filter_;
  TextbookUkf<State> textbook_;
  MarkerFrame<M> frame_{};
  ImuSample s0_{}, s1_{};
  Exposure<S> exposed_{};
  typename Filter::Covariance q_;  // the process noise of one step on the IMU block
};

}  // namespace mirrorcal::bench
