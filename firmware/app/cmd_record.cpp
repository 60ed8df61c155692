// mirrorcal record: the simulated rig's streams and priors, written as a EuRoC recording that
// `mirrorcal calibrate` replays bit-identically to `mirrorcal sim` with the same seed.
#include <cstdio>
#include <string>

#include "cli.hpp"
#include "mirrorcal/sim_host/recording.hpp"
#include "sim_run.hpp"

namespace mirrorcal::app {

int cmd_record(int argc, char** argv) {
  const Options o = parse(argc, argv, 2, {"scenario", "seed", "out"}, {"intrinsics"});
  if (!o.flag("out")) fail("record needs --out DIR\n" + usage());
  const sim::Scenario s = scenario_option(o);
  const std::uint64_t seed = parse_count(o, "seed", 1, 0);
  const std::string dir = make_out_dir(o, "");

  // Exactly what `sim` with this seed hands to the loop, and the prior it starts from.
  const sim::SimData data = sim::simulate(s, seed);
  const Prior<kMarkers> prior = simulation_prior(s, data, seed);

  std::string err;
  sim::RecordingWriter writer;
  if (!writer.open(dir, err)) fail(err, 1);
  for (const ImuSample& smp : data.imu)
    if (!writer.add_imu(smp)) break;
  for (const sim::ObservedFrame& f : data.frames)
    if (!writer.add_frame(f)) break;
  if (!writer.close(err)) fail(err, 1);

  sim::SensorInfo sensors;
  sensors.imu = s.imu;
  sensors.imu_rate_hz = s.imu_rate_hz;
  sensors.intrinsics = s.truth.intrinsics;  // stage 1 calibrates with a calibrated camera
  sensors.width = s.truth.width;
  sensors.height = s.truth.height;
  // --intrinsics: calibrate estimates the intrinsics too, from the prior's guess (the paper's
  // Table III errors) rather than camchain.yaml's calibrated camera.
  const sim::RecordingPriors priors =
      sim::from_prior(prior, s.gravity_n, s.pixel_sigma, o.flag("intrinsics"));
  sim::RecordingTruth truth;
  truth.p_b_c = s.truth.p_b_c;
  truth.q_b_c = s.truth.q_b_c;
  truth.features_c = s.truth.markers;
  truth.intrinsics = s.truth.intrinsics;
  if (!sim::write_sensor_yaml(dir, sensors, err) || !sim::write_priors_yaml(dir, priors, err) ||
      !sim::write_truth_yaml(dir, truth, err))
    fail(err, 1);
  std::printf(
      "mirrorcal record: scenario '%s', seed %llu: %zu IMU samples, %zu frames (%.0f s) in %s\n"
      "  mav0/imu0/data.csv, mav0/cam0/data.csv, mav0/cam0/features.csv, imu.yaml, "
      "camchain.yaml, mirrorcal.yaml, truth.yaml\n",
      s.name.c_str(), static_cast<unsigned long long>(seed), data.imu.size(), data.frames.size(),
      s.duration_s, dir.c_str());
  return 0;
}

}  // namespace mirrorcal::app
