// mirrorcal run: the calibration loop on the board's own devices. The IMU comes from a driver
// (spidev, i2c-dev or SocketCAN, optionally paced by a GPIO data-ready line); the marker stream
// from open_marker_source(), where the camera's capture and detection plug in (until then a run
// is IMU-only: the filter propagates and the result is the prior, carried through the motion).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include "cli.hpp"
#include "loop_options.hpp"
#include "mirrorcal/drivers/can_imu.hpp"
#include "mirrorcal/drivers/device_spec.hpp"
#include "mirrorcal/drivers/gpio_lines.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/drivers/open_imu.hpp"
#include "mirrorcal/drivers/register_imu.hpp"
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

// The marker source of the run's camera (none: IMU only).
std::unique_ptr<hal::MarkerSource<kMarkers>> open_marker_source(const RunSettings& s) {
  if (s.camera.empty()) return std::make_unique<NoMarkers>();
  fail("--camera " + s.camera +
           ": `run` does not drive a camera yet; run without --camera for "
           "the IMU alone",
       2);
}

// Ends the device's stream after `duration_ns` of samples (0: never) and counts them.
class LimitedImu final : public hal::ImuSource {
 public:
  LimitedImu(hal::ImuSource& device, std::int64_t duration_ns)
      : device_(device), duration_ns_(duration_ns) {}
  hal::SourceStatus next(ImuSample& s) override {
    const hal::SourceStatus st = device_.next(s);
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
  std::unique_ptr<hal::MarkerSource<kMarkers>> markers;
  try {
    const drivers::ImuSpec spec = drivers::parse_imu_spec(s.imu);
    if (!s.drdy.empty())
      drdy = std::make_unique<drivers::GpioDataReady>(drivers::parse_line_spec(s.drdy));
    drivers::RegisterImuConfig imu_config;
    imu_config.rate_hz = s.rate_hz;
    imu_config.gyro_range_dps = s.gyro_range_dps;
    imu_config.accel_range_g = s.accel_range_g;
    device = drivers::open_imu(spec, imu_config, drdy.get());
    markers = open_marker_source(s);
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
  drivers::MonotonicClock clock;
  const std::int64_t imu_period = imu_period_ns(sensors.sensors.imu_rate_hz);
  const std::int64_t frame_period = 50'000'000;  // 20 Hz, until a camera says otherwise
  const auto profiler = make_profiler(o, clock, imu_period, frame_period);
  apply_realtime_options(o);
  firmware::LoopConfig lc;
  lc.imu_period_ns = imu_period;
  lc.profiler = profiler.get();
  firmware::CalibrationLoop<double, kMarkers, 0> loop(filter, imu, *markers, lc);
  std::printf("mirrorcal run: IMU %s%s%s, %s; %s\n", s.imu.c_str(),
              s.drdy.empty() ? "" : ", data-ready ", s.drdy.c_str(),
              s.camera.empty() ? "no camera (IMU only)" : s.camera.c_str(),
              s.duration_s > 0 ? ("for " + std::to_string(s.duration_s) + " s").c_str()
                               : "until the IMU stops");
  std::fflush(stdout);
  const firmware::LoopEnd end = loop.run();

  const firmware::LoopCounters& lcount = loop.counters();
  std::printf("loop: %llu IMU samples over %.3f s, %llu gaps, %llu out of order, %llu frames\n",
              static_cast<unsigned long long>(lcount.imu_samples), imu.seconds(),
              static_cast<unsigned long long>(lcount.imu_gaps),
              static_cast<unsigned long long>(lcount.imu_out_of_order),
              static_cast<unsigned long long>(lcount.frames));
  print_driver_counters(*device);
  if (profiler) report_profile(*profiler, "timing", s.out);
  const CalibrationResult result =
      make_result(filter, sensors.sensors.width, sensors.sensors.height);
  if (!write_camchain_imucam(s.out + "/camchain-imucam.yaml", result, error) ||
      !write_result_yaml(s.out + "/mirrorcal-result.yaml", result, error))
    fail(error, 1);
  std::printf("wrote %s/camchain-imucam.yaml and %s/mirrorcal-result.yaml\n", s.out.c_str(),
              s.out.c_str());
  if (end == firmware::LoopEnd::kImuError) fail(imu.error(), 1);
  if (end == firmware::LoopEnd::kMarkerError) fail(markers->error(), 1);
  return 0;
}

}  // namespace mirrorcal::app
