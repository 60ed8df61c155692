// mirrorcal record of the simulated rig: its streams and priors as a EuRoC recording (which
// `mirrorcal calibrate` replays bit-identically to `mirrorcal sim` with the same seed), or with
// --bag as a ROS 2 bag of its IMU messages and images. Host only: the board's program has no
// simulator.
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "mirrorcal/io/bags.hpp"
#include "mirrorcal/io/recording.hpp"
#include "mirrorcal/sim/frame_renderer.hpp"
#include "mirrorcal/sim/simulator.hpp"
#include "record.hpp"
#include "sim_options.hpp"

namespace mirrorcal::app {

namespace {

// Draws frame j's markers into pixels as the renderer of sim --frames does.
void render_frame(sim::FrameRenderer& renderer, const sim::RenderConfig& render,
                  const io::ObservedFrame& f, std::uint64_t j, std::uint8_t* pixels) {
  for (const io::ObservedMarker& m : f.markers)
    renderer.add_spot(m.u, m.v, render.brightness[std::size_t(m.id) % render.brightness.size()]);
  renderer.finish(j, pixels);
}

// How the simulated camera's frames are recorded: their markers in features.csv, with their images
// too, or as a bag of images; the LEDs drawn with the brightness code or all alike.
struct FrameOutput {
  bool images = false, bag = false;
  sim::RenderConfig render;
};

// The simulated streams into dir as a EuRoC recording (mav0/: the IMU's samples, the frames'
// markers in features.csv, with images their PNGs too).
bool write_simulated_streams(const sim::Scenario& s, std::uint64_t seed, const sim::SimData& data,
                             const std::string& dir, const FrameOutput& out, std::string& err) {
  io::RecordingWriter writer;
  if (!writer.open(dir, err)) return false;
  for (const ImuSample& smp : data.imu)
    if (!writer.add_imu(smp)) break;
  const bool images = out.images;
  const sim::RenderConfig& render = out.render;
  sim::FrameRenderer renderer(s, render, sim::derive_seed(seed, 200));
  std::vector<std::uint8_t> pixels(
      images ? std::size_t(renderer.width()) * std::size_t(renderer.height()) : 0);
  const io::GrayImage image{renderer.width(), renderer.height(), pixels.data()};
  std::uint64_t j = 0;
  for (const io::ObservedFrame& f : data.frames) {
    if (images) render_frame(renderer, render, f, j++, pixels.data());
    if (!writer.add_frame(f, images ? &image : nullptr)) break;
  }
  return writer.close(err);
}

// The same as a ROS 2 bag folder (io::BagWriter): the IMU's samples and the frames' images (the
// very images of --images, raw mono8) in the order of their stamps, as a recorder receives them,
// on the topics the yaml files name; the bag's file is named after name (the user's folder).
bool write_simulated_bag(const sim::Scenario& s, std::uint64_t seed, const sim::SimData& data,
                         const io::SensorInfo& sensors, const std::string& dir,
                         const std::string& name, const sim::RenderConfig& render,
                         std::string& err) {
#ifdef MIRRORCAL_BAGS
  io::BagWriter writer;
  if (!writer.open(dir, name, sensors.imu_rostopic, sensors.rostopic, err)) return false;
  sim::FrameRenderer renderer(s, render, sim::derive_seed(seed, 200));
  std::vector<std::uint8_t> pixels(std::size_t(renderer.width()) * std::size_t(renderer.height()));
  const io::GrayImage image{renderer.width(), renderer.height(), pixels.data()};
  std::size_t i = 0;
  std::uint64_t j = 0;
  bool ok = true;
  for (const io::ObservedFrame& f : data.frames) {
    for (; ok && i < data.imu.size() && data.imu[i].t_ns <= f.t_ns; ++i)
      ok = writer.add_imu(data.imu[i]);
    render_frame(renderer, render, f, j++, pixels.data());
    ok = ok && writer.add_image(f.t_ns, image);
  }
  for (; ok && i < data.imu.size(); ++i) ok = writer.add_imu(data.imu[i]);
  return writer.close(err);
#else
  (void)s, (void)seed, (void)data, (void)sensors, (void)dir, (void)name, (void)render;
  err =
      "--bag: this build of mirrorcal (a board's) writes recording folders only; record the bag "
      "with the host's build";
  return false;
#endif
}

// The simulated rig's streams of one run (data and prior from seed) and its priors, as `sim` with
// that seed hands them to the loop, and its truth, into dir.
// dir lies within folder's temporary folder; failures name the folder the user asked for.
// With images, each frame's image is drawn too (the renderer of sim --frames, GREY): a spot for
// each marker of features.csv at the very pixel listed there (its pixel noise included), so the
// images hold the same data as features.csv and a calibration from either sees the same.
// With lens (estimate_distortion, with intrinsics and skew held), camchain.yaml holds the prior's
// guess of the lens's coefficients, as `sim --estimate-distortion` starts from, and truth.yaml the
// true ones. With bag, the streams are a ROS 2 bag (write_simulated_bag). False, with the error,
// when a file cannot be written.
template <int M>
bool write_simulated_recording(const sim::Scenario& s, std::uint64_t seed, bool intrinsics,
                               bool hold_skew, bool lens, const io::StagedFolder& folder,
                               const std::string& sub, std::string& err, const FrameOutput& out) {
  const bool bag = out.bag;
  const std::string dir = folder.path() + sub;
  const sim::SimData data = sim::simulate(s, seed);
  const Prior<M> prior = sim::simulation_prior<M>(s, data, seed);

  io::SensorInfo sensors;
  sensors.imu = s.told_imu.value_or(s.imu);  // what imu.yaml says (the mems family's told noise)
  sensors.imu_rate_hz = s.imu_rate_hz;
  // The datasheet's tolerances the scenario states, which sim's ideal-IMU check uses too.
  sensors.imu_tolerances = s.priors.imu_intrinsics;
  sensors.imu_tolerances_defaulted = false;
  sensors.imu_model = simulated_imu_model(s);  // the model of the IMU simulated
  sensors.intrinsics = s.truth.intrinsics;     // stage 1 calibrates with a calibrated camera
  if (lens) sensors.intrinsics.coeffs = prior.intrinsics.coeffs;
  sensors.width = s.truth.width;
  sensors.height = s.truth.height;
  // intrinsics: calibrate estimates them too, from the prior's guess (the paper's Table III
  // errors) rather than camchain.yaml's calibrated camera.
  io::RecordingPriors priors =
      io::from_prior(prior, s.gravity_n, s.told_pixel_sigma.value_or(s.pixel_sigma), intrinsics,
                     hold_skew || lens);
  priors.estimate_distortion = lens;
  if (out.render.brightness.size() == 1)  // identical LEDs: mirrorcal.yaml says so
    priors.leds.brightness.assign(std::size_t(M), out.render.brightness.front());
  const io::RecordingTruth truth = sim::recording_truth(s, lens);
  const std::string target = folder.as_target(dir);
  const std::string name = std::filesystem::path(target).lexically_normal().filename().string();
  if (!(bag ? write_simulated_bag(s, seed, data, sensors, dir, name, out.render, err)
            : write_simulated_streams(s, seed, data, dir, out, err)) ||
      !io::write_sensor_yaml(dir, sensors, err) || !io::write_priors_yaml(dir, priors, err) ||
      !io::write_truth_yaml(dir, truth, err))
    return false;
  const std::string streams =
      bag ? "metadata.yaml, " + name + "_0.mcap (a ROS 2 bag: " + sensors.imu_rostopic + ", " +
                sensors.rostopic + " mono8),"
          : std::string("mav0/imu0/data.csv, mav0/cam0/data.csv, mav0/cam0/features.csv,") +
                (out.images ? " mav0/cam0/data/*.png," : "");
  std::printf(
      "mirrorcal record: scenario '%s', seed %llu: %zu IMU samples, %zu frames (%.0f s) in %s\n"
      "  %s imu.yaml, camchain.yaml, mirrorcal.yaml, truth.yaml\n",
      s.name.c_str(), static_cast<unsigned long long>(seed), data.imu.size(), data.frames.size(),
      s.duration_s, target.c_str(), streams.c_str());
  return true;
}

}  // namespace

int record_simulated(const Options& o, const std::string& dir) {
  std::string error;
  const bool bag = o.flag("bag");
  if (bag && o.flag("images")) return refuse("--bag holds the images already; drop --images");
  FrameOutput out;
  out.images = o.flag("images");
  out.bag = bag;
  if (o.flag("identical-leds")) {
    if (!out.images && !bag)
      return refuse("--identical-leds draws the images: give --images or --bag");
    out.render.brightness = {out.render.brightness[1]};  // as sim --frames --identical-leds
  }
  const bool two_stage = o.flag("two-stage"), hold_skew = o.flag("hold-skew");
  if (hold_skew && !o.flag("intrinsics") && !two_stage)
    return refuse("--hold-skew applies with --intrinsics or --two-stage");
  if (two_stage && o.flag("intrinsics"))
    return refuse(
        "--two-stage records stage 1 without and stage 2 with the intrinsics; drop --intrinsics");
  // --estimate-distortion: the recording (stage 2's) asks calibrate to estimate the lens's
  // coefficients too (mirrorcal.yaml's estimate_distortion), skew held as with --hold-skew.
  const bool lens = o.flag("estimate-distortion");
  if (lens && ((!o.flag("intrinsics") && !two_stage) || o.get("distortion", "none") == "none"))
    return refuse(
        "--estimate-distortion applies with --intrinsics or --two-stage and --distortion "
        "radtan|equidistant");
  // --hold-skew: a camera without skew, whose recording asks calibrate to hold it at zero.
  std::uint64_t seed = 0;
  sim::Scenario s;
  if (!parse_count(o, "seed", 1, 0, seed, error) || !scenario_option(o, seed, s, error))
    return refuse(error);
  if (hold_skew) s = sim::without_skew(s);
  return with_markers(int(s.truth.markers.size()), [&](auto markers) {
    constexpr int M = decltype(markers)::value;
    io::StagedFolder folder;
    if (!folder.begin(dir, o.flag("force"), error)) return refuse(error, 1);
    if (!two_stage) {
      if (!write_simulated_recording<M>(s, seed, o.flag("intrinsics"), hold_skew, lens, folder, "",
                                        error, out) ||
          !folder.commit(error))
        return refuse_recording(folder, error);
      return 0;
    }
    // The two minutes `sim --intrinsics` calibrates (run_two_stage_simulation's seeds), committed
    // together.
    const std::string stage1 = dir + "/stage1", stage2 = dir + "/stage2";
    if (!write_simulated_recording<M>(s, seed, false, false, false, folder, "/stage1", error,
                                      out) ||
        !write_simulated_recording<M>(s, sim::derive_seed(seed, sim::kStage2SeedStream), true,
                                      hold_skew, lens, folder, "/stage2", error, out) ||
        !folder.commit(error))
      return refuse_recording(folder, error);
    std::printf(
        "calibrate them as `sim --intrinsics%s%s%s%s --seed %llu` does (the same bytes):\n"
        "  mirrorcal calibrate %s --out OUT1\n  mirrorcal calibrate %s --from OUT1 --out OUT2\n",
        hold_skew ? " --hold-skew" : "", o.flag("distortion") ? " --distortion " : "",
        o.flag("distortion") ? o.get("distortion", "").c_str() : "",
        lens ? " --estimate-distortion" : "", static_cast<unsigned long long>(seed), stage1.c_str(),
        stage2.c_str());
    return 0;
  });
}

}  // namespace mirrorcal::app
