// mirrorcal run: the calibration loop on the board's own devices. The IMU comes from a driver
// (spidev, i2c-dev or SocketCAN, optionally paced by a GPIO data-ready line); the marker stream
// from a V4L2 camera whose frames go through the board's marker detection, identified with the
// filter's prediction at each frame's time (without --camera a run is IMU-only: the filter
// propagates and the result is the prior, carried through the motion). The live pass keeps what
// it consumed; the result is then calibrated from it as `mirrorcal calibrate` calibrates a
// recording (kDefaultPasses passes from the prior: one pass alone is over-confident).
#include <unistd.h>

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "build_tools.hpp"
#include "cli.hpp"
#include "devices.hpp"
#include "live_feedback.hpp"
#include "loop_options.hpp"
#include "mirrorcal/calibration/recording_run.hpp"
#include "mirrorcal/calibration/report.hpp"
#include "mirrorcal/calibration/result.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/io/recording.hpp"
#include "mirrorcal/loop/loop.hpp"
#include "run_config.hpp"

namespace mirrorcal::app {

using namespace calibration;

namespace {

// No camera: the marker stream is empty from the start.
template <int M>
class NoMarkers final : public hal::MarkerSource<M> {
 public:
  hal::SourceStatus poll(MarkerFrame<M>&) override { return hal::SourceStatus::kEndOfStream; }
};

// What the live loop consumed, kept for the calibration after it. The memory is reserved before
// the loop starts (the loop does not allocate); what does not fit is counted and left out.
template <int M>
struct SessionLog {
  SessionLog(std::size_t imu_capacity, std::size_t frame_capacity) {
    imu.reserve(imu_capacity);
    frames.reserve(frame_capacity);
  }
  std::vector<ImuSample> imu;
  std::vector<MarkerFrame<M>> frames;  // as labelled with the filter's prediction
  std::uint64_t left_out = 0;

  template <class T>
  void keep(std::vector<T>& v, const T& item) {
    if (v.size() < v.capacity())
      v.push_back(item);
    else
      ++left_out;
  }
  // The log as a recording with the run's sensor description and priors.
  void to_recording(io::Recording& r) const {
    r.imu = imu;
    r.frames.clear();
    for (const MarkerFrame<M>& f : frames) {
      io::ObservedFrame o;
      o.t_ns = f.t_ns;
      for (int i = 0; i < M; ++i) {
        const auto k = static_cast<std::size_t>(i);
        if (f.seen[k]) o.markers.push_back({i, f.uv[k].x(), f.uv[k].y()});
      }
      r.frames.push_back(o);
    }
  }
};

template <int M>
class LoggedImu final : public hal::ImuSource {
 public:
  LoggedImu(hal::ImuSource& inner, SessionLog<M>& log) : inner_(inner), log_(log) {}
  hal::SourceStatus next(ImuSample& s) override {
    const hal::SourceStatus st = inner_.next(s);
    if (st == hal::SourceStatus::kOk) log_.keep(log_.imu, s);
    return st;
  }
  const char* error() const override { return inner_.error(); }
  std::int64_t wait_ns() const override { return inner_.wait_ns(); }

 private:
  hal::ImuSource& inner_;
  SessionLog<M>& log_;
};

// The camera's markers; each frame is kept once the loop has labelled it with its prediction.
template <int M>
class LoggedMarkers final : public hal::MarkerSource<M>, public hal::MarkerRelabeler<M> {
 public:
  LoggedMarkers(detection::DetectingMarkerSource<M>& inner, SessionLog<M>& log)
      : inner_(inner), log_(log) {}
  hal::SourceStatus poll(MarkerFrame<M>& frame) override { return inner_.poll(frame); }
  void relabel(const hal::MarkerPrediction<M>& prediction, MarkerFrame<M>& frame) override {
    inner_.relabel(prediction, frame);
    log_.keep(log_.frames, frame);
  }
  const char* error() const override { return inner_.error(); }
  std::int64_t detection_ns() const override { return inner_.detection_ns(); }

 private:
  detection::DetectingMarkerSource<M>& inner_;
  SessionLog<M>& log_;
};

// Seconds of data a run without --duration keeps for its calibration: about 7 MB of IMU samples
// at 200 Hz and 2 MB of frames at 60 Hz, reserved at the start.
constexpr double kLoggedSecondsWithoutDuration = 600.0;

// The devices' streams as the live loop reads them: the IMU ended by --duration or a signal, and
// both streams kept in a SessionLog sized for the run (markers only with a camera).
template <int M>
class LiveStreams {
 public:
  LiveStreams(const Devices& devices, double duration_s, std::int64_t imu_period,
              std::int64_t frame_period)
      : stopping_(devices.imu_stream(), static_cast<std::int64_t>(duration_s * 1e9)),
        log_(capacity(duration_s, imu_period),
             devices.camera ? capacity(duration_s, frame_period) : 0),
        imu_(stopping_, log_) {
    if (devices.camera)
      logged_markers_ = std::make_unique<LoggedMarkers<M>>(devices.camera->markers<M>(), log_);
  }
  hal::ImuSource& imu() { return imu_; }
  hal::MarkerSource<M>& markers() {
    return logged_markers_ ? static_cast<hal::MarkerSource<M>&>(*logged_markers_) : no_markers_;
  }
  // What labels the camera's markers with the filter's prediction (null without a camera).
  hal::MarkerRelabeler<M>* identifier() { return logged_markers_.get(); }
  double seconds() const { return stopping_.seconds(); }
  SessionLog<M>& log() { return log_; }

 private:
  // Items of one period kept over the run (--duration, else kLoggedSecondsWithoutDuration).
  static std::size_t capacity(double duration_s, std::int64_t period_ns) {
    const double kept_s = (duration_s > 0 ? duration_s : kLoggedSecondsWithoutDuration) + 1.0;
    return static_cast<std::size_t>(kept_s * 1e9 / static_cast<double>(period_ns));
  }

  StoppingImu stopping_;
  SessionLog<M> log_;
  LoggedImu<M> imu_;
  NoMarkers<M> no_markers_;
  std::unique_ptr<LoggedMarkers<M>> logged_markers_;
};

bool parse_run_options(int argc, char** argv, Options& o, std::string& error) {
  std::vector<std::string> with_value = {"config", "from", "imu-model"};
  for (const char* key : kRunKeys) with_value.emplace_back(key);
  std::vector<std::string> flags;
  with_value.insert(with_value.end(), kLoopValueOptions.begin(), kLoopValueOptions.end());
  flags.insert(flags.end(), kLoopFlagOptions.begin(), kLoopFlagOptions.end());
  return parse(argc, argv, 2, with_value, flags, o, error);
}

// The priors of a run's mirrorcal.yaml (--sensors); an error names the file.
template <int M>
bool run_prior(const RunSettings& s, const io::Recording& sensors, Prior<M>& prior,
               std::string& error) {
  if (io::to_prior(sensors.priors, prior, error)) return true;
  error = s.sensors + "/mirrorcal.yaml: " + error;
  return false;
}

// Runs the loop while SIGINT and SIGTERM ask it to stop (at the next IMU sample).
template <class Loop>
loop::LoopEnd run_until_signal(Loop& loop) {
  StopOnSignal stop_on_signal;
  return loop.run();
}

// The frame path's budget: the camera's frame interval where the driver reports one, else 20 Hz.
std::int64_t frame_period_ns(const Devices& devices) {
  const std::unique_ptr<Camera>& camera = devices.camera;
  return camera && camera->capture.frame_period_ns() > 0 ? camera->capture.frame_period_ns()
                                                         : 50'000'000;
}

void print_run_start(const RunSettings& s, const Devices& devices, double imu_rate_hz) {
  std::printf("mirrorcal run: IMU %s%s%s, %s%s; %s\n", s.imu.c_str(),
              s.drdy.empty() ? "" : ", data-ready ", s.drdy.c_str(),
              describe_camera(s, devices).c_str(),
              describe_trigger(s, devices, imu_rate_hz).c_str(),
              s.duration_s > 0 ? ("for " + std::to_string(s.duration_s) + " s").c_str()
                               : "until the IMU stops");
  std::fflush(stdout);
}

void print_loop_counters(const loop::LoopCounters& lcount, double seconds) {
  std::printf(
      "loop: %llu IMU samples over %.3f s, %llu gaps (%llu too long to cross: motion restarted), "
      "%llu out of order, %llu frames\n",
      static_cast<unsigned long long>(lcount.imu_samples), seconds,
      static_cast<unsigned long long>(lcount.imu_gaps),
      static_cast<unsigned long long>(lcount.imu_restarts),
      static_cast<unsigned long long>(lcount.imu_out_of_order),
      static_cast<unsigned long long>(lcount.frames));
}

// The calibration after the live pass: what it kept, as a recording with the sensor description
// and priors, calibrated as `mirrorcal calibrate` calibrates one (from an earlier calibration with
// from). The result and its report replace the live pass's; false with the error when it fails.
template <int M, int NI>
bool calibrate_log(const SessionLog<M>& log, io::Recording& sensors,
                   const io::CalibrationStart* from, const std::string& title,
                   CalibrationResult& result, ReportData& report, std::string& error) {
  std::printf(
      "calibrating from the run's %zu IMU samples and %zu labelled frames%s, in %d passes "
      "(more if one gates too many) and the Gauss-Newton refinement's, as `mirrorcal calibrate` "
      "does\n",
      log.imu.size(), log.frames.size(),
      log.left_out > 0 ? " (the rest did not fit the memory reserved)" : "", kDefaultPasses);
  log.to_recording(sensors);
  // The live pass predicted with camchain.yaml's intrinsics; the calibration estimates them too
  // when mirrorcal.yaml asks (estimate_intrinsics, hold_skew), with the IMU's as the live pass did.
  const auto refine = [&](auto k) {
    CalibrationRun<M, decltype(k)::value, NI> run;
    if (!calibrate_recording(sensors, run, error, {}, from)) return false;
    result = run.result;
    report = report_data(run, title);
    report.from_earlier = from != nullptr;
    return true;
  };
  const io::RecordingPriors& p = sensors.priors;
  return with_camera_block(camera_block(p.estimate_intrinsics, p.hold_skew, p.estimate_distortion),
                           refine);
}

// The result's warnings on stderr, and its files in dir.
bool write_run_result(const std::string& dir, const CalibrationResult& result,
                      const ReportData& report, std::string& error) {
  print_result_warnings(result);
  io::OutputSet out;
  if (!write_camchain_imucam(out, dir + "/camchain-imucam.yaml", result, error) ||
      !write_result_yaml(out, dir + "/mirrorcal-result.yaml", result, error) ||
      !write_report(out, dir, report, report_plots(), error) || !out.commit(error))
    return false;
  std::printf(
      "wrote %s/camchain-imucam.yaml, mirrorcal-result.yaml, report.txt, report.html, "
      "residuals.csv, imu_residuals.csv\n",
      dir.c_str());
  return true;
}

// The live pass's filter, its start and its feedback, allocated once before the loop starts: with
// 6 markers and the IMU's intrinsics they outgrow the 64 KiB a stack frame is held to.
template <int M, int NI>
struct LiveEstimator {
  using Filter = CalibrationFilter<double, M, 0, NI>;
  struct Start {
    typename Filter::State x0;
    typename Filter::Covariance p0;
    explicit Start(const Prior<M>& prior) { initialise(prior, x0, p0); }
  };
  LiveEstimator(const Prior<M>& prior, const CalibrationConfig& config, bool every_window)
      : start(prior), filter(config), feedback(start.p0, stdout, every_window) {
    filter.reset(start.x0, start.p0);
  }
  Start start;
  Filter filter;
  // While the user moves the rig: what is still uncertain, what motion helps, when it converged.
  // On a terminal a line every window; in a log only when the verdict changes.
  LiveFeedback<M, NI> feedback;
};

}  // namespace

// The live loop of M markers (and NI of the IMU's intrinsics) on the devices, then the calibration
// of what it kept.
template <int M, int NI>
int run_on_devices(const Options& o, const RunSettings& s, io::Recording& sensors) {
  std::string error;
  Prior<M> prior;
  if (!run_prior(s, sensors, prior, error)) return refuse(error, 2);
  prior.sigma_imu_intrinsics = sensors.sensors.imu_tolerances;
  // --from: the calibration after the live pass starts the camera pose and markers from an earlier
  // one (stage 2 after stage 1, as calibrate --from).
  io::CalibrationStart start;
  const io::CalibrationStart* from = nullptr;
  if (o.flag("from")) {
    if (!io::read_calibration_start(o.get("from", ""), M, start, error)) return refuse(error, 1);
    from = &start;
  }

  // The devices; anything missing, busy or of the wrong kind ends the run here, with its reason.
  Devices devices;
  int exit_code = 1;
  if (!open_devices(s, M, sensors.priors.leds, sensors.sensors.width, sensors.sensors.height,
                    sensors.sensors.imu_rate_hz, devices, error, exit_code))
    return refuse(error, exit_code);
  if (!create_out_dir(s.out, error)) return refuse(error, 1);

  const auto estimator = std::make_unique<LiveEstimator<M, NI>>(prior, recording_config(sensors),
                                                                isatty(STDOUT_FILENO) == 1);
  auto& filter = estimator->filter;
  const std::int64_t imu_period = imu_period_ns(sensors.sensors.imu_rate_hz);
  const std::int64_t frame_period = frame_period_ns(devices);
  LiveStreams<M> streams(devices, s.duration_s, imu_period, frame_period);
  drivers::MonotonicClock clock;
  std::unique_ptr<loop::LoopProfiler> profiler;
  if (!make_profiler(o, clock, imu_period, frame_period, profiler, error) ||
      !apply_realtime_options(o, error))
    return refuse(error);
  loop::LoopConfig lc;
  lc.imu_period_ns = imu_period;
  lc.profiler = profiler.get();
  loop::CalibrationLoop<double, M, 0, NI> loop(filter, streams.imu(), streams.markers(), lc,
                                               devices.camera ? &estimator->feedback : nullptr);
  if (devices.camera) loop.set_identifier(streams.identifier());
  print_run_start(s, devices, sensors.sensors.imu_rate_hz);
  if constexpr (NI > 0)
    std::printf("mirrorcal run: the IMU's intrinsics estimated too (model %s)\n",
                to_string(imu_model_of_dim(NI)));
  const loop::LoopEnd end = run_until_signal(loop);
  StopOnSignal::report("writing the calibration so far");

  print_loop_counters(loop.counters(), streams.seconds());
  print_device_counters(devices);
  if (profiler && !report_profile(*profiler, "timing", s.out, error)) return refuse(error, 1);
  CalibrationResult result = make_result(filter, sensors.sensors.width, sensors.sensors.height);
  const std::string title = "mirrorcal run, IMU " + s.imu;
  ReportData report = report_data_without_history(result, title);
  if (!streams.log().frames.empty() &&
      !calibrate_log<M, NI>(streams.log(), sensors, from, title, result, report, error))
    return refuse(error, 1);
  // The camera's stamps against the IMU's clock (a V4L2 driver stamping the end of the frame, the
  // bus's latency): what the calibration found.
  const auto t_row = std::size_t(calibration_layout(M, 0)[CalibrationGroup::kTimeOffset].begin);
  std::printf("time offset found: timeshift_cam_imu %.3f ms +- %.3f ms (t_imu = t_cam + it)\n",
              1e3 * result.t_d, t_row < result.sigma.size() ? 1e3 * result.sigma[t_row] : 0.0);
  result.rostopic = sensors.sensors.rostopic;  // also when no frame was labelled
  report.result = result;
  if (!write_run_result(s.out, result, report, error)) return refuse(error, 1);
  if (end == loop::LoopEnd::kImuError) return refuse(streams.imu().error(), 1);
  if (end == loop::LoopEnd::kMarkerError) return refuse(streams.markers().error(), 1);
  return calibration_exit_status(result);
}

int cmd_run(int argc, char** argv) {
  Options o;
  std::string error;
  if (!parse_run_options(argc, argv, o, error)) return refuse(error);
  // The settings (--config, then the command line) and the sensor description (--sensors), whose
  // mirrorcal.yaml says how many markers the camera's frames hold and imu.yaml which IMU model
  // the calibration estimates (or --imu-model).
  RunSettings s;
  io::Recording sensors;
  ImuModel imu_model = kDefaultImuModel;
  if (!device_settings(o, "run", true, s, error) || !read_sensors(s.sensors, sensors, error) ||
      !calibration_imu_model(o, sensors.sensors, s.sensors, imu_model, error))
    return refuse(error, 2);
  return with_markers(int(sensors.priors.features_c.size()), [&](auto markers) {
    return with_imu_model_of(imu_model, [&](auto imu) {
      return run_on_devices<decltype(markers)::value, decltype(imu)::value>(o, s, sensors);
    });
  });
}

}  // namespace mirrorcal::app
