// mirrorcal run: the calibration loop on the board's own devices. The IMU comes from a driver
// (spidev, i2c-dev or SocketCAN, optionally paced by a GPIO data-ready line); the marker stream
// from a V4L2 camera whose frames go through the board's marker detection, identified with the
// filter's prediction at each frame's time (without --camera a run is IMU-only: the filter
// propagates and the result is the prior, carried through the motion).
#include <signal.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include "cli.hpp"
#include "loop_options.hpp"
#include "mirrorcal/drivers/can_imu.hpp"
#include "mirrorcal/drivers/detecting_marker_source.hpp"
#include "mirrorcal/drivers/device_spec.hpp"
#include "mirrorcal/drivers/gpio_lines.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/drivers/open_imu.hpp"
#include "mirrorcal/drivers/register_imu.hpp"
#include "mirrorcal/drivers/v4l2.hpp"
#include "mirrorcal/firmware/loop.hpp"
#include "mirrorcal/sim_host/recording.hpp"
#include "outputs.hpp"
#include "recording_run.hpp"
#include "run_config.hpp"

namespace mirrorcal::app {

namespace {

// No camera: the marker stream is empty from the start.
class NoMarkers final : public hal::MarkerSource<kMarkers> {
 public:
  hal::SourceStatus poll(MarkerFrame<kMarkers>&) override {
    return hal::SourceStatus::kEndOfStream;
  }
};

// The camera: V4L2 capture of the size camchain.yaml gives, and the markers detected in its
// frames (blobs, labelled by the filter's prediction once the loop relabels them, with the
// markers' brightness ratios 1 : 1.5 : 2.25 as the second cue).
struct Camera {
  drivers::V4l2Capture capture;
  std::unique_ptr<drivers::DetectingMarkerSource<kMarkers>> markers;
};

// Frame buffers the camera gets: a few frames of slack while the loop is busy with an update.
constexpr int kCameraBuffers = 8;

// Opens and starts the camera (nullptr without --camera); throws DriverError naming the device.
std::unique_ptr<Camera> open_camera(const RunSettings& s, int width, int height) {
  if (s.camera.empty()) return nullptr;
  const drivers::CameraSpec spec = drivers::parse_camera_spec(s.camera);
  auto camera = std::make_unique<Camera>();
  drivers::V4l2Config config;
  config.format = spec.format;
  config.format_from_device = !spec.format_given;
  config.width = width;
  config.height = height;
  config.buffers = kCameraBuffers;
  if (!camera->capture.open(spec.device, config) || !camera->capture.start())
    throw drivers::DriverError(drivers::Fault::kWrongKind, camera->capture.error());
  camera->markers = std::make_unique<drivers::DetectingMarkerSource<kMarkers>>(
      camera->capture, drivers::DetectionConfig<kMarkers>{}, width, height);
  return camera;
}

void print_camera_counters(const Camera& camera) {
  const hal::FrameCounters f = camera.capture.counters();
  const drivers::DetectionCounters& d = camera.markers->counters();
  const drivers::IdentifierCounters id = camera.markers->identifier_counters();
  std::printf(
      "camera: %llu frames, %llu dropped, %llu corrupt (skipped), %llu restarts; timestamps %s, "
      "%s\n",
      static_cast<unsigned long long>(f.frames), static_cast<unsigned long long>(f.dropped),
      static_cast<unsigned long long>(f.corrupt), static_cast<unsigned long long>(f.restarts),
      camera.capture.timestamps_monotonic() ? "CLOCK_MONOTONIC" : "NOT CLOCK_MONOTONIC (unusable)",
      camera.capture.start_of_exposure() ? "start of exposure" : "end of frame");
  std::printf(
      "markers: %llu labelled, %llu in doubt, %llu crossing, %llu blobs refused, %llu blobs "
      "unassigned; detection %.2f ms per frame\n",
      static_cast<unsigned long long>(id.identified), static_cast<unsigned long long>(id.ambiguous),
      static_cast<unsigned long long>(id.crossing), static_cast<unsigned long long>(id.refused),
      static_cast<unsigned long long>(id.unassigned),
      d.frames > 0 ? 1e3 * d.detect_seconds / static_cast<double>(d.frames) : 0.0);
}

// The signal (SIGINT, SIGTERM) that asked the run to stop, 0 while none has. The handler only
// stores it; the IMU source below looks at it at every sample, so the loop stops at the next one.
std::atomic<int> g_stop_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the signal handler needs a lock-free flag");

extern "C" void request_stop(int signal) {
  g_stop_signal.store(signal, std::memory_order_relaxed);
}

// SIGINT and SIGTERM stop the run (without SA_RESTART, so a blocking wait returns early) while
// this object lives; the previous handlers come back after it.
class StopOnSignal {
 public:
  StopOnSignal() {
    struct sigaction sa {};
    sa.sa_handler = request_stop;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &old_int_);
    sigaction(SIGTERM, &sa, &old_term_);
  }
  ~StopOnSignal() {
    sigaction(SIGINT, &old_int_, nullptr);
    sigaction(SIGTERM, &old_term_, nullptr);
  }
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;

 private:
  struct sigaction old_int_ {
  }, old_term_{};
};

// Ends the device's stream after `duration_ns` of samples (0: never) or when a signal asks the
// run to stop, and counts the samples.
class LimitedImu final : public hal::ImuSource {
 public:
  LimitedImu(hal::ImuSource& device, std::int64_t duration_ns)
      : device_(device), duration_ns_(duration_ns) {}
  hal::SourceStatus next(ImuSample& s) override {
    if (g_stop_signal.load(std::memory_order_relaxed) != 0) return hal::SourceStatus::kEndOfStream;
    const hal::SourceStatus st = device_.next(s);
    // A device that timed out while the stop was asked for has not failed: the run was ending.
    if (g_stop_signal.load(std::memory_order_relaxed) != 0) return hal::SourceStatus::kEndOfStream;
    if (st != hal::SourceStatus::kOk) return st;
    if (samples_++ == 0) first_ns_ = s.t_ns;
    last_ns_ = s.t_ns;
    if (duration_ns_ > 0 && s.t_ns - first_ns_ > duration_ns_)
      return hal::SourceStatus::kEndOfStream;
    return st;
  }
  const char* error() const override { return device_.error(); }
  std::uint64_t samples() const { return samples_; }
  double seconds() const { return static_cast<double>(last_ns_ - first_ns_) * 1e-9; }

 private:
  hal::ImuSource& device_;
  std::int64_t duration_ns_;
  std::uint64_t samples_ = 0;
  std::int64_t first_ns_ = 0, last_ns_ = 0;
};

bool read_text(const std::string& path, std::string& text, std::string& error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    error = path + ": cannot read";
    return false;
  }
  std::ostringstream ss;
  ss << in.rdbuf();
  text = ss.str();
  return true;
}

// imu.yaml, camchain.yaml and mirrorcal.yaml of dir, as beside a recording.
void read_sensors(const std::string& dir, sim::Recording& r) {
  std::string text, error;
  const std::string imu = dir + "/imu.yaml", cam = dir + "/camchain.yaml",
                    priors = dir + "/mirrorcal.yaml";
  if (!read_text(imu, text, error) || !sim::parse_imu_yaml(text, imu, r.sensors, error) ||
      !read_text(cam, text, error) ||
      !sim::parse_camchain_yaml(text, cam, r.sensors, r.notes, error) ||
      !read_text(priors, text, error) ||
      !sim::parse_priors_yaml(text, priors, r.sensors.intrinsics, r.priors, r.notes, error))
    fail(error, 2);
}

RunSettings settings(const Options& o) {
  RunSettings s;
  std::string error;
  if (o.flag("config")) {
    const std::string file = o.get("config", "");
    std::string text;
    if (!read_text(file, text, error) || !parse_run_config(text, file, s, error)) fail(error, 2);
  }
  for (const char* key : kRunKeys)
    if (o.flag(key) && !set_run_setting(s, key, o.get(key, ""), error)) fail("--" + error, 2);
  if (s.imu.empty()) fail("run: no IMU given (--imu SPEC, or `imu:` in the --config file)", 2);
  if (s.sensors.empty())
    fail(
        "run: no sensor description given (--sensors DIR with imu.yaml, camchain.yaml and "
        "mirrorcal.yaml, as `mirrorcal record` writes them)",
        2);
  return s;
}

void print_driver_counters(const hal::ImuSource& imu) {
  if (const auto* can = dynamic_cast<const drivers::CanImu*>(&imu)) {
    const drivers::CanImuCounters& c = can->counters();
    std::printf(
        "CAN: %llu frames, %llu lost, %llu incomplete samples, %llu rejected, %llu error "
        "frames, %llu bus-off, %llu recoveries\n",
        static_cast<unsigned long long>(c.frames), static_cast<unsigned long long>(c.lost_frames()),
        static_cast<unsigned long long>(c.assembly.incomplete_samples),
        static_cast<unsigned long long>(c.rejected_frames),
        static_cast<unsigned long long>(c.error_frames), static_cast<unsigned long long>(c.bus_off),
        static_cast<unsigned long long>(c.recoveries));
  } else if (const auto* reg = dynamic_cast<const drivers::RegisterImu*>(&imu)) {
    const drivers::RegisterImuCounters& c = reg->counters();
    std::printf("IMU: %llu samples, %llu missed (data-ready), %llu read retries\n",
                static_cast<unsigned long long>(c.samples),
                static_cast<unsigned long long>(c.missed_samples),
                static_cast<unsigned long long>(c.read_retries));
  }
}

}  // namespace

int cmd_run(int argc, char** argv) {
  std::vector<std::string> with_value = {"config"};
  for (const char* key : kRunKeys) with_value.emplace_back(key);
  std::vector<std::string> flags;
  with_value.insert(with_value.end(), kLoopValueOptions.begin(), kLoopValueOptions.end());
  flags.insert(flags.end(), kLoopFlagOptions.begin(), kLoopFlagOptions.end());
  const Options o = parse(argc, argv, 2, with_value, flags);
  const RunSettings s = settings(o);

  sim::Recording sensors;
  read_sensors(s.sensors, sensors);
  Prior<kMarkers> prior;
  std::string error;
  if (!sim::to_prior(sensors.priors, prior, error))
    fail(s.sensors + "/mirrorcal.yaml: " + error, 2);

  // The devices; anything missing, busy or of the wrong kind ends the run here, with its reason.
  std::unique_ptr<drivers::GpioDataReady> drdy;
  std::unique_ptr<hal::ImuSource> device;
  std::unique_ptr<Camera> camera;
  try {
    camera = open_camera(s, sensors.sensors.width, sensors.sensors.height);
    const drivers::ImuSpec spec = drivers::parse_imu_spec(s.imu);
    if (!s.drdy.empty())
      drdy = std::make_unique<drivers::GpioDataReady>(drivers::parse_line_spec(s.drdy));
    drivers::RegisterImuConfig imu_config;
    imu_config.rate_hz = s.rate_hz;
    imu_config.gyro_range_dps = s.gyro_range_dps;
    imu_config.accel_range_g = s.accel_range_g;
    device = drivers::open_imu(spec, imu_config, drdy.get());
  } catch (const drivers::DriverError& e) {
    fail(e.what(), 1);
  }
  std::filesystem::create_directories(s.out);

  using Filter = CalibrationFilter<double, kMarkers, 0>;
  Filter filter(recording_config(sensors));
  Filter::State x0;
  Filter::Covariance p0;
  initialise(prior, x0, p0);
  filter.reset(x0, p0);
  LimitedImu imu(*device, static_cast<std::int64_t>(s.duration_s * 1e9));
  NoMarkers no_markers;
  hal::MarkerSource<kMarkers>& markers =
      camera ? static_cast<hal::MarkerSource<kMarkers>&>(*camera->markers) : no_markers;
  drivers::MonotonicClock clock;
  const std::int64_t imu_period = imu_period_ns(sensors.sensors.imu_rate_hz);
  // The frame path's budget: the camera's frame interval where the driver reports one, else 20 Hz.
  const std::int64_t frame_period = camera && camera->capture.frame_period_ns() > 0
                                        ? camera->capture.frame_period_ns()
                                        : 50'000'000;
  const auto profiler = make_profiler(o, clock, imu_period, frame_period);
  apply_realtime_options(o);
  firmware::LoopConfig lc;
  lc.imu_period_ns = imu_period;
  lc.profiler = profiler.get();
  firmware::CalibrationLoop<double, kMarkers, 0> loop(filter, imu, markers, lc);
  std::string camera_text = "no camera (IMU only)";
  if (camera) {
    const std::int64_t reported = camera->capture.frame_period_ns();
    char rate[48] = "frame interval not reported";
    if (reported > 0)
      std::snprintf(rate, sizeof rate, "%.3f Hz", 1e9 / static_cast<double>(reported));
    char text[200];
    std::snprintf(text, sizeof text, "camera %s (%s %dx%d, %s)", s.camera.c_str(),
                  hal::to_string(camera->capture.format()), camera->capture.width(),
                  camera->capture.height(), rate);
    camera_text = text;
    loop.set_identifier(camera->markers.get());
  }
  std::printf("mirrorcal run: IMU %s%s%s, %s; %s\n", s.imu.c_str(),
              s.drdy.empty() ? "" : ", data-ready ", s.drdy.c_str(), camera_text.c_str(),
              s.duration_s > 0 ? ("for " + std::to_string(s.duration_s) + " s").c_str()
                               : "until the IMU stops");
  std::fflush(stdout);
  firmware::LoopEnd end;
  {
    StopOnSignal stop_on_signal;
    end = loop.run();
  }
  const int stop_signal = g_stop_signal.load();
  if (stop_signal != 0)
    std::printf(
        "interrupted by %s: stopped at the next IMU sample; writing the calibration so far\n",
        stop_signal == SIGINT ? "SIGINT" : "SIGTERM");

  const firmware::LoopCounters& lcount = loop.counters();
  std::printf("loop: %llu IMU samples over %.3f s, %llu gaps, %llu out of order, %llu frames\n",
              static_cast<unsigned long long>(lcount.imu_samples), imu.seconds(),
              static_cast<unsigned long long>(lcount.imu_gaps),
              static_cast<unsigned long long>(lcount.imu_out_of_order),
              static_cast<unsigned long long>(lcount.frames));
  print_driver_counters(*device);
  if (camera) print_camera_counters(*camera);
  if (profiler) report_profile(*profiler, "timing", s.out);
  const CalibrationResult result =
      make_result(filter, sensors.sensors.width, sensors.sensors.height);
  if (!write_camchain_imucam(s.out + "/camchain-imucam.yaml", result, error) ||
      !write_result_yaml(s.out + "/mirrorcal-result.yaml", result, error))
    fail(error, 1);
  std::printf("wrote %s/camchain-imucam.yaml and %s/mirrorcal-result.yaml\n", s.out.c_str(),
              s.out.c_str());
  if (end == firmware::LoopEnd::kImuError) fail(imu.error(), 1);
  if (end == firmware::LoopEnd::kMarkerError) fail(markers.error(), 1);
  return 0;
}

}  // namespace mirrorcal::app
