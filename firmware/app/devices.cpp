#include "devices.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <string>
#include <type_traits>

#include "cli.hpp"
#include "mirrorcal/calibration/image_markers.hpp"
#include "mirrorcal/drivers/can_imu.hpp"
#include "mirrorcal/drivers/device_spec.hpp"
#include "mirrorcal/drivers/driver_error.hpp"
#include "mirrorcal/drivers/open_imu.hpp"
#include "mirrorcal/drivers/register_imu.hpp"
#include "mirrorcal/io/files.hpp"

namespace mirrorcal::app {

using namespace calibration;

namespace {

// Frame buffers the camera gets: a few frames of slack while the loop is busy with an update.
constexpr int kCameraBuffers = 8;

std::unique_ptr<Camera> open_camera(const RunSettings& s, int markers, const io::MarkerLeds& leds,
                                    int width, int height) {
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
    throw drivers::DriverError(camera->capture.fault(), camera->capture.error());
  // 20 frame periods of silence, at least 2 s (20 Hz when the driver reports no frame interval).
  const std::int64_t period = camera->capture.frame_period_ns();
  camera->watchdog = std::make_unique<drivers::FrameWatchdog>(
      camera->capture, camera->clock, spec.device,
      drivers::FrameWatchdog::timeout_for(period > 0 ? period : 50'000'000));
  with_marker_count(markers, [&](auto count) {
    constexpr int M = decltype(count)::value;
    camera->detection = std::make_unique<detection::DetectingMarkerSource<M>>(
        *camera->watchdog, calibration::marker_detection_config<M>(leds), width, height);
  });
  return camera;
}

void print_camera_counters(const Camera& camera) {
  const hal::FrameCounters f = camera.capture.counters();
  detection::DetectionCounters d;
  detection::IdentifierCounters id;
  std::visit(
      [&](const auto& markers) {
        if constexpr (!std::is_same_v<std::decay_t<decltype(markers)>, std::monostate>) {
          d = markers->counters();
          id = markers->identifier_counters();
        }
      },
      camera.detection);
  std::printf(
      "camera: %llu frames, %llu dropped, %llu corrupt (skipped), %llu restarts; timestamps %s, "
      "%s\n",
      static_cast<unsigned long long>(f.frames), static_cast<unsigned long long>(f.dropped),
      static_cast<unsigned long long>(f.corrupt), static_cast<unsigned long long>(f.restarts),
      f.stamped_at_dequeue == 0 ? "CLOCK_MONOTONIC" : "NOT CLOCK_MONOTONIC",
      camera.capture.start_of_exposure() ? "start of exposure" : "end of frame");
  if (f.stamped_at_dequeue > 0)
    std::printf(
        "camera: %llu frames stamped when dequeued (the driver's timestamps are on another "
        "clock): late by the readout and the loop's latency, expect a poorer calibration\n",
        static_cast<unsigned long long>(f.stamped_at_dequeue));
  std::printf(
      "markers: %llu labelled, %llu in doubt, %llu crossing, %llu blobs refused, %llu blobs "
      "unassigned; detection %.2f ms per frame\n",
      static_cast<unsigned long long>(id.identified), static_cast<unsigned long long>(id.ambiguous),
      static_cast<unsigned long long>(id.crossing), static_cast<unsigned long long>(id.refused),
      static_cast<unsigned long long>(id.unassigned),
      d.frames > 0 ? 1e3 * d.detect_seconds / static_cast<double>(d.frames) : 0.0);
}

void print_imu_counters(const hal::ImuSource& imu) {
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

std::atomic<int> g_stop_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the signal handler needs a lock-free flag");

extern "C" void request_stop(int signal) {
  g_stop_signal.store(signal, std::memory_order_relaxed);
}

}  // namespace

bool device_settings(const Options& o, const char* command, bool sensors_required, RunSettings& s,
                     std::string& error) {
  if (o.flag("config")) {
    const std::string file = o.get("config", "");
    std::string text;
    if (!io::read_file(file, text, error) || !parse_run_config(text, file, s, error)) return false;
  }
  for (const char* key : kRunKeys)
    if (o.flag(key) && !set_run_setting(s, key, o.get(key, ""), error)) {
      error = "--" + error;
      return false;
    }
  if (s.imu.empty()) {
    error = std::string(command) + ": no IMU given (--imu SPEC, or `imu:` in the --config file)";
    return false;
  }
  if (sensors_required && s.sensors.empty()) {
    error = std::string(command) +
            ": no sensor description given (--sensors DIR with imu.yaml, camchain.yaml and "
            "mirrorcal.yaml, as `mirrorcal record` writes them)";
    return false;
  }
  return true;
}

bool read_sensors(const std::string& dir, io::Recording& r, std::string& error) {
  std::string text;
  const std::string imu = dir + "/imu.yaml", cam = dir + "/camchain.yaml",
                    priors = dir + "/mirrorcal.yaml";
  return io::read_file(imu, text, error) &&
         io::parse_imu_yaml(text, imu, r.sensors, r.notes, error) &&
         io::read_file(cam, text, error) &&
         io::parse_camchain_yaml(text, cam, r.sensors, r.notes, error) &&
         io::read_file(priors, text, error) &&
         io::parse_priors_yaml(text, priors, r.sensors.intrinsics, r.priors, r.notes, error);
}

bool open_devices(const RunSettings& s, int markers, const io::MarkerLeds& leds, int width,
                  int height, double imu_rate_hz, Devices& d, std::string& error, int& exit_code) {
  if (!s.trigger.empty() && s.camera.empty()) {
    error = "--trigger " + s.trigger + ": a camera trigger needs a camera (--camera DEV)";
    exit_code = 2;
    return false;
  }
  if (!leds.lines.empty() && s.trigger.empty()) {
    error =
        "mirrorcal.yaml: led_lines: LEDs that blink their names need a camera trigger "
        "(--trigger CHIP:LINE): each exposure's pulse sets them, so that frame n shows "
        "their code's frame n";
    exit_code = 2;
    return false;
  }
  try {
    if (!s.trigger.empty())
      d.trigger = std::make_unique<drivers::GpioOutput>(drivers::parse_line_spec(s.trigger));
    for (const std::string& line : leds.lines)
      d.leds.push_back(std::make_unique<drivers::GpioOutput>(drivers::parse_line_spec(line), false,
                                                             "mirrorcal-led", true));
    d.camera = open_camera(s, markers, leds, width, height);
    const drivers::ImuSpec spec = drivers::parse_imu_spec(s.imu);
    if (!s.drdy.empty())
      d.drdy = std::make_unique<drivers::GpioDataReady>(drivers::parse_line_spec(s.drdy));
    drivers::RegisterImuConfig imu_config;
    imu_config.rate_hz = s.rate_hz;
    imu_config.gyro_range_dps = s.gyro_range_dps;
    imu_config.accel_range_g = s.accel_range_g;
    d.imu = drivers::open_imu(spec, imu_config, d.drdy.get());
  } catch (const drivers::DriverError& e) {
    error = e.what();
    exit_code = 1;
    return false;
  }
  if (d.trigger) {
    int every = s.trigger_every;
    if (every == 0) {
      const std::int64_t frame = d.camera->capture.frame_period_ns() > 0
                                     ? d.camera->capture.frame_period_ns()
                                     : 50'000'000;
      // The fastest rate the camera keeps up with: whole IMU periods, at least one frame interval
      // (and two periods: a pulse lasts one).
      every = std::max(
          2, static_cast<int>(std::ceil(static_cast<double>(frame) * 1e-9 * imu_rate_hz - 1e-6)));
    }
    if (!d.leds.empty()) {
      std::vector<hal::OutputLine*> lines;
      for (const auto& led : d.leds) lines.push_back(led.get());
      d.blinking = std::make_unique<loop::BlinkingLeds>(
          lines.data(), static_cast<int>(lines.size()), hal::BlinkCode{leds.blink_period});
    }
    d.triggering =
        std::make_unique<loop::TriggeringImu>(*d.imu, *d.trigger, every, d.blinking.get());
  }
  return true;
}

std::string describe_trigger(const RunSettings& s, const Devices& d, double imu_rate_hz) {
  if (!d.triggering) return "";
  const int every = d.triggering->every();
  char text[160];
  std::snprintf(text, sizeof text, ", camera trigger %s every %d IMU samples (%.4g Hz)",
                s.trigger.c_str(), every, imu_rate_hz / every);
  std::string described = text;
  if (d.blinking)
    described += ", " + std::to_string(d.blinking->count()) +
                 " LEDs blinking their names (a code of " +
                 std::to_string(d.blinking->code().period) + " frames)";
  return described;
}

std::string describe_camera(const RunSettings& s, const Devices& d) {
  if (!d.camera) return "no camera (IMU only)";
  const drivers::V4l2Capture& c = d.camera->capture;
  char rate[48] = "frame interval not reported";
  if (c.frame_period_ns() > 0)
    std::snprintf(rate, sizeof rate, "%.3f Hz", 1e9 / static_cast<double>(c.frame_period_ns()));
  char text[200];
  std::snprintf(text, sizeof text, "camera %s (%s %dx%d, %s)", s.camera.c_str(),
                hal::to_string(c.format()), c.width(), c.height(), rate);
  return text;
}

void print_device_counters(const Devices& d) {
  print_imu_counters(*d.imu);
  if (d.triggering)
    std::printf("trigger: %llu pulses, one every %d IMU samples\n",
                static_cast<unsigned long long>(d.triggering->pulses()), d.triggering->every());
  if (d.camera) print_camera_counters(*d.camera);
}

StopOnSignal::StopOnSignal() {
  struct sigaction sa {};
  sa.sa_handler = request_stop;  // no SA_RESTART: a blocking wait returns early
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, &old_int_);
  sigaction(SIGTERM, &sa, &old_term_);
}

StopOnSignal::~StopOnSignal() {
  sigaction(SIGINT, &old_int_, nullptr);
  sigaction(SIGTERM, &old_term_, nullptr);
}

int StopOnSignal::signal() {
  return g_stop_signal.load(std::memory_order_relaxed);
}

void StopOnSignal::report(const char* then) {
  const int sig = signal();
  if (sig != 0)
    std::printf("interrupted by %s: stopped at the next IMU sample; %s\n",
                sig == SIGINT ? "SIGINT" : "SIGTERM", then);
}

hal::SourceStatus StoppingImu::next(ImuSample& s) {
  if (StopOnSignal::signal() != 0) return hal::SourceStatus::kEndOfStream;
  const hal::SourceStatus st = device_.next(s);
  // A device that timed out while the stop was asked for has not failed: the run was ending.
  if (StopOnSignal::signal() != 0) return hal::SourceStatus::kEndOfStream;
  if (st != hal::SourceStatus::kOk) return st;
  if (samples_ == 0) first_ns_ = s.t_ns;
  if (duration_ns_ > 0 && s.t_ns - first_ns_ > duration_ns_) return hal::SourceStatus::kEndOfStream;
  ++samples_;
  last_ns_ = s.t_ns;
  return st;
}

}  // namespace mirrorcal::app
