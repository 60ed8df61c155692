// mirrorcal record: a EuRoC recording, either of the simulated rig's streams and priors (which
// `mirrorcal calibrate` replays bit-identically to `mirrorcal sim` with the same seed; with --bag
// as a ROS 2 bag of its IMU messages and images), or, with --imu, of the board's devices (the
// IMU's samples and the markers detected in the camera's frames, labelled by their brightness)
// through the same writer.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "cli.hpp"
#include "devices.hpp"
#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/sim_host/bags.hpp"
#include "mirrorcal/sim_host/files.hpp"
#include "mirrorcal/sim_host/frame_renderer.hpp"
#include "mirrorcal/sim_host/recording.hpp"

namespace mirrorcal::app {

using namespace calibration;

namespace {

// A recording's folder is written whole or not at all, into the temporary folder of a
// files::StagedFolder that replaces it when committed. An error returned before then leaves
// nothing: the StagedFolder removes its temporary folder as it goes out of scope, after the writer
// declared after it has closed its files. refuse_recording refuses err, about a file in folder,
// naming the file as the user will find it (exit code 1).
int refuse_recording(const files::StagedFolder& folder, const std::string& err) {
  return refuse(folder.as_target(err), 1);
}

// The camera's last frame as the image beside its markers: its luma copied into luma (sized for
// the camera's frames) and grey pointing at it; nullptr for a frame larger than that.
const sim::GrayImage* frame_image(const hal::FrameView& view, std::vector<std::uint8_t>& luma,
                                  sim::GrayImage& grey) {
  grey = {view.width, view.height, luma.data()};
  if (std::size_t(view.width) * std::size_t(view.height) > luma.size()) return nullptr;
  for (int y = 0; y < view.height; ++y)
    for (int x = 0; x < view.width; ++x)
      luma[std::size_t(y) * std::size_t(view.width) + std::size_t(x)] = view.luma(x, y);
  return &grey;
}

// How recording the devices' streams ended, and the frames written.
struct RecordEnd {
  hal::SourceStatus imu_status = hal::SourceStatus::kOk;
  hal::SourceStatus frame_status = hal::SourceStatus::kNotReady;
  std::string camera_error;  // with frame_status kError
  std::uint64_t frames = 0;
};

// The IMU's samples into writer, each followed by the camera's frames that came meanwhile (with
// their images when asked: luma is their buffer), until the IMU stream ends (its duration, a
// signal) or fails, the writer refuses, or the camera fails.
template <int M>
RecordEnd record_streams(const Devices& devices, hal::ImuSource& imu, sim::RecordingWriter& writer,
                         bool images, std::vector<std::uint8_t>& luma) {
  RecordEnd end;
  StopOnSignal stop_on_signal;
  ImuSample sample;
  MarkerFrame<M> frame{};
  while ((end.imu_status = imu.next(sample)) == hal::SourceStatus::kOk) {
    if (!writer.add_imu(sample)) break;
    // The frames that came meanwhile, in their order (the camera's clock is the IMU's).
    while (devices.camera && (end.frame_status = devices.camera->markers<M>().poll(frame)) ==
                                 hal::SourceStatus::kOk) {
      const sim::GrayImage* image = nullptr;
      sim::GrayImage grey;
      if (images) image = frame_image(devices.camera->markers<M>().last_frame(), luma, grey);
      if (!writer.add_frame(frame, image)) break;
      ++end.frames;
    }
    if (end.frame_status == hal::SourceStatus::kError) {
      end.camera_error = devices.camera->markers<M>().error();
      break;
    }
  }
  return end;
}

void print_record_start(const RunSettings& s, const Devices& devices, double imu_rate_hz,
                        const std::string& dir) {
  std::printf("mirrorcal record: IMU %s, %s%s; %s into %s\n", s.imu.c_str(),
              describe_camera(s, devices).c_str(),
              describe_trigger(s, devices, imu_rate_hz).c_str(),
              s.duration_s > 0 ? ("for " + std::to_string(s.duration_s) + " s").c_str()
                               : "until Ctrl-C or the IMU stops",
              dir.c_str());
  std::fflush(stdout);
}

// The board's devices into dir until --duration or Ctrl-C. With --sensors, its imu.yaml,
// camchain.yaml and mirrorcal.yaml are copied beside the streams (the camera's size is
// camchain.yaml's), so `mirrorcal calibrate DIR` takes the recording as it is; else the camera
// streams 640x480.
int record_devices(const Options& o, const std::string& dir) {
  RunSettings s;
  sim::Recording sensors;
  std::string error;
  if (!device_settings(o, "record", false, s, error) ||
      (!s.sensors.empty() && !read_sensors(s.sensors, sensors, error)))
    return refuse(error, 2);
  const double imu_rate_hz = s.sensors.empty() ? s.rate_hz : sensors.sensors.imu_rate_hz;
  // The markers the camera's frames are searched for: as many as --sensors' mirrorcal.yaml lists,
  // else --markers (three by default).
  std::uint64_t markers = sensors.priors.features_c.size();
  if (!s.sensors.empty() && o.flag("markers"))
    return refuse("--markers applies without --sensors (its mirrorcal.yaml lists the markers)");
  if (s.sensors.empty() && !parse_count(o, "markers", sim::kPaperMarkers, 1, markers, error, 64))
    return refuse(error);
  if (!marker_count_built(int(markers))) return refuse(marker_count_not_built(int(markers)));
  Devices devices;
  int exit_code = 1;
  if (!open_devices(s, int(markers), sensors.priors.leds, sensors.sensors.width,
                    sensors.sensors.height, imu_rate_hz, devices, error, exit_code))
    return refuse(error, exit_code);
  files::StagedFolder folder;
  if (!folder.begin(dir, o.flag("force"), error)) return refuse(error, 1);

  std::string err;
  sim::RecordingWriter writer;
  if (!writer.open(folder.path(), err)) return refuse_recording(folder, err);
  // --images: each frame's luma too, as PNG in mav0/cam0/data/ (a buffer allocated here; the
  // writer allocates its PNG buffers with the first image).
  const bool images = o.flag("images");
  if (images && !devices.camera) return refuse("--images needs a camera (--camera DEV)");
  std::vector<std::uint8_t> luma(
      images ? std::size_t(sensors.sensors.width) * std::size_t(sensors.sensors.height) : 0);
  print_record_start(s, devices, imu_rate_hz, dir);
  StoppingImu imu(devices.imu_stream(), static_cast<std::int64_t>(s.duration_s * 1e9));
  RecordEnd end;
  const int status = with_markers(int(markers), [&](auto count) {
    end = record_streams<decltype(count)::value>(devices, imu, writer, images, luma);
    return 0;
  });
  if (status != 0) return status;
  StopOnSignal::report("closing the recording");
  const bool written = writer.close(err);
  std::printf("record: %llu IMU samples over %.3f s, %llu frames\n",
              static_cast<unsigned long long>(imu.samples()), imu.seconds(),
              static_cast<unsigned long long>(end.frames));
  print_device_counters(devices);
  if (!written) return refuse_recording(folder, err);
  if (end.imu_status == hal::SourceStatus::kError) return refuse_recording(folder, imu.error());
  if (end.frame_status == hal::SourceStatus::kError)
    return refuse_recording(folder, end.camera_error);
  if (!s.sensors.empty()) {
    std::string text;
    for (const char* f : {"imu.yaml", "camchain.yaml", "mirrorcal.yaml"})
      if (!files::read_file(s.sensors + "/" + f, text, err) ||
          !files::write_file(folder.path() + "/" + f, text, err))
        return refuse_recording(folder, err);
  }
  if (!folder.commit(err)) return refuse_recording(folder, err);
  std::printf("wrote %s/mav0%s\n", dir.c_str(),
              s.sensors.empty() ? "" : " and the sensor files of --sensors");
  return 0;
}

// Draws frame j's markers into pixels as the renderer of sim --frames does.
void render_frame(sim::FrameRenderer& renderer, const sim::RenderConfig& render,
                  const sim::ObservedFrame& f, std::uint64_t j, std::uint8_t* pixels) {
  for (const sim::ObservedMarker& m : f.markers)
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
  sim::RecordingWriter writer;
  if (!writer.open(dir, err)) return false;
  for (const ImuSample& smp : data.imu)
    if (!writer.add_imu(smp)) break;
  const bool images = out.images;
  const sim::RenderConfig& render = out.render;
  sim::FrameRenderer renderer(s, render, sim::derive_seed(seed, 200));
  std::vector<std::uint8_t> pixels(
      images ? std::size_t(renderer.width()) * std::size_t(renderer.height()) : 0);
  const sim::GrayImage image{renderer.width(), renderer.height(), pixels.data()};
  std::uint64_t j = 0;
  for (const sim::ObservedFrame& f : data.frames) {
    if (images) render_frame(renderer, render, f, j++, pixels.data());
    if (!writer.add_frame(f, images ? &image : nullptr)) break;
  }
  return writer.close(err);
}

// The same as a ROS 2 bag folder (sim::BagWriter): the IMU's samples and the frames' images (the
// very images of --images, raw mono8) in the order of their stamps, as a recorder receives them,
// on the topics the yaml files name; the bag's file is named after name (the user's folder).
bool write_simulated_bag(const sim::Scenario& s, std::uint64_t seed, const sim::SimData& data,
                         const sim::SensorInfo& sensors, const std::string& dir,
                         const std::string& name, const sim::RenderConfig& render,
                         std::string& err) {
#ifdef MIRRORCAL_BAGS
  sim::BagWriter writer;
  if (!writer.open(dir, name, sensors.imu_rostopic, sensors.rostopic, err)) return false;
  sim::FrameRenderer renderer(s, render, sim::derive_seed(seed, 200));
  std::vector<std::uint8_t> pixels(std::size_t(renderer.width()) * std::size_t(renderer.height()));
  const sim::GrayImage image{renderer.width(), renderer.height(), pixels.data()};
  std::size_t i = 0;
  std::uint64_t j = 0;
  bool ok = true;
  for (const sim::ObservedFrame& f : data.frames) {
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
                               bool hold_skew, bool lens, const files::StagedFolder& folder,
                               const std::string& sub, std::string& err, const FrameOutput& out) {
  const bool bag = out.bag;
  const std::string dir = folder.path() + sub;
  const sim::SimData data = sim::simulate(s, seed);
  const Prior<M> prior = sim::simulation_prior<M>(s, data, seed);

  sim::SensorInfo sensors;
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
  sim::RecordingPriors priors =
      sim::from_prior(prior, s.gravity_n, s.told_pixel_sigma.value_or(s.pixel_sigma), intrinsics,
                      hold_skew || lens);
  priors.estimate_distortion = lens;
  if (out.render.brightness.size() == 1)  // identical LEDs: mirrorcal.yaml says so
    priors.leds.brightness.assign(std::size_t(M), out.render.brightness.front());
  const sim::RecordingTruth truth = sim::recording_truth(s, lens);
  const std::string target = folder.as_target(dir);
  const std::string name = std::filesystem::path(target).lexically_normal().filename().string();
  if (!(bag ? write_simulated_bag(s, seed, data, sensors, dir, name, out.render, err)
            : write_simulated_streams(s, seed, data, dir, out, err)) ||
      !sim::write_sensor_yaml(dir, sensors, err) || !sim::write_priors_yaml(dir, priors, err) ||
      !sim::write_truth_yaml(dir, truth, err))
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

int cmd_record(int argc, char** argv) {
  std::vector<std::string> with_value = {"scenario",  "seed",       "out",        "config",
                                         "timeshift", "distortion", "line-delay", "markers",
                                         "outliers",  "label-swaps"};
  for (const char* key : kRunKeys)
    if (std::string(key) != "out") with_value.emplace_back(key);
  Options o;
  std::string error;
  if (!parse(argc, argv, 2, with_value,
             {"intrinsics", "hold-skew", "two-stage", "force", "images", "estimate-distortion",
              "bag", "identical-leds"},
             o, error))
    return refuse(error);
  if (!o.flag("out")) return refuse("record needs --out DIR\n" + usage("record"));
  const std::string dir = o.get("out", "");
  if (o.flag("imu") || o.flag("config")) {
    if (o.flag("bag"))
      return refuse("--bag records the simulated rig; the board's devices record a folder");
    return record_devices(o, dir);
  }
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
    files::StagedFolder folder;
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
