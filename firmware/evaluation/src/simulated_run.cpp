#include "mirrorcal/evaluation/simulated_run.hpp"

#include <algorithm>
#include <array>
#include <numeric>
#include <optional>

#include "mirrorcal/evaluation/rendered_markers.hpp"

namespace mirrorcal::evaluation {

using namespace calibration;

CalibrationConfig scenario_config(const sim::Scenario& s) {
  CalibrationConfig c;
  c.gravity_n = s.gravity_n;
  c.imu = s.told_imu.value_or(s.imu);
  c.pixel_sigma = s.told_pixel_sigma.value_or(s.pixel_sigma);
  c.intrinsics = s.truth.intrinsics;
  if (s.told_line_delay_s) c.intrinsics.line_delay_s = *s.told_line_delay_s;
  return c;
}

LoopData loop_data(const sim::Scenario& s, const sim::SimData& data) {
  LoopData d;
  d.imu = data.imu;
  d.frames = data.frames;
  d.imu_period_ns = imu_period_ns(s.imu_rate_hz);
  d.width = s.truth.width;
  d.height = s.truth.height;
  return d;
}

// The simulator's markers by the names the detection gave their LEDs (naming[i]: the truth's
// index of the LED named i). The passes take theirs from the rendered frames, but a pass's IMU
// start is fitted to the first frames of these (imu_start_from): under the truth's names, where
// identical LEDs were named otherwise, that fit put every reflection behind the camera, and the
// pass after the first used no marker at all.
template <int M>
LoopData loop_data_as_named(const sim::Scenario& s, const sim::SimData& data,
                            const std::array<int, M>& naming) {
  LoopData d = loop_data(s, data);
  std::array<int, M> name_of_led;
  name_of_led.fill(-1);
  for (int i = 0; i < M; ++i) name_of_led[static_cast<std::size_t>(naming[std::size_t(i)])] = i;
  for (io::ObservedFrame& f : d.frames) {
    for (io::ObservedMarker& m : f.markers) m.id = name_of_led[static_cast<std::size_t>(m.id)];
    // An LED no name went to (two names went to one: a track that was a room light's) is none.
    f.markers.erase(std::remove_if(f.markers.begin(), f.markers.end(),
                                   [](const io::ObservedMarker& m) { return m.id < 0; }),
                    f.markers.end());
  }
  return d;
}

// The scenario with its markers in the order the detection names them. The LEDs are named by the
// rig's shape fitted to their tracks, the priors' guesses and their brightness code, which cannot
// always tell identical LEDs apart: the name i may be given to another LED than the truth's i,
// and the estimate of marker i is then that LED's. A look at the first seconds of frames finds the
// names (names: which track got each; naming: which LED each went to), and every pass then labels
// those tracks from their first frame: the filter would otherwise go the seconds of the fit's
// window without a marker.
template <int M>
sim::Scenario named_as_detected(const sim::Scenario& s, const FrameMode& frames,
                                const sim::RenderConfig& render,
                                const detection::RigGeometry<M>& geometry, std::uint64_t seed,
                                TrackNames<M>& names, std::array<int, M>& naming) {
  names = no_track_names<M>();
  std::iota(naming.begin(), naming.end(), 0);
  // LEDs that blink their names are named as the truth's markers.
  if (!frames.enabled || frames.blink_period > 0) return s;
  RenderedMarkers<M> look(s, render, geometry, seed);
  MarkerFrame<M> frame;
  while (!look.named() && look.poll(frame) == hal::SourceStatus::kOk) {
  }
  names = look.track_names();
  naming = look.naming();
  sim::Scenario named = s;
  for (int i = 0; i < M; ++i)
    named.truth.markers[static_cast<std::size_t>(i)] =
        s.truth.markers[static_cast<std::size_t>(look.naming()[static_cast<std::size_t>(i)])];
  return named;
}

template <int M, int NI>
CalibrationRun<M, 0, NI> run_simulation(const sim::Scenario& s, std::uint64_t seed,
                                        const std::function<void(double)>& progress,
                                        const FrameMode& frames, loop::LoopProfiler* profiler,
                                        Passes passes) {
  using Run = CalibrationRun<M, 0, NI>;
  const sim::SimData data = sim::simulate(s, seed);
  const Prior<M> prior = sim::simulation_prior<M>(s, data, seed);
  typename Run::State x0;
  typename Run::Filter::Covariance p0;
  initialise(prior, x0, p0);
  CalibrationConfig config = scenario_config(s);
  if (frames.enabled && frames.pixel_sigma > 0.0) config.pixel_sigma = frames.pixel_sigma;
  sim::RenderConfig render;
  render.format = frames.format;
  render.spot_noise_px = frames.spot_noise_px >= 0.0 ? frames.spot_noise_px : s.pixel_sigma;
  if (frames.identical_leds) render.brightness = {render.brightness[1]};
  render.blink.period = frames.blink_period;
  render.room.enabled = frames.room;
  // The room's camera exposes its frames over a time that smears the spots: the filter is told it,
  // as camchain.yaml's exposure_time tells a user's.
  if (frames.room) config.intrinsics.exposure_s = render.room.exposure_s;
  const detection::RigGeometry<M> geometry =
      detection::prior_geometry(prior, config.intrinsics, config.pixel_sigma);
  const std::uint64_t render_seed = sim::derive_seed(seed, 200);
  TrackNames<M> names;
  std::array<int, M> naming;
  const typename Run::State truth = truth_state<typename Run::State>(
      named_as_detected<M>(s, frames, render, geometry, render_seed, names, naming));
  // With frames, every pass renders and detects them afresh (detection follows the prediction).
  std::optional<RenderedMarkers<M>> rendered;
  std::uint64_t wrong_labels_before = 0;
  const auto hooks = [&](int pass) {
    LoopHooks<M> h;
    // The timing of one pass: the last of those always made.
    if (pass == passes.min - 1) h.profiler = profiler;
    if (frames.enabled) {
      if (rendered) wrong_labels_before += rendered->report().wrong_labels;
      rendered.emplace(s, render, geometry, render_seed, names, &naming);
      h.source = &*rendered;
      h.relabeler = &*rendered;
      h.detection = [&] { return rendered->report(); };
    }
    return h;
  };
  passes.imu_tolerances = s.priors.imu_intrinsics;  // the ideal-IMU check's prior
  Run run = run_loop<M, 0, NI>(config, x0, p0, loop_data_as_named<M>(s, data, naming), &truth,
                               progress, hooks, passes);
  run.markers_out_of_image = data.markers_out_of_image;
  if (rendered) {
    run.detection = rendered->report();
    run.detection.wrong_labels_before = wrong_labels_before;
    run.result.detection = detection_counts(run.detection);
  }
  return run;
}

template <int M, int NI>
std::vector<double> data_limit_sigmas(const sim::Scenario& s, std::uint64_t seed) {
  using Run = CalibrationRun<M, 0, NI>;
  const sim::SimData noisy = sim::simulate(s, seed);
  typename Run::State x0;
  typename Run::Filter::Covariance p0;
  initialise(sim::simulation_prior<M>(s, noisy, seed), x0, p0);
  sim::Scenario clean = s;  // the same rig, motion and true biases; no noise, no bias walk
  clean.pixel_sigma = 0.0;
  clean.imu.gyro_noise_density = clean.imu.accel_noise_density = 0.0;
  clean.imu.gyro_random_walk = clean.imu.accel_random_walk = 0.0;
  const sim::SimData data = sim::simulate(clean, seed);
  typename Run::State start = truth_state<typename Run::State>(s);
  const sim::Kinematics k = sim::kinematics(s.motion, 0.0);
  start.p = k.p;
  start.v = k.v;
  start.q_n_b = k.q_n_b;
  start.b_a = data.b_a0;
  start.b_g = data.b_g0;
  // What the data hold is of their true noise, whatever noise the user stated (told_imu).
  CalibrationConfig config = scenario_config(s);
  config.imu = s.imu;
  config.pixel_sigma = s.pixel_sigma;
  const Run run = run_single_pass<M, 0, NI>(config, start, p0, loop_data(s, data), nullptr);
  std::vector<double> sigma;
  for (int i = Run::State::kCalibrationBegin; i < Run::State::kDim; ++i)
    sigma.push_back(std::sqrt(run.covariance(i, i)));
  return sigma;
}

template <int M, int NK, int NI>
CalibrationRun<M, NK, NI> run_two_stage_simulation(const sim::Scenario& s, std::uint64_t seed,
                                                   const std::function<void(double)>& progress) {
  const auto half = [&](double offset) {
    return [&progress, offset](double f) {
      if (progress) progress(offset + 0.5 * f);
    };
  };
  const CalibrationRun<M, 0, NI> stage1 = run_simulation<M, NI>(s, seed, half(0.0));

  using Run = CalibrationRun<M, NK, NI>;
  using State = typename Run::State;
  const std::uint64_t seed2 = sim::derive_seed(seed, sim::kStage2SeedStream);
  const sim::SimData data = sim::simulate(s, seed2);
  const Prior<M> prior = sim::simulation_prior<M>(s, data, seed2);
  State x0;
  typename Run::Filter::Covariance p0;
  initialise(prior, x0, p0);
  // Stage 1's calibration parameters, estimate and covariance, in place of the prior's guesses.
  const io::CalibrationStart start = calibration_start(stage1.result);
  start_from(start, x0, p0);
  const State truth = truth_state<State>(s);
  Run run = run_loop<M, NK, NI>(scenario_config(s), x0, p0, loop_data(s, data), &truth, half(0.5));
  note_start(start, run.result);
  run.markers_out_of_image = stage1.markers_out_of_image + data.markers_out_of_image;
  return run;
}

template <int M, int NK, int NI>
CalibrationRun<M, NK, NI> run_one_stage_simulation(const sim::Scenario& s, std::uint64_t seed,
                                                   const std::function<void(double)>& progress) {
  using Run = CalibrationRun<M, NK, NI>;
  const sim::SimData data = sim::simulate(s, seed);
  typename Run::State x0;
  typename Run::Filter::Covariance p0;
  initialise(sim::simulation_prior<M>(s, data, seed), x0, p0);
  const typename Run::State truth = truth_state<typename Run::State>(s);
  Run run = run_loop<M, NK, NI>(scenario_config(s), x0, p0, loop_data(s, data), &truth, progress);
  run.markers_out_of_image = data.markers_out_of_image;
  return run;
}

#define MIRRORCAL_SIMULATION_(M, NI)        \
  template MIRRORCAL_RUN_SIMULATION(M, NI); \
  template std::vector<double> data_limit_sigmas<M, NI>(const sim::Scenario&, std::uint64_t);
MIRRORCAL_FOR_EACH_STAGE1_FILTER(MIRRORCAL_SIMULATION_)
#undef MIRRORCAL_SIMULATION_
#define MIRRORCAL_STAGED_SIMULATIONS_(M, NK, NI)                             \
  template MIRRORCAL_STAGED_SIMULATION(run_two_stage_simulation, M, NK, NI); \
  template MIRRORCAL_STAGED_SIMULATION(run_one_stage_simulation, M, NK, NI);
MIRRORCAL_FOR_EACH_STAGE2_FILTER(MIRRORCAL_STAGED_SIMULATIONS_)
#undef MIRRORCAL_STAGED_SIMULATIONS_

}  // namespace mirrorcal::evaluation
