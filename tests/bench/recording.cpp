#include "recording.hpp"

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/loop/loop.hpp"

namespace mirrorcal::bench {

Recording paper_recording() {
  Recording r;
  r.scenario = sim::paper_scenario();
  r.scenario.camera_rate_hz = 20.0;  // the paper scenario's camera runs at 60 Hz
  r.data = sim::simulate(r.scenario, 1);
  return r;
}

std::uint64_t calibrate(const Recording& r) {
  using Filter = CalibrationFilter<double, 3, 0>;
  const auto prior = sim::draw_prior<3>(r.scenario, r.data, 1);
  Filter filter(evaluation::scenario_config(r.scenario));
  Filter::State x0;
  Filter::Covariance p0;
  initialise(prior, x0, p0);
  filter.reset(x0, p0);
  io::VectorImuSource imu(r.data.imu);
  io::VectorMarkerSource<3> markers(r.data.frames);
  struct DropSink final : loop::EstimateSink<Filter> {
    void publish(std::int64_t, const Filter&) override {}
  } sink;
  loop::LoopConfig lc;
  lc.imu_period_ns = static_cast<std::int64_t>(1e9 / r.scenario.imu_rate_hz);
  loop::CalibrationLoop<double, 3, 0> loop(filter, imu, markers, lc, &sink);
  loop.run();
  return filter.counters().markers_used;
}

namespace {

template <int NI>
std::uint64_t shipped(const Recording& r) {
  using Run = calibration::CalibrationRun<3, 0, NI>;
  const auto prior = sim::draw_prior<3>(r.scenario, r.data, 1);
  typename Run::State x0;
  typename Run::Filter::Covariance p0;
  initialise(prior, x0, p0);
  calibration::Passes passes;
  passes.imu_tolerances = r.scenario.priors.imu_intrinsics;
  const Run run = calibration::run_loop<3, 0, NI>(evaluation::scenario_config(r.scenario), x0, p0,
                                                  evaluation::loop_data(r.scenario, r.data),
                                                  nullptr, {}, {}, passes);
  return run.filter_counters.markers_used;
}

// A template, so that a model the build lacks is not asked for.
template <int NI>
std::uint64_t shipped_if_built(const Recording& r) {
  if constexpr (imu_model_built(NI)) return shipped<NI>(r);
  (void)r;
  return 0;
}

}  // namespace

std::uint64_t calibrate_as_shipped(const Recording& r) {
  return shipped<0>(r);
}

std::uint64_t calibrate_as_shipped_with_imu_intrinsics(const Recording& r) {
  return shipped_if_built<12>(r);
}

}  // namespace mirrorcal::bench
