// The board's devices as `mirrorcal run` and `mirrorcal record` open them: the IMU (spidev, i2c-dev
// or SocketCAN, optionally paced by a GPIO data-ready line) and the camera (V4L2 capture, markers
// detected in its frames); their counters; and the end of a run by duration or Ctrl-C.
#pragma once

#include <signal.h>

#include <cstdint>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include "cli.hpp"
#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/detection/detecting_marker_source.hpp"
#include "mirrorcal/drivers/frame_watchdog.hpp"
#include "mirrorcal/drivers/gpio_lines.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/drivers/v4l2.hpp"
#include "mirrorcal/hal/sources.hpp"
#include "mirrorcal/io/recording.hpp"
#include "mirrorcal/loop/triggering_imu.hpp"
#include "run_config.hpp"

namespace mirrorcal::app {

// The camera's marker detection, for one of the numbers of markers this build has.
#define MIRRORCAL_DETECTION_OF_(M) std::unique_ptr<detection::DetectingMarkerSource<M>>,
using MarkerDetection =
    std::variant<MIRRORCAL_FOR_EACH_MARKER_COUNT(MIRRORCAL_DETECTION_OF_) std::monostate>;
#undef MIRRORCAL_DETECTION_OF_

// The camera: V4L2 capture, watched for silence (a camera that stops delivering frames ends the
// run with a message, FrameWatchdog), and the markers detected in its frames (blobs, labelled by
// brightness, 1 : 1.5 : 2.25 ... in id order, and by the filter's prediction once a loop relabels
// them), as many as open_devices was given.
struct Camera {
  drivers::V4l2Capture capture;
  drivers::MonotonicClock clock;
  std::unique_ptr<drivers::FrameWatchdog> watchdog;
  MarkerDetection detection;
  // The detection of M markers: M must be the count given to open_devices.
  template <int M>
  detection::DetectingMarkerSource<M>& markers() const {
    return *std::get<std::unique_ptr<detection::DetectingMarkerSource<M>>>(detection);
  }
};

// The settings of a command on the devices into s: --config FILE, then the command line
// (kRunKeys). An IMU is required, and the sensor description (--sensors) when sensors_required;
// else an error naming what is missing.
bool device_settings(const Options& o, const char* command, bool sensors_required, RunSettings& s,
                     std::string& error);

// imu.yaml, camchain.yaml and mirrorcal.yaml of dir into r, as beside a recording; an error names
// the file, line and what is wrong.
bool read_sensors(const std::string& dir, io::Recording& r, std::string& error);

struct Devices {
  std::unique_ptr<drivers::GpioDataReady> drdy;
  std::unique_ptr<hal::ImuSource> imu;
  std::unique_ptr<Camera> camera;                          // null without one
  std::unique_ptr<drivers::GpioOutput> trigger;            // null without one
  std::vector<std::unique_ptr<drivers::GpioOutput>> leds;  // the markers' LED lines, if given
  std::unique_ptr<loop::BlinkingLeds> blinking;            // their code, with them
  std::unique_ptr<loop::TriggeringImu> triggering;         // the IMU driving the trigger, with one

  // The IMU stream a command reads: the one that drives the camera's trigger when there is one.
  hal::ImuSource& imu_stream() const {
    return triggering ? static_cast<hal::ImuSource&>(*triggering) : *imu;
  }
};

// Opens the devices s names into d, the camera (streaming, width x height, detecting `markers`
// markers, a built count, whose LEDs leds describes) first; and the LEDs' lines (leds.lines), which
// the trigger sets in their blink code for each exposure. A device that is missing, busy or of the
// wrong kind, or a malformed specification, is an error naming it with exit_code 1; a trigger
// without a camera, or LED lines without a trigger, one with exit_code 2. imu_rate_hz sets how
// many IMU samples a camera trigger pulse takes when --trigger-every does not (one frame
// interval's worth, 20 Hz where none is reported).
bool open_devices(const RunSettings& s, int markers, const io::MarkerLeds& leds, int width,
                  int height, double imu_rate_hz, Devices& d, std::string& error, int& exit_code);

// ", camera trigger gpiochip0:18 every 4 IMU samples (50 Hz)", or "" without a trigger.
std::string describe_trigger(const RunSettings& s, const Devices& d, double imu_rate_hz);

// "camera /dev/video0 (GREY 640x480, 59.940 Hz)", or "no camera (IMU only)".
std::string describe_camera(const RunSettings& s, const Devices& d);

// The drivers' counters, one line per device: CAN frames lost or rejected, data-ready misses;
// camera frames dropped or corrupt; markers labelled or withheld.
void print_device_counters(const Devices& d);

// SIGINT and SIGTERM ask a run to stop while this object lives (the previous handlers come back
// after it). The handler only stores the signal in a lock-free atomic; StoppingImu reads it.
class StopOnSignal {
 public:
  StopOnSignal();
  ~StopOnSignal();
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;
  // The signal that asked to stop (SIGINT, SIGTERM), 0 while none has.
  static int signal();
  // If one has: prints "interrupted by SIGINT: stopped at the next IMU sample; <then>".
  static void report(const char* then);

 private:
  struct sigaction old_int_ {};
  struct sigaction old_term_ {};
};

// The device's IMU stream, ended after duration_ns of samples (0: never) or at the first sample
// after a signal asked to stop (StopOnSignal); counts the samples it delivered.
class StoppingImu final : public hal::ImuSource {
 public:
  StoppingImu(hal::ImuSource& device, std::int64_t duration_ns)
      : device_(device), duration_ns_(duration_ns) {}
  hal::SourceStatus next(ImuSample& s) override;
  const char* error() const override { return device_.error(); }
  std::int64_t wait_ns() const override { return device_.wait_ns(); }
  std::uint64_t samples() const { return samples_; }
  double seconds() const { return static_cast<double>(last_ns_ - first_ns_) * 1e-9; }

 private:
  hal::ImuSource& device_;
  std::int64_t duration_ns_;
  std::uint64_t samples_ = 0;
  std::int64_t first_ns_ = 0, last_ns_ = 0;
};

}  // namespace mirrorcal::app
