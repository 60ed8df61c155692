#include "sim_run.hpp"

#include <optional>

#include "sim_frames.hpp"

namespace mirrorcal::app {

CalibrationConfig scenario_config(const sim::Scenario& s) {
  CalibrationConfig c;
  c.gravity_n = s.gravity_n;
  c.imu = s.imu;
  c.pixel_sigma = s.pixel_sigma;
  c.intrinsics = s.truth.intrinsics;
  return c;
}

LoopData loop_data(const sim::Scenario& s, const sim::SimData& data) {
  LoopData d;
  d.imu = data.imu;
  d.frames = data.frames;
  d.imu_period_ns = static_cast<std::int64_t>(1e9 / s.imu_rate_hz);
  d.width = s.truth.width;
  d.height = s.truth.height;
  return d;
}

Prior<kMarkers> simulation_prior(const sim::Scenario& s, const sim::SimData& data,
                                 std::uint64_t seed) {
  return sim::draw_prior<kMarkers>(s, data, sim::derive_seed(seed, 100));
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

template <int NK>
SimRun<NK> run_loop(const CalibrationConfig& config, const typename SimRun<NK>::State& x0,
                    const typename SimRun<NK>::Filter::Covariance& p0, const LoopData& data,
                    const typename SimRun<NK>::State* truth,
                    const std::function<void(double)>& progress) {
  using Run = SimRun<NK>;
  using Filter = typename Run::Filter;
  Run run;
  if (truth != nullptr) run.truth = *truth;
  Filter filter(config);
  filter.reset(x0, p0);

  sim::VectorImuSource imu(data.imu);
  sim::VectorMarkerSource<kMarkers> listed(data.frames);
  hal::MarkerSource<kMarkers>& markers = data.camera != nullptr ? *data.camera : listed;
  HistorySink<Filter> sink(data.frames.size() + 1, truth != nullptr ? &run.truth : nullptr);
  firmware::LoopConfig lc;
  lc.imu_period_ns = data.imu_period_ns;
  firmware::CalibrationLoop<double, kMarkers, NK> loop(filter, imu, markers, lc, &sink);
  loop.set_identifier(data.identifier);

  const std::size_t report_every = data.imu.size() / 100 + 1;
  std::size_t n = 0;
  while (loop.step()) {
    if (progress && ++n % report_every == 0)
      progress(static_cast<double>(n) / static_cast<double>(data.imu.size()));
  }
  loop.finish();

  run.history = sink.rows();
  run.result = make_result(filter, data.width, data.height);
  run.filter_counters = filter.counters();
  run.loop_counters = loop.counters();
  run.imu_samples = data.imu.size();
  run.frames = data.frames.size();
  return run;
}

template SimRun<0> run_loop<0>(const CalibrationConfig&, const SimRun<0>::State&,
                               const SimRun<0>::Filter::Covariance&, const LoopData&,
                               const SimRun<0>::State*, const std::function<void(double)>&);
template SimRun<5> run_loop<5>(const CalibrationConfig&, const SimRun<5>::State&,
                               const SimRun<5>::Filter::Covariance&, const LoopData&,
                               const SimRun<5>::State*, const std::function<void(double)>&);

SimRun<0> run_simulation(const sim::Scenario& s, std::uint64_t seed,
                         const std::function<void(double)>& progress, const FrameMode& frames) {
  using Run = SimRun<0>;
  const sim::SimData data = sim::simulate(s, seed);
  const Prior<kMarkers> prior = simulation_prior(s, data, seed);
  Run::State x0;
  Run::Filter::Covariance p0;
  initialise(prior, x0, p0);
  const Run::State truth = truth_state<Run::State>(s);
  LoopData loop_input = loop_data(s, data);
  std::optional<RenderedMarkers> rendered;
  if (frames.enabled) {
    sim::RenderConfig render;
    render.format = frames.format;
    rendered.emplace(s, render, sim::derive_seed(seed, 200));
    loop_input.camera = &*rendered;
    loop_input.identifier = &*rendered;
  }
  Run run = run_loop<0>(scenario_config(s), x0, p0, loop_input, &truth, progress);
  run.markers_out_of_image = data.markers_out_of_image;
  if (rendered) run.detection = rendered->report();
  return run;
}

}  // namespace mirrorcal::app
