// mirrorcal record: a EuRoC recording, with --imu of the board's devices (the IMU's samples and the
// markers detected in the camera's frames, labelled by their brightness), else of the simulated
// rig (record_simulated.cpp, the host's build), through the same writer.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "cli.hpp"
#include "devices.hpp"
#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/io/bags.hpp"
#include "mirrorcal/io/files.hpp"
#include "mirrorcal/io/recording.hpp"
#include "record.hpp"

namespace mirrorcal::app {

using namespace calibration;

namespace {

// The camera's last frame as the image beside its markers: its luma copied into luma (sized for
// the camera's frames) and grey pointing at it; nullptr for a frame larger than that.
const io::GrayImage* frame_image(const hal::FrameView& view, std::vector<std::uint8_t>& luma,
                                 io::GrayImage& grey) {
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
RecordEnd record_streams(const Devices& devices, hal::ImuSource& imu, io::RecordingWriter& writer,
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
      const io::GrayImage* image = nullptr;
      io::GrayImage grey;
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
  io::Recording sensors;
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
  if (s.sensors.empty() && !parse_count(o, "markers", kDefaultMarkerCount, 1, markers, error, 64))
    return refuse(error);
  if (!marker_count_built(int(markers))) return refuse(marker_count_not_built(int(markers)));
  Devices devices;
  int exit_code = 1;
  if (!open_devices(s, int(markers), sensors.priors.leds, sensors.sensors.width,
                    sensors.sensors.height, imu_rate_hz, devices, error, exit_code))
    return refuse(error, exit_code);
  io::StagedFolder folder;
  if (!folder.begin(dir, o.flag("force"), error)) return refuse(error, 1);

  std::string err;
  io::RecordingWriter writer;
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
      if (!io::read_file(s.sensors + "/" + f, text, err) ||
          !io::write_file(folder.path() + "/" + f, text, err))
        return refuse_recording(folder, err);
  }
  if (!folder.commit(err)) return refuse_recording(folder, err);
  std::printf("wrote %s/mav0%s\n", dir.c_str(),
              s.sensors.empty() ? "" : " and the sensor files of --sensors");
  return 0;
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
  return record_simulated(o, dir);
}

}  // namespace mirrorcal::app
