// Recordings in the EuRoC/ASL layout (docs/design.md, "File formats"):
//   DIR/mav0/imu0/data.csv       #timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_z [m s^-2]
//   DIR/mav0/cam0/data.csv       #timestamp [ns],filename          (every frame, with or without
//                                                                  markers)
//   DIR/mav0/cam0/features.csv   #timestamp [ns],feature_id,u [px],v [px]   (ids 0..M-1; pixels
//                                                                  with the origin at the top-left
//                                                                  pixel's centre)
//   DIR/mav0/cam0/data/          the images, only when the recording has them (8-bit grey PNG,
//                                <timestamp>.png as data.csv names them; PGM is read too)
//   DIR/imu.yaml, DIR/camchain.yaml   Kalibr sensor descriptions
//   DIR/mirrorcal.yaml                the priors (docs/recordings.md, "mirrorcal.yaml")
// Numbers are written as the shortest decimal that reads back as the same double, so a recording
// written and read again replays bit-identically.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "mirrorcal/estimator/prior.hpp"
#include "mirrorcal/hal/frames.hpp"
#include "mirrorcal/hal/sources.hpp"
#include "mirrorcal/io/files.hpp"
#include "mirrorcal/io/images.hpp"
#include "mirrorcal/io/replay.hpp"

namespace mirrorcal::io {

// features.csv's header (the other files' are EuRoC's).
inline constexpr const char* kFeaturesHeader = "#timestamp [ns],feature_id,u [px],v [px]";

// Kalibr's topics of the first camera and the IMU: what camchain.yaml and imu.yaml name when they
// name none.
inline constexpr const char* kDefaultCameraTopic = "/cam0/image_raw";
inline constexpr const char* kDefaultImuTopic = "/imu0";

// camchain.yaml's distortion_model: radtan (with zero coefficients) for no lens, which every
// reader takes.
inline const char* kalibr_lens_name(Distortion d) {
  return to_string(d == Distortion::kNone ? Distortion::kRadtan : d);
}

// A camera as camchain.yaml and mirrorcal-result.yaml describe it.
struct CameraInfo {
  Pinhole<double> intrinsics{};  // skew: camchain.yaml's intrinsics_skew (0 if absent)
  int width = 640, height = 480;
  std::string rostopic = kDefaultCameraTopic;  // written back for Kalibr and OpenVINS
};

// The IMU sample rates imu.yaml's update_rate may give (Hz): every real part's lies within, and
// beyond them the sample period in ns rounds to 0 or overflows.
constexpr double kMinImuRateHz = 1.0, kMaxImuRateHz = 10000.0;

// What imu.yaml and camchain.yaml say about the sensors.
struct SensorInfo : CameraInfo {
  ImuNoise imu{};
  double imu_rate_hz = 200.0;
  std::string imu_rostopic = kDefaultImuTopic;  // where a bag's IMU messages are
  // mirrorcal's own imu.yaml keys (docs/recordings.md): the IMU model the calibration estimates
  // (imu_model; none: the program's default) and the datasheet's tolerances, 1-sigma (defaults
  // that cover common MEMS parts where not given).
  std::optional<ImuModel> imu_model;
  ImuIntrinsicsSigma imu_tolerances{};
  bool imu_tolerances_defaulted = true;  // some not given (the calibration notes it)
};

// What mirrorcal.yaml says is known before calibrating. SI units, rotations in rad; quaternions
// Hamilton, w first in the file. Markers are as many as the file lists.
// The markers' LEDs, for the detection in frames (mirrorcal.yaml's led_brightness, blink_period
// and led_lines, all optional): their relative brightness, one per marker (empty: 1 : 1.5 :
// 2.25 ..., the brightness code; all equal: identical LEDs); the blink code's period in frames
// (hal/blink_code.hpp; 0: the LEDs stay lit); and the GPIO line of each marker's LED, CHIP:LINE,
// which run and record drive in that code.
struct MarkerLeds {
  std::vector<double> brightness;
  int blink_period = 0;
  std::vector<std::string> lines;
};

struct RecordingPriors {
  Eigen::Vector3d gravity_n = Eigen::Vector3d::Zero();
  double pixel_sigma = 1.0;
  Eigen::Vector3d p_n_b = Eigen::Vector3d::Zero(), sigma_p_n_b = Eigen::Vector3d::Zero();
  Eigen::Vector3d v_n_b = Eigen::Vector3d::Zero(), sigma_v_n_b = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_n_b = Eigen::Quaterniond::Identity();
  Eigen::Vector3d sigma_rot_n_b = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_a = Eigen::Vector3d::Zero(), sigma_b_a = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_g = Eigen::Vector3d::Zero(), sigma_b_g = Eigen::Vector3d::Zero();
  Eigen::Vector3d p_b_c = Eigen::Vector3d::Zero(), sigma_p_b_c = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_b_c = Eigen::Quaterniond::Identity();
  Eigen::Vector3d sigma_rot_b_c = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> features_c, sigma_features_c;
  double t_d = 0.0, sigma_t_d = 0.02;  // timeshift_cam_imu and its 1-sigma (s)
  bool estimate_intrinsics = false;
  bool hold_skew = false;  // estimate fu fv cu cv only; skew stays at camchain.yaml's (0 if absent)
  Pinhole<double> intrinsics_guess{};        // default: camchain.yaml's
  std::array<double, 5> sigma_intrinsics{};  // fu fv cu cv skew (px)
  // With estimate_intrinsics: estimate the lens's four distortion coefficients too, skew held at
  // camchain.yaml's (needs a distortion_model other than none). Their guess is camchain.yaml's
  // distortion_coeffs (intrinsics_guess.coeffs), their 1-sigma sigma_distortion.
  bool estimate_distortion = false;
  std::array<double, 4> sigma_distortion = default_sigma_distortion(Distortion::kRadtan);
  MarkerLeds leds;
};

// What is true, known only for simulated recordings (truth.yaml, optional): lets calibrate report
// the error of its estimate.
struct RecordingTruth {
  Eigen::Vector3d p_b_c = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_b_c = Eigen::Quaterniond::Identity();
  std::vector<Eigen::Vector3d> features_c;
  double t_d = 0.0;  // timeshift_cam_imu (s); 0 in files written before it was simulated
  Pinhole<double> intrinsics{};
  // The lens's true coefficients (intrinsics.coeffs), when camchain.yaml holds a guess of them
  // (a recording for estimate_distortion); otherwise camchain.yaml's are the truth.
  bool has_distortion = false;
};

// What the input checks and the loop need to know of a recording's streams, gathered in one
// pass over its files (recording_checks.hpp).
struct RecordingStats {
  std::uint64_t imu_samples = 0;
  std::int64_t imu_first_ns = 0, imu_last_ns = 0;
  // Medians over every sample (over an evenly spaced subset of at most 65536 in longer data).
  double imu_step_median_ns = 0.0, gyro_norm_median = 0.0, accel_norm_median = 0.0;
  // The discrete white noise the data show in their second differences (0: nothing to measure).
  double gyro_noise_seen = 0.0, accel_noise_seen = 0.0;
  std::uint64_t frames_listed = 0;  // every frame of cam0/data.csv
  std::int64_t frames_first_ns = 0, frames_last_ns = 0;
  std::uint64_t frames = 0;  // within the IMU data: those the filter gets
  std::int64_t frames_inside_first_ns = 0, frames_inside_last_ns = 0;
  std::uint64_t markers = 0;      // observations in those frames
  std::vector<bool> marker_seen;  // by id, in those frames
};

class FrameStream;

// What reading a recording's images met (calibrate on images): an image that cannot be read is
// skipped, counted and named here, and the rest go on. Fixed storage: the loop allocates nothing.
struct ImageLog {
  std::uint64_t unreadable = 0;  // in the pass that met most (every full pass meets the same)
  static constexpr int kKept = 5;
  int kept = 0;
  std::array<std::array<char, 512>, kKept> messages{};  // the first ones', naming their files
  // Keeps text (cut to 511 characters) among messages if it is among the first, each once.
  void keep(const char* text);
};

// A recording's streams, opened afresh for each pass of a calibration (open_recording reads them
// from the files again each time, so that memory stays bounded whatever their size).
class RecordingStreams {
 public:
  virtual ~RecordingStreams() = default;
  // A pass's sources from the start of the streams: the IMU samples, and the frames within the
  // IMU data. A file that no longer reads as it did ends its stream with an error.
  virtual std::unique_ptr<hal::ImuSource> open_imu() const = 0;
  virtual std::unique_ptr<FrameStream> open_frames() const = 0;
  // The images of the frames within the IMU data, as 8-bit grey frames (a recording opened with
  // from_images; nullptr otherwise). Each source allocates its buffers when opened.
  virtual std::unique_ptr<hal::FrameSource> open_images() const { return nullptr; }
  // What the image sources met; nullptr without images.
  virtual const ImageLog* image_log() const { return nullptr; }
  // The first error any pass met (the files changed while calibrating); empty if none.
  virtual const std::string& error() const = 0;
};

// The frames within the IMU data, with their markers, in timestamp order.
class FrameStream {
 public:
  virtual ~FrameStream() = default;
  // kOk with the next frame (its marker list reused), kEndOfStream, or kError.
  virtual hal::SourceStatus next(ObservedFrame& frame) = 0;
};

// A FrameStream as the loop's marker source; markers with an id at or above M are ignored.
template <int M>
class StreamedMarkerSource final : public hal::MarkerSource<M> {
 public:
  explicit StreamedMarkerSource(std::unique_ptr<FrameStream> frames) : frames_(std::move(frames)) {
    frame_.markers.reserve(M);  // the loop allocates nothing once it runs
  }
  hal::SourceStatus poll(MarkerFrame<M>& frame) override {
    const hal::SourceStatus status = frames_->next(frame_);
    if (status != hal::SourceStatus::kOk) return status;
    frame.t_ns = frame_.t_ns;
    frame.seen.fill(false);
    for (const ObservedMarker& m : frame_.markers) {
      if (m.id < 0 || m.id >= M) continue;
      frame.seen[static_cast<std::size_t>(m.id)] = true;
      frame.uv[static_cast<std::size_t>(m.id)] = Eigen::Vector2d(m.u, m.v);
    }
    return hal::SourceStatus::kOk;
  }

 private:
  std::unique_ptr<FrameStream> frames_;
  ObservedFrame frame_;
};

// A recording read back: the streams in timestamp order and the descriptions beside them.
struct Recording {
  // The streams, held whole by read_recording; empty after open_recording, whose streams read
  // them from the files.
  std::vector<ImuSample> imu;
  std::vector<ObservedFrame> frames;  // only frames within the IMU data
  std::shared_ptr<const RecordingStreams> streams;
  RecordingStats stats;
  SensorInfo sensors;
  RecordingPriors priors;
  std::uint64_t frames_outside_imu = 0;  // skipped: before the first or after the last IMU sample
  std::vector<std::string> notes;        // defaults used, frames skipped: tell the user
  std::vector<std::string> warnings;     // the data disagree with a description (noise densities)
  std::string fingerprint;  // of the CSV files (a bag: of its samples and stamps): results name
                            // their recording
  // The markers come from the images in cam0/data/ (open_recording's from_images), not from
  // features.csv; the streams' frames then carry no markers.
  bool from_images = false;
  bool has_truth = false;  // truth.yaml was there
  RecordingTruth truth;
};

// Reads DIR for a calibration with M = markers. On bad input returns false with a message that
// names the file, the line and what is wrong; data that contradict their descriptions (timestamps
// in another unit than ns, deg/s for rad/s, g for m/s^2) are bad input too.
bool read_recording(const std::string& dir, int markers, Recording& out, std::string& error);
// The same checks without holding the streams: they are read from the files in passes of bounded
// memory (out.streams), whatever their size. A recording that changes on disk after this gives
// errors through out.streams->error().
// from_images: the markers are to be found in the images cam0/data.csv names (in cam0/data/);
// features.csv is not read, and the streams open the images too (RecordingStreams::open_images).
bool open_recording(const std::string& dir, int markers, Recording& out, std::string& error,
                    bool from_images = false);
// The number of markers DIR's mirrorcal.yaml lists (its features_c): the M a calibration of the
// recording needs. False, with a message naming the file, if camchain.yaml or mirrorcal.yaml is
// bad.
bool recording_marker_count(const std::string& dir, int& markers, std::string& error);
// Whether DIR's recording has features.csv, and whether it has images (cam0/data/ is a folder).
bool has_features_csv(const std::string& dir);
bool has_images(const std::string& dir);

// The parsers behind read_recording, on a file's text; file names the file in messages.
bool parse_imu_csv(std::string_view text, const std::string& file, std::vector<ImuSample>& out,
                   std::string& error);
// cam0/data.csv: one frame (no markers yet) per line.
bool parse_frames_csv(std::string_view text, const std::string& file,
                      std::vector<ObservedFrame>& out, std::string& error);
// features.csv: adds each row's marker to the frame of that timestamp (frames from
// parse_frames_csv, in order).
bool parse_features_csv(std::string_view text, const std::string& file, int markers,
                        std::vector<ObservedFrame>& frames, std::string& error);
bool parse_imu_yaml(std::string_view text, const std::string& file, SensorInfo& out,
                    std::vector<std::string>& notes, std::string& error);
bool parse_camchain_yaml(std::string_view text, const std::string& file, SensorInfo& out,
                         std::vector<std::string>& notes, std::string& error);
// camera: the intrinsics camchain.yaml gave (the default guess when intrinsics are estimated).
bool parse_priors_yaml(std::string_view text, const std::string& file,
                       const Pinhole<double>& camera, RecordingPriors& out,
                       std::vector<std::string>& notes, std::string& error);

// imu.yaml's text (Kalibr's keys, rostopic /imu0), which parse_imu_yaml reads back.
std::string imu_yaml_text(const SensorInfo& sensors);
// imu.yaml and camchain.yaml into dir.
bool write_sensor_yaml(const std::string& dir, const SensorInfo& sensors, std::string& error);
// mirrorcal.yaml into dir.
bool write_priors_yaml(const std::string& dir, const RecordingPriors& priors, std::string& error);
// truth.yaml into dir, and its parser.
bool write_truth_yaml(const std::string& dir, const RecordingTruth& truth, std::string& error);
bool parse_truth_yaml(std::string_view text, const std::string& file, RecordingTruth& out,
                      std::string& error);

// Where a calibration's camera pose and markers start instead of mirrorcal.yaml's guesses
// (`calibrate --from`): an earlier calibration's estimate, with the covariance of that block, as
// its mirrorcal-result.yaml holds them (SI units; rows p_b_c, rotation error, markers, and the
// time offset in results that have one).
struct CalibrationStart {
  Eigen::Vector3d p_b_c = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_b_c = Eigen::Quaterniond::Identity();
  std::vector<Eigen::Vector3d> features_c;
  bool has_t_d = false;        // results written before the time offset was estimated have none
  double t_d = 0.0;            // timeshift_cam_imu (s)
  Eigen::MatrixXd covariance;  // layout().size() square, positive definite
  // The camera the calibration ended with (`mirrorcal export`); hand-written starts may omit it.
  bool has_camera = false;
  CameraInfo camera;
  std::string recording_fingerprint;  // Recording::fingerprint of its data; empty in older results
  bool trusted = true;  // its self-check's `consistent` (true where a hand-written start has none)
  // The IMU model it estimated (its imu section's): one with intrinsics says the IMU is a MEMS
  // part whose scale factors and axes an ideal IMU's model does not cover.
  ImuModel imu_model = ImuModel::kCalibrated;
  // That model's intrinsics and their rows of the joint covariance: columns the calibration block
  // (covariance's), then the intrinsics (imu_intrinsic_names' order). Empty in results written
  // before the file carried them, and for the ideal IMU.
  ImuIntrinsics<double> imu_intrinsics{};
  Eigen::MatrixXd imu_covariance;  // imu_intrinsics_dim(imu_model) x (layout().size() + that)

  // The covariance's rows: the calibration block of these markers, without the intrinsics.
  CalibrationLayout layout() const {
    return calibration_layout(static_cast<int>(features_c.size()), 0, has_t_d);
  }
};

// Reads a mirrorcal-result.yaml (path, or a folder holding one); on bad input false with a message
// naming the file, the line and what is wrong.
bool read_calibration_result(const std::string& path, CalibrationStart& out, std::string& error);
// The same as a start for a calibration with M = markers (another number of markers is refused).
bool read_calibration_start(const std::string& path, int markers, CalibrationStart& out,
                            std::string& error);
bool parse_calibration_start(std::string_view text, const std::string& file, CalibrationStart& out,
                             std::string& error);

// The filter's prior from a recording's (false, with a message, if the file lists a number of
// markers other than M), and back.
template <int M>
bool to_prior(const RecordingPriors& r, Prior<M>& p, std::string& error) {
  if (r.features_c.size() != static_cast<std::size_t>(M) ||
      r.sigma_features_c.size() != static_cast<std::size_t>(M)) {
    error = "mirrorcal.yaml lists " + std::to_string(r.features_c.size()) +
            " markers; this build calibrates M = " + std::to_string(M);
    return false;
  }
  p.p = r.p_n_b;
  p.sigma_p = r.sigma_p_n_b;
  p.v = r.v_n_b;
  p.sigma_v = r.sigma_v_n_b;
  p.q_n_b = r.q_n_b;
  p.sigma_theta = r.sigma_rot_n_b;
  p.b_a = r.b_a;
  p.sigma_b_a = r.sigma_b_a;
  p.b_g = r.b_g;
  p.sigma_b_g = r.sigma_b_g;
  p.p_b_c = r.p_b_c;
  p.sigma_p_b_c = r.sigma_p_b_c;
  p.q_b_c = r.q_b_c;
  p.sigma_rot_b_c = r.sigma_rot_b_c;
  for (std::size_t i = 0; i < static_cast<std::size_t>(M); ++i) {
    p.markers[i] = r.features_c[i];
    p.sigma_markers[i] = r.sigma_features_c[i];
  }
  p.t_d = r.t_d;
  p.sigma_t_d = r.sigma_t_d;
  p.intrinsics = r.intrinsics_guess;
  p.sigma_intrinsics = r.sigma_intrinsics;
  p.sigma_distortion = r.sigma_distortion;
  return true;
}

template <int M>
RecordingPriors from_prior(const Prior<M>& p, const Eigen::Vector3d& gravity_n, double pixel_sigma,
                           bool estimate_intrinsics, bool hold_skew = false) {
  RecordingPriors r;
  r.gravity_n = gravity_n;
  r.pixel_sigma = pixel_sigma;
  r.p_n_b = p.p;
  r.sigma_p_n_b = p.sigma_p;
  r.v_n_b = p.v;
  r.sigma_v_n_b = p.sigma_v;
  r.q_n_b = p.q_n_b;
  r.sigma_rot_n_b = p.sigma_theta;
  r.b_a = p.b_a;
  r.sigma_b_a = p.sigma_b_a;
  r.b_g = p.b_g;
  r.sigma_b_g = p.sigma_b_g;
  r.p_b_c = p.p_b_c;
  r.sigma_p_b_c = p.sigma_p_b_c;
  r.q_b_c = p.q_b_c;
  r.sigma_rot_b_c = p.sigma_rot_b_c;
  r.features_c.assign(p.markers.begin(), p.markers.end());
  r.sigma_features_c.assign(p.sigma_markers.begin(), p.sigma_markers.end());
  r.t_d = p.t_d;
  r.sigma_t_d = p.sigma_t_d;
  r.estimate_intrinsics = estimate_intrinsics;
  r.hold_skew = hold_skew;
  r.intrinsics_guess = p.intrinsics;
  r.sigma_intrinsics = p.sigma_intrinsics;
  r.sigma_distortion = p.sigma_distortion;
  return r;
}

// Writes the streams of a recording as they come (the simulator here, the board's loop later).
// open() allocates what it needs; add_imu() and add_frame() only write (fixed buffers, POSIX calls
// for images; only the first image allocates, creating cam0/data/ and the PNG writer's buffers for
// its size, which no later image may exceed). Timestamps must increase in
// each stream, so whatever it writes reads back.
class RecordingWriter {
 public:
  RecordingWriter();
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;
  ~RecordingWriter();

  // Creates DIR/mav0/imu0 and DIR/mav0/cam0 and the CSV files with their headers (temporary
  // files until close()).
  bool open(const std::string& dir, std::string& error);
  bool add_imu(const ImuSample& sample);
  // The frame's marker observations; its image too, when there is one (into cam0/data/).
  bool add_frame(const ObservedFrame& frame, const GrayImage* image = nullptr);
  // The same from the loop's frame type, as a marker source delivers it on the board.
  template <int M>
  bool add_frame(const MarkerFrame<M>& frame, const GrayImage* image = nullptr) {
    if (!begin_frame(frame.t_ns, image)) return false;
    for (int i = 0; i < M; ++i) {
      const auto k = static_cast<std::size_t>(i);
      if (frame.seen[k]) add_feature(frame.t_ns, i, frame.uv[k].x(), frame.uv[k].y());
    }
    return true;
  }
  // Flushes and closes the files, and renames them into place if all went well (an earlier
  // recording's CSV files stay as they were otherwise); false if anything failed since open().
  bool close(std::string& error);
  const std::string& error() const { return error_; }

 private:
  struct File;
  bool fail(const char* what, const std::string& path);
  bool begin_frame(std::int64_t t_ns, const GrayImage* image);  // data.csv row and the image
  void add_feature(std::int64_t t_ns, int id, double u, double v);
  bool write_image(std::int64_t t_ns, const GrayImage& image);

  std::string dir_, images_path_, error_;
  std::unique_ptr<File> imu_, frames_, features_;
  std::unique_ptr<PngWriter> png_;
  // The CSV files, renamed into place by close(). Declared after the Files so that it goes first,
  // closing its files while their buffers still exist.
  std::unique_ptr<io::OutputSet> streams_;
  std::int64_t last_imu_ns_ = 0, last_frame_ns_ = 0;
  bool any_imu_ = false, any_frame_ = false, images_dir_ = false;
};

}  // namespace mirrorcal::io
