#include "sim_run.hpp"

#include "mirrorcal/sim_host/simulator.hpp"

namespace mirrorcal::app {

CalibrationConfig scenario_config(const sim::Scenario& s) {
  CalibrationConfig c;
  c.gravity_n = s.gravity_n;
  c.imu = s.imu;
  c.pixel_sigma = s.pixel_sigma;
  c.intrinsics = s.truth.intrinsics;
  return c;
}

namespace {

template <class State>
State truth_state(const sim::Scenario& s) {
  State t;
  t.p_b_c = s.truth.p_b_c;
  t.q_b_c = s.truth.q_b_c;
  for (int i = 0; i < State::kMarkers; ++i)
    t.markers.template segment<3>(3 * i) = s.truth.markers[static_cast<std::size_t>(i)];
  return t;
}

}  // namespace

SimRun<0> run_simulation(const sim::Scenario& s, std::uint64_t seed,
                         const std::function<void(double)>& progress,
                         firmware::LoopProfiler* profiler) {
  using Run = SimRun<0>;
  using Filter = Run::Filter;
  Run run;
  run.truth = truth_state<Run::State>(s);
  const sim::SimData data = sim::simulate(s, seed);
  const Prior<kMarkers> prior = sim::draw_prior<kMarkers>(s, data, sim::derive_seed(seed, 100));

  Filter filter(scenario_config(s));
  Run::State x0;
  Filter::Covariance p0;
  initialise(prior, x0, p0);
  filter.reset(x0, p0);

  sim::VectorImuSource imu(data.imu);
  sim::VectorMarkerSource<kMarkers> markers(data.frames);
  HistorySink<Filter> sink(data.frames.size() + 1, &run.truth);
  firmware::LoopConfig lc;
  lc.imu_period_ns = static_cast<std::int64_t>(1e9 / s.imu_rate_hz);
  lc.profiler = profiler;
  firmware::CalibrationLoop<double, kMarkers, 0> loop(filter, imu, markers, lc, &sink);

  const std::size_t report_every = data.imu.size() / 100 + 1;
  std::size_t n = 0;
  while (loop.step()) {
    if (progress && ++n % report_every == 0)
      progress(static_cast<double>(n) / static_cast<double>(data.imu.size()));
  }
  loop.finish();

  run.history = sink.rows();
  run.result = make_result(filter, s.truth.width, s.truth.height);
  run.filter_counters = filter.counters();
  run.loop_counters = loop.counters();
  run.markers_out_of_image = data.markers_out_of_image;
  run.imu_samples = data.imu.size();
  run.frames = data.frames.size();
  return run;
}

}  // namespace mirrorcal::app
