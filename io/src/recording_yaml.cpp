// The YAML beside a recording: Kalibr's imu.yaml and camchain.yaml, and mirrorcal.yaml (priors).
// Read with yaml-cpp; numbers parsed with std::from_chars and written in their shortest
// round-trip form, so written-then-read values are the same doubles.
#include <yaml-cpp/yaml.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <initializer_list>

#include "mirrorcal/hal/blink_code.hpp"
#include "mirrorcal/io/files.hpp"
#include "mirrorcal/io/recording.hpp"
#include "text_io.hpp"

namespace mirrorcal::io {

namespace {

// The largest 1-sigma a guess of each quantity can have: beyond it the value is in another unit
// or a typo (a marker's 1e200 m made the filter fail numerically, silently).
struct SigmaCeiling {
  double max;
  const char* unit;
};
constexpr SigmaCeiling kPositionSigma{1.0, "m"};        // camera and markers in the IMU's reach
constexpr SigmaCeiling kStartPositionSigma{10.0, "m"};  // the IMU's start before the mirror
constexpr SigmaCeiling kVelocitySigma{10.0, "m/s"};
constexpr SigmaCeiling kRotationSigma{M_PI, "rad"};
constexpr SigmaCeiling kAccelBiasSigma{10.0, "m/s^2"};
constexpr SigmaCeiling kGyroBiasSigma{1.0, "rad/s"};
constexpr SigmaCeiling kPixelSigma{100.0, "px"};
constexpr SigmaCeiling kIntrinsicsSigma{10000.0, "px"};
constexpr SigmaCeiling kDistortionSigma{1.0, "(unitless)"};

// Keys of one YAML map, read with messages that name the file, the line and the key.
class YamlMap {
 public:
  YamlMap(const std::string& file, std::string& error, std::vector<std::string>* notes = nullptr)
      : file_(file), error_(error), notes_(notes) {}

  bool load(std::string_view text) {
    try {
      root_ = YAML::Load(std::string(text));
    } catch (const YAML::Exception& e) {
      error_ = file_ + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg;
      return false;
    }
    if (!root_.IsMap()) {
      error_ = file_ + ": expected a map of keys at the top level";
      return false;
    }
    return true;
  }
  bool sub(const YamlMap& parent, const char* key) {
    const YAML::Node n = parent.root_[key];
    if (!n) return parent.missing(key);
    if (!n.IsMap()) return parent.fail(n, key, "expected a map of keys");
    root_ = n;
    prefix_ = parent.prefix_ + key + ".";
    return true;
  }
  bool has(const char* key) const { return static_cast<bool>(root_[key]); }
  YAML::Node node(const char* key) const { return root_[key]; }

  // Notes keys not in known (typos would otherwise pass as defaults).
  void unknown_keys(std::initializer_list<const char*> known) const {
    if (notes_ == nullptr) return;
    for (const auto& kv : root_) {
      const std::string k = kv.first.IsScalar() ? kv.first.Scalar() : "?";
      if (std::none_of(known.begin(), known.end(), [&](const char* s) { return k == s; }))
        notes_->push_back(file_ + ":" + line(kv.first) + ": unknown key " + text::quoted(k) +
                          " ignored");
    }
  }

  bool number(const char* key, double& v) const {
    const YAML::Node n = root_[key];
    if (!n) return missing(key);
    return scalar(n, key, v);
  }
  bool positive(const char* key, double& v) const {
    if (!number(key, v)) return false;
    return v > 0.0 || fail(root_[key], key, "must be > 0");
  }
  // A number within lo..hi (unit in the message).
  bool within(const char* key, double lo, double hi, const char* unit, double& v) const {
    if (!number(key, v)) return false;
    if (v >= lo && v <= hi) return true;
    std::string range;
    text::append(range, lo);
    range += "..";
    text::append(range, hi);
    return fail(
        root_[key], key,
        "must lie within " + range + " " + unit + ", not " + text::quoted(root_[key].Scalar()));
  }
  bool integer(const YAML::Node& n, const char* key, std::int64_t& v) const {
    if (!n.IsScalar() || !text::parse(n.Scalar(), v)) return fail(n, key, "expected an integer");
    return true;
  }
  bool flag(const char* key, bool& v) const {
    const YAML::Node n = root_[key];
    if (!n) return missing(key);
    if (!n.IsScalar() || !YAML::convert<bool>::decode(n, v))
      return fail(n, key, "expected true or false");
    return true;
  }
  bool string(const char* key, std::string& v) const {
    const YAML::Node n = root_[key];
    if (!n) return missing(key);
    if (!n.IsScalar()) return fail(n, key, "expected a string");
    v = n.Scalar();
    return true;
  }
  // A sequence of exactly n numbers.
  bool numbers(const YAML::Node& n, const char* key, std::size_t count, double* v) const {
    if (!n.IsSequence() || n.size() != count)
      return fail(n, key, "expected a list of " + std::to_string(count) + " numbers");
    for (std::size_t i = 0; i < count; ++i)
      if (!scalar(n[i], key, v[i])) return false;
    return true;
  }
  bool numbers(const char* key, std::size_t count, double* v) const {
    const YAML::Node n = root_[key];
    if (!n) return missing(key);
    return numbers(n, key, count, v);
  }
  bool vec3(const char* key, Eigen::Vector3d& v) const { return numbers(key, 3, v.data()); }
  // A list of `rows` rows of `cols` numbers each, every row's length checked before m is sized (a
  // damaged file could list many).
  bool matrix(const char* key, std::size_t rows, std::size_t cols, Eigen::MatrixXd& m) const {
    const YAML::Node n = root_[key];
    if (!n) return missing(key);
    if (!n.IsSequence() || n.size() != rows)
      return fail(n, key, "expected " + std::to_string(rows) + " rows");
    for (std::size_t i = 0; i < rows; ++i)
      if (!n[i].IsSequence() || n[i].size() != cols)
        return fail(n[i], key, "expected a list of " + std::to_string(cols) + " numbers");
    m.resize(long(rows), long(cols));
    std::vector<double> row(cols);
    for (std::size_t i = 0; i < rows; ++i) {
      if (!numbers(n[i], key, cols, row.data())) return false;
      for (std::size_t j = 0; j < cols; ++j) m(long(i), long(j)) = row[j];
    }
    return true;
  }
  // A 1-sigma per axis: three numbers, or one for all axes; each > 0 and at most the ceiling.
  bool sigma3(const YAML::Node& n, const char* key, SigmaCeiling ceiling,
              Eigen::Vector3d& v) const {
    double s = 0.0;
    if (n.IsScalar()) {
      if (!scalar(n, key, s)) return false;
      v.setConstant(s);
    } else if (!numbers(n, key, 3, v.data())) {
      return false;
    }
    if (!(v.minCoeff() > 0.0)) return fail(n, key, "every 1-sigma must be > 0");
    return below_ceiling(n, key, ceiling, v.maxCoeff());
  }
  bool sigma3(const char* key, SigmaCeiling ceiling, Eigen::Vector3d& v) const {
    const YAML::Node n = root_[key];
    if (!n) return missing(key);
    return sigma3(n, key, ceiling, v);
  }
  bool below_ceiling(const YAML::Node& n, const char* key, SigmaCeiling ceiling,
                     double sigma) const {
    if (sigma <= ceiling.max) return true;
    std::string what = "a 1-sigma of ";
    text::append(what, sigma);
    what += std::string(" ") + ceiling.unit + " is no guess (at most ";
    text::append(what, ceiling.max);
    return fail(n, key, what + " " + ceiling.unit + "; another unit?)");
  }
  // A unit quaternion [w, x, y, z] (Hamilton); up to 1e-3 off unit norm is accepted as rounding.
  bool quaternion(const char* key, Eigen::Quaterniond& q) const {
    double v[4];
    if (!numbers(key, 4, v)) return false;
    q = Eigen::Quaterniond(v[0], v[1], v[2], v[3]);
    if (std::abs(q.norm() - 1.0) > 1e-3)
      return fail(root_[key], key,
                  "expected a unit quaternion [w, x, y, z], norm is " + std::to_string(q.norm()));
    return true;
  }
  // A list of count [x, y, z] (count < 0: any number, at least one).
  bool vec3_list(const char* key, std::vector<Eigen::Vector3d>& out,
                 const SigmaCeiling* sigma = nullptr, long count = -1) const {
    const YAML::Node n = root_[key];
    if (!n) return missing(key);
    if (!n.IsSequence() || n.size() == 0) return fail(n, key, "expected a list of [x, y, z]");
    if (count >= 0 && n.size() != static_cast<std::size_t>(count))
      return fail(n, key,
                  "lists " + std::to_string(n.size()) + " entries, features_c lists " +
                      std::to_string(count));
    out.assign(n.size(), Eigen::Vector3d::Zero());
    for (std::size_t i = 0; i < n.size(); ++i) {
      const bool ok =
          sigma ? sigma3(n[i], key, *sigma, out[i]) : numbers(n[i], key, 3, out[i].data());
      if (!ok) return false;
    }
    return true;
  }

  void note_default(const char* key, const std::string& value) const {
    if (notes_ != nullptr)
      notes_->push_back(file_ + ": " + prefix_ + key + " not given; using the default " + value);
  }
  bool missing(const char* key) const {
    error_ = file_ + ": missing required key '" + prefix_ + key + "'";
    return false;
  }
  bool fail(const YAML::Node& n, const char* key, const std::string& what) const {
    error_ = file_ + ":" + line(n) + ": " + prefix_ + key + ": " + what;
    return false;
  }

 private:
  static std::string line(const YAML::Node& n) {
    const YAML::Mark m = n.Mark();
    return m.is_null() ? "?" : std::to_string(m.line + 1);
  }
  bool scalar(const YAML::Node& n, const char* key, double& v) const {
    if (!n.IsScalar() || !text::parse(n.Scalar(), v))
      return fail(n, key,
                  "expected a number" +
                      (n.IsScalar() ? ", not " + text::quoted(n.Scalar()) : std::string()));
    if (!std::isfinite(v)) return fail(n, key, text::quoted(n.Scalar()) + " is not finite");
    return true;
  }

  const std::string& file_;
  std::string& error_;
  std::vector<std::string>* notes_;
  YAML::Node root_;
  std::string prefix_;
};

// "[a, b, c]" in shortest round-trip form.
std::string list(const double* v, std::size_t n) {
  std::string s = "[";
  for (std::size_t i = 0; i < n; ++i) {
    if (i > 0) s += ", ";
    text::append(s, v[i]);
  }
  return s + "]";
}
std::string list(const Eigen::Vector3d& v) {
  return list(v.data(), 3);
}
std::string number(double v) {
  std::string s;
  text::append(s, v);
  return s;
}
std::string wxyz(const Eigen::Quaterniond& q) {
  const double v[4] = {q.w(), q.x(), q.y(), q.z()};
  return list(v, 4);
}
std::array<double, 5> as_array(const Pinhole<double>& k) {
  return {k.fu, k.fv, k.cu, k.cv, k.skew};
}

}  // namespace

namespace {

// imu.yaml's IMU model and tolerances (mirrorcal's keys), each optional. A tolerance is the
// datasheet's 1-sigma, relative for scale factors and cross-axis sensitivity (1 % = 0.01, about
// 0.57 deg for an axis's tilt), (rad/s)/(m/s^2) for the g-sensitivity; one of 20 % or more is no
// trimmed part's (or a percentage given as a number).
// An IMU model's name at key (imu_intrinsics.hpp).
bool imu_model_key(const YamlMap& y, const char* key, ImuModel& model) {
  std::string name;
  if (!y.string(key, name)) return false;
  if (imu_model_from_string(name, model)) return true;
  return y.fail(y.node(key), key,
                text::quoted(name) +
                    " is not an IMU model (calibrated, scale-misalignment, "
                    "scale-misalignment-rotation, scale-misalignment-rotation-g-sensitivity)");
}

bool parse_imu_model_keys(const YamlMap& y, SensorInfo& out) {
  if (y.has("imu_model")) {
    ImuModel model = ImuModel::kCalibrated;
    if (!imu_model_key(y, "imu_model", model)) return false;
    out.imu_model = model;
  }
  ImuIntrinsicsSigma& t = out.imu_tolerances;
  const std::pair<const char*, double*> keys[] = {
      {"accelerometer_scale_tolerance", &t.accel_scale},
      {"accelerometer_cross_axis_tolerance", &t.accel_misalignment},
      {"gyroscope_scale_tolerance", &t.gyro_scale},
      {"gyroscope_cross_axis_tolerance", &t.gyro_misalignment},
      {"gyroscope_g_sensitivity", &t.g_sensitivity}};
  bool any_default = false;
  for (const auto& [key, value] : keys) {
    if (!y.has(key)) {
      any_default = true;
      continue;
    }
    if (!y.positive(key, *value)) return false;
    if (*value >= 0.2)
      return y.fail(y.node(key), key,
                    "a 1-sigma of 20 % or more is no MEMS part's (0.01 is 1 %: a fraction, not a "
                    "percentage)");
  }
  out.imu_tolerances_defaulted = any_default;
  return true;
}

}  // namespace

bool parse_imu_yaml(std::string_view text, const std::string& file, SensorInfo& out,
                    std::vector<std::string>& notes, std::string& error) {
  YamlMap y(file, error, &notes);
  return y.load(text) && y.positive("accelerometer_noise_density", out.imu.accel_noise_density) &&
         y.positive("accelerometer_random_walk", out.imu.accel_random_walk) &&
         y.positive("gyroscope_noise_density", out.imu.gyro_noise_density) &&
         y.positive("gyroscope_random_walk", out.imu.gyro_random_walk) &&
         y.within("update_rate", kMinImuRateHz, kMaxImuRateHz, "Hz", out.imu_rate_hz) &&
         (!y.has("rostopic") || y.string("rostopic", out.imu_rostopic)) &&
         parse_imu_model_keys(y, out);
}

namespace {

// The shutter: a rolling shutter's line_delay (s per row, default 0: a global shutter) and the
// exposure_time (s, the stamp at its middle; default 0: not modelled). Real sensors read a row in
// 5-100 us; a whole frame's readout or an exposure beyond 0.1 s is no camera for this (or
// microseconds or milliseconds given as seconds).
bool parse_shutter(const YamlMap& cam, CameraInfo& out) {
  double& line_delay = out.intrinsics.line_delay_s;
  double& exposure = out.intrinsics.exposure_s;
  line_delay = 0.0;
  exposure = 0.0;
  if (cam.has("line_delay")) {
    if (!cam.number("line_delay", line_delay)) return false;
    if (!(line_delay >= 0.0 && line_delay * out.height <= 0.1))
      return cam.fail(cam.node("line_delay"), "line_delay",
                      "must be seconds per row, from 0 (global shutter) to a readout of 0.1 s over "
                      "the image's " +
                          std::to_string(out.height) + " rows");
  }
  if (cam.has("exposure_time")) {
    if (!cam.number("exposure_time", exposure)) return false;
    if (!(exposure >= 0.0 && exposure <= 0.1))
      return cam.fail(cam.node("exposure_time"), "exposure_time",
                      "must be the frames' exposure in seconds, from 0 (not modelled) to 0.1");
  }
  return true;
}

// The camera keys camchain.yaml's cam0 and mirrorcal-result.yaml share: intrinsics, skew (under
// skew_key, 0 if absent), resolution, the lens and the topic.
bool read_camera(const YamlMap& cam, const char* skew_key, CameraInfo& out) {
  double k[4];
  if (!cam.numbers("intrinsics", 4, k)) return false;
  out.intrinsics = {k[0], k[1], k[2], k[3], 0.0};
  if (cam.has(skew_key)) {
    if (!cam.number(skew_key, out.intrinsics.skew)) return false;
  } else {
    cam.note_default(skew_key, "0 px");
  }
  double res[2];
  if (!cam.numbers("resolution", 2, res)) return false;
  if (res[0] < 1 || res[1] < 1 || res[0] > 1e5 || res[1] > 1e5 || res[0] != std::floor(res[0]) ||
      res[1] != std::floor(res[1]))
    return cam.fail(cam.node("resolution"), "resolution",
                    "expected two positive integers [width, height]");
  out.width = static_cast<int>(res[0]);
  out.height = static_cast<int>(res[1]);
  out.rostopic = kDefaultCameraTopic;
  if (cam.has("rostopic") && !cam.string("rostopic", out.rostopic)) return false;
  // The lens: Kalibr's pinhole distortion models, the features being raw (distorted) pixels.
  Distortion& d = out.intrinsics.distortion;
  if (cam.has("distortion_model")) {
    std::string name;
    if (!cam.string("distortion_model", name)) return false;
    if (!distortion_from_string(name, d))
      return cam.fail(cam.node("distortion_model"), "distortion_model",
                      text::quoted(name) + " is not supported (radtan, equidistant or none)");
  } else {
    d = Distortion::kNone;
    cam.note_default("distortion_model", "none");
  }
  double c[4] = {0.0, 0.0, 0.0, 0.0};
  if (cam.has("distortion_coeffs")) {
    const YAML::Node n = cam.node("distortion_coeffs");
    // "none" with an empty or all-zero list, as some tools write it.
    if (d == Distortion::kNone && n.IsSequence() && n.size() == 0) return parse_shutter(cam, out);
    if (!cam.numbers("distortion_coeffs", 4, c)) return false;
    if (d == Distortion::kNone && (c[0] != 0.0 || c[1] != 0.0 || c[2] != 0.0 || c[3] != 0.0))
      return cam.fail(n, "distortion_coeffs",
                      "given without a distortion_model (radtan or equidistant)");
  } else if (d != Distortion::kNone) {
    return cam.missing("distortion_coeffs");
  }
  out.intrinsics.coeffs = {c[0], c[1], c[2], c[3]};
  // radtan with zero coefficients (how Kalibr and we write an undistorted camera) is no lens.
  if (d == Distortion::kRadtan && c[0] == 0.0 && c[1] == 0.0 && c[2] == 0.0 && c[3] == 0.0)
    d = Distortion::kNone;
  return parse_shutter(cam, out);
}

}  // namespace

bool parse_camchain_yaml(std::string_view text, const std::string& file, SensorInfo& out,
                         std::vector<std::string>& notes, std::string& error) {
  YamlMap top(file, error, &notes), cam(file, error, &notes);
  if (!top.load(text) || !cam.sub(top, "cam0")) return false;
  // A Kalibr camchain of several cameras: mirrorcal calibrates one, and taking cam0 silently would
  // leave the user believing the others calibrated.
  if (top.has("cam1"))
    return top.fail(top.node("cam1"), "cam1",
                    "a second camera; mirrorcal calibrates one camera, cam0: give a camchain.yaml "
                    "with cam0 alone (each camera is calibrated from its own recording)");
  std::string model;
  if (!cam.string("camera_model", model)) return false;
  if (model != "pinhole")
    return cam.fail(cam.node("camera_model"), "camera_model",
                    text::quoted(model) + " is not supported (mirrorcal models a pinhole)");
  return read_camera(cam, "intrinsics_skew", out);
}

namespace {

// The markers' LEDs (led_brightness, blink_period, led_lines): each list one entry per marker.
bool read_leds(const YamlMap& y, RecordingPriors& r) {
  const std::size_t m = r.features_c.size();
  const auto per_marker = [&](const char* key, const YAML::Node& n) {
    return (n.IsSequence() && n.size() == m) ||
           y.fail(n, key, "expected a list of " + std::to_string(m) + " entries, one per marker");
  };
  if (y.has("led_brightness")) {
    if (!per_marker("led_brightness", y.node("led_brightness"))) return false;
    r.leds.brightness.assign(m, 0.0);
    if (!y.numbers("led_brightness", m, r.leds.brightness.data())) return false;
    if (*std::min_element(r.leds.brightness.begin(), r.leds.brightness.end()) <= 0.0)
      return y.fail(y.node("led_brightness"), "led_brightness", "every brightness must be > 0");
  }
  if (y.has("blink_period")) {
    std::int64_t period = 0;
    if (!y.integer(y.node("blink_period"), "blink_period", period)) return false;
    if (period < static_cast<std::int64_t>(m) + 1 || period > hal::BlinkCode::kMaxPeriod)
      return y.fail(y.node("blink_period"), "blink_period",
                    "must be " + std::to_string(m + 1) + ".." +
                        std::to_string(hal::BlinkCode::kMaxPeriod) + " frames (each of the " +
                        std::to_string(m) + " markers dark in one, one with all lit)");
    r.leds.blink_period = static_cast<int>(period);
  }
  if (y.has("led_lines")) {
    const YAML::Node n = y.node("led_lines");
    if (!per_marker("led_lines", n)) return false;
    for (const YAML::Node& line : n) {
      if (!line.IsScalar() || line.Scalar().empty())
        return y.fail(line, "led_lines", "expected a GPIO line, CHIP:LINE (gpiochip0:17)");
      r.leds.lines.push_back(line.Scalar());
    }
    if (r.leds.blink_period == 0)
      return y.fail(n, "led_lines",
                    "needs blink_period: the LEDs on these lines blink their names in that code");
  }
  return true;
}

}  // namespace

bool parse_priors_yaml(std::string_view text, const std::string& file,
                       const Pinhole<double>& camera, RecordingPriors& out,
                       std::vector<std::string>& notes, std::string& error) {
  YamlMap y(file, error, &notes);
  if (!y.load(text)) return false;
  y.unknown_keys({"gravity_n",
                  "pixel_sigma",
                  "p_n_b",
                  "sigma_p_n_b",
                  "v_n_b",
                  "sigma_v_n_b",
                  "q_n_b_wxyz",
                  "sigma_rot_n_b",
                  "b_a",
                  "sigma_b_a",
                  "b_g",
                  "sigma_b_g",
                  "p_b_c",
                  "sigma_p_b_c",
                  "q_b_c_wxyz",
                  "sigma_rot_b_c",
                  "features_c",
                  "sigma_features_c",
                  "estimate_intrinsics",
                  "hold_skew",
                  "intrinsics_guess",
                  "sigma_intrinsics",
                  "timeshift_cam_imu",
                  "sigma_timeshift_cam_imu",
                  "estimate_distortion",
                  "sigma_distortion",
                  "led_brightness",
                  "blink_period",
                  "led_lines"});
  RecordingPriors r;
  if (!y.vec3("gravity_n", r.gravity_n) || !y.vec3("p_n_b", r.p_n_b) ||
      !y.sigma3("sigma_p_n_b", kStartPositionSigma, r.sigma_p_n_b) || !y.vec3("v_n_b", r.v_n_b) ||
      !y.sigma3("sigma_v_n_b", kVelocitySigma, r.sigma_v_n_b) ||
      !y.quaternion("q_n_b_wxyz", r.q_n_b) ||
      !y.sigma3("sigma_rot_n_b", kRotationSigma, r.sigma_rot_n_b) || !y.vec3("p_b_c", r.p_b_c) ||
      !y.sigma3("sigma_p_b_c", kPositionSigma, r.sigma_p_b_c) ||
      !y.quaternion("q_b_c_wxyz", r.q_b_c) ||
      !y.sigma3("sigma_rot_b_c", kRotationSigma, r.sigma_rot_b_c) ||
      !y.vec3_list("features_c", r.features_c) ||
      !y.vec3_list("sigma_features_c", r.sigma_features_c, &kPositionSigma,
                   static_cast<long>(r.features_c.size())))
    return false;
  // Optional keys, with the defaults the filter's prior uses.
  const auto optional_vec3 = [&](const char* key, Eigen::Vector3d& v, const Eigen::Vector3d& def,
                                 const char* shown, const SigmaCeiling* sigma) {
    if (!y.has(key)) {
      v = def;
      y.note_default(key, shown);
      return true;
    }
    return sigma ? y.sigma3(key, *sigma, v) : y.vec3(key, v);
  };
  if (!optional_vec3("b_a", r.b_a, Eigen::Vector3d::Zero(), "[0, 0, 0] m/s^2", nullptr) ||
      !optional_vec3("sigma_b_a", r.sigma_b_a, Eigen::Vector3d::Constant(0.03), "0.03 m/s^2",
                     &kAccelBiasSigma) ||
      !optional_vec3("b_g", r.b_g, Eigen::Vector3d::Zero(), "[0, 0, 0] rad/s", nullptr) ||
      !optional_vec3("sigma_b_g", r.sigma_b_g, Eigen::Vector3d::Constant(0.002), "0.002 rad/s",
                     &kGyroBiasSigma))
    return false;
  // The time offset and its 1-sigma, in seconds: beyond 1 s (more than the loop believes) a value
  // is in the wrong unit.
  const auto optional_seconds = [&](const char* key, double& v, double def, const char* shown,
                                    bool sigma) {
    if (!y.has(key)) {
      v = def;
      y.note_default(key, shown);
      return true;
    }
    if (!(sigma ? y.positive(key, v) : y.number(key, v))) return false;
    return std::abs(v) < 1.0 ||
           y.fail(y.node(key), key,
                  "must lie within +-1 s (seconds: t_imu = t_cam + timeshift_cam_imu)");
  };
  if (!optional_seconds("timeshift_cam_imu", r.t_d, 0.0, "0 s", false) ||
      !optional_seconds("sigma_timeshift_cam_imu", r.sigma_t_d, 0.02, "0.02 s", true))
    return false;
  if (y.has("pixel_sigma")) {
    if (!y.positive("pixel_sigma", r.pixel_sigma) ||
        !y.below_ceiling(y.node("pixel_sigma"), "pixel_sigma", kPixelSigma, r.pixel_sigma))
      return false;
  } else {
    r.pixel_sigma = 1.0;
    y.note_default("pixel_sigma", "1 px");
  }
  r.estimate_intrinsics = false;
  if (y.has("estimate_intrinsics") && !y.flag("estimate_intrinsics", r.estimate_intrinsics))
    return false;
  r.hold_skew = false;
  if (y.has("hold_skew") && !y.flag("hold_skew", r.hold_skew)) return false;
  // The intrinsics' guess and 1-sigma matter only when they are estimated; say so only then.
  if (y.has("intrinsics_guess")) {
    double k[5];
    if (!y.numbers("intrinsics_guess", 5, k)) return false;
    r.intrinsics_guess = {k[0], k[1], k[2], k[3], k[4]};
  } else {
    r.intrinsics_guess = camera;
    if (r.estimate_intrinsics) y.note_default("intrinsics_guess", "of camchain.yaml");
  }
  if (y.has("sigma_intrinsics")) {
    if (!y.numbers("sigma_intrinsics", 5, r.sigma_intrinsics.data())) return false;
    if (*std::min_element(r.sigma_intrinsics.begin(), r.sigma_intrinsics.end()) <= 0.0)
      return y.fail(y.node("sigma_intrinsics"), "sigma_intrinsics", "every 1-sigma must be > 0");
    if (!y.below_ceiling(y.node("sigma_intrinsics"), "sigma_intrinsics", kIntrinsicsSigma,
                         *std::max_element(r.sigma_intrinsics.begin(), r.sigma_intrinsics.end())))
      return false;
  } else {
    r.sigma_intrinsics = {100.0, 100.0, 100.0, 100.0, 100.0};
    if (r.estimate_intrinsics) y.note_default("sigma_intrinsics", "100 px each (the paper's)");
  }
  // The lens is camchain.yaml's; estimate_distortion starts its coefficients there.
  r.intrinsics_guess.distortion = camera.distortion;
  r.intrinsics_guess.coeffs = camera.coeffs;
  r.estimate_distortion = false;
  if (y.has("estimate_distortion")) {
    if (!y.flag("estimate_distortion", r.estimate_distortion)) return false;
    if (r.estimate_distortion && !r.estimate_intrinsics)
      return y.fail(y.node("estimate_distortion"), "estimate_distortion",
                    "needs estimate_intrinsics: true (the coefficients are estimated with the "
                    "intrinsics, in stage 2)");
    if (r.estimate_distortion && camera.distortion == Distortion::kNone)
      return y.fail(y.node("estimate_distortion"), "estimate_distortion",
                    "needs a lens model: camchain.yaml's distortion_model is none (give radtan or "
                    "equidistant, with its distortion_coeffs as the guess)");
  }
  if (y.has("sigma_distortion")) {
    if (!y.numbers("sigma_distortion", 4, r.sigma_distortion.data())) return false;
    if (*std::min_element(r.sigma_distortion.begin(), r.sigma_distortion.end()) <= 0.0)
      return y.fail(y.node("sigma_distortion"), "sigma_distortion", "every 1-sigma must be > 0");
    if (!y.below_ceiling(y.node("sigma_distortion"), "sigma_distortion", kDistortionSigma,
                         *std::max_element(r.sigma_distortion.begin(), r.sigma_distortion.end())))
      return false;
  } else {
    r.sigma_distortion = default_sigma_distortion(camera.distortion);
    if (r.estimate_distortion)
      y.note_default("sigma_distortion", camera.distortion == Distortion::kEquidistant
                                             ? "0.05 each (k1..k4)"
                                             : "0.2, 0.1, 0.002, 0.002 (k1, k2, p1, p2)");
  }
  if (!read_leds(y, r)) return false;
  out = std::move(r);
  return true;
}

bool write_sensor_yaml(const std::string& dir, const SensorInfo& s, std::string& error) {
  const std::string imu = imu_yaml_text(s);
  const auto k = as_array(s.intrinsics);
  std::string cam = "# Kalibr camera description (pixels: origin at the top-left pixel's centre)\n";
  cam += "cam0:\n  camera_model: pinhole\n  intrinsics: " + list(k.data(), 4) + "\n";
  cam += "  intrinsics_skew: " + number(s.intrinsics.skew) + "\n";
  cam += std::string("  distortion_model: ") + kalibr_lens_name(s.intrinsics.distortion) + "\n";
  cam += "  distortion_coeffs: " + list(s.intrinsics.coeffs.data(), 4) + "\n";
  cam += "  resolution: [" + std::to_string(s.width) + ", " + std::to_string(s.height) + "]\n";
  cam +=
      "  line_delay: " + number(s.intrinsics.line_delay_s) + "  # s per row; 0: global shutter\n";
  cam += "  exposure_time: " + number(s.intrinsics.exposure_s) +
         "  # s, the stamp at its middle; 0: not modelled\n";
  cam += "  rostopic: " + s.rostopic + "\n";
  return io::write_file(dir + "/imu.yaml", imu, error) &&
         io::write_file(dir + "/camchain.yaml", cam, error);
}

bool write_priors_yaml(const std::string& dir, const RecordingPriors& r, std::string& error) {
  std::string t =
      "# mirrorcal priors: what is known before calibrating (docs/recordings.md, "
      "\"mirrorcal.yaml\").\n"
      "# SI units (m, m/s, rad, m/s^2, rad/s, px); quaternions Hamilton [w, x, y, z];\n"
      "# sigma_* are 1-sigma per axis (rotations: of the error vector, R = R_guess Exp(e)).\n";
  t += "gravity_n: " + list(r.gravity_n) + "\n";
  t += "pixel_sigma: " + number(r.pixel_sigma) + "\n";
  t += "p_n_b: " + list(r.p_n_b) + "\nsigma_p_n_b: " + list(r.sigma_p_n_b) + "\n";
  t += "v_n_b: " + list(r.v_n_b) + "\nsigma_v_n_b: " + list(r.sigma_v_n_b) + "\n";
  t += "q_n_b_wxyz: " + wxyz(r.q_n_b) + "\nsigma_rot_n_b: " + list(r.sigma_rot_n_b) + "\n";
  t += "b_a: " + list(r.b_a) + "\nsigma_b_a: " + list(r.sigma_b_a) + "\n";
  t += "b_g: " + list(r.b_g) + "\nsigma_b_g: " + list(r.sigma_b_g) + "\n";
  t += "p_b_c: " + list(r.p_b_c) + "\nsigma_p_b_c: " + list(r.sigma_p_b_c) + "\n";
  t += "q_b_c_wxyz: " + wxyz(r.q_b_c) + "\nsigma_rot_b_c: " + list(r.sigma_rot_b_c) + "\n";
  t += "features_c:\n";
  for (const auto& f : r.features_c) t += "  - " + list(f) + "\n";
  t += "sigma_features_c:\n";
  for (const auto& f : r.sigma_features_c) t += "  - " + list(f) + "\n";
  t += "timeshift_cam_imu: " + number(r.t_d) + "  # s: t_imu = t_cam + timeshift_cam_imu\n";
  t += "sigma_timeshift_cam_imu: " + number(r.sigma_t_d) + "\n";
  t += std::string("estimate_intrinsics: ") + (r.estimate_intrinsics ? "true" : "false") + "\n";
  t += std::string("hold_skew: ") + (r.hold_skew ? "true" : "false") +
       "  # with estimate_intrinsics: skew stays at camchain.yaml's intrinsics_skew\n";
  const auto k = as_array(r.intrinsics_guess);
  t += "intrinsics_guess: " + list(k.data(), 5) + "  # fu, fv, cu, cv, skew (px)\n";
  t += "sigma_intrinsics: " + list(r.sigma_intrinsics.data(), 5) + "\n";
  if (r.estimate_distortion) {
    t += "estimate_distortion: true  # the lens's coefficients too, from camchain.yaml's\n";
    t += "sigma_distortion: " + list(r.sigma_distortion.data(), 4) + "\n";
  }
  if (!r.leds.brightness.empty())
    t += "led_brightness: " + list(r.leds.brightness.data(), r.leds.brightness.size()) +
         "  # relative, one per marker; all equal: identical LEDs\n";
  if (r.leds.blink_period > 0)
    t += "blink_period: " + std::to_string(r.leds.blink_period) +
         "  # frames: marker i's LED dark in frame i + 1 of each period\n";
  if (!r.leds.lines.empty()) {
    t += "led_lines: [";
    for (std::size_t i = 0; i < r.leds.lines.size(); ++i)
      t += (i > 0 ? ", " : "") + r.leds.lines[i];
    t += "]  # marker i's LED, CHIP:LINE\n";
  }
  return io::write_file(dir + "/mirrorcal.yaml", t, error);
}

bool write_truth_yaml(const std::string& dir, const RecordingTruth& t, std::string& error) {
  std::string y =
      "# The truth of a simulated recording (SI units, px): calibrate reports its error.\n";
  y += "p_b_c: " + list(t.p_b_c) + "\nq_b_c_wxyz: " + wxyz(t.q_b_c) + "\nfeatures_c:\n";
  for (const auto& f : t.features_c) y += "  - " + list(f) + "\n";
  const auto k = as_array(t.intrinsics);
  y += "intrinsics: " + list(k.data(), 5) + "  # fu, fv, cu, cv, skew\n";
  y += "timeshift_cam_imu: " + number(t.t_d) + "  # s\n";
  if (t.has_distortion)
    y += "distortion_coeffs: " + list(t.intrinsics.coeffs.data(), 4) +
         "  # the lens's (camchain.yaml holds the guess)\n";
  return io::write_file(dir + "/truth.yaml", y, error);
}

bool parse_truth_yaml(std::string_view text, const std::string& file, RecordingTruth& out,
                      std::string& error) {
  YamlMap y(file, error);
  double k[5];
  if (!y.load(text) || !y.vec3("p_b_c", out.p_b_c) || !y.quaternion("q_b_c_wxyz", out.q_b_c) ||
      !y.vec3_list("features_c", out.features_c) || !y.numbers("intrinsics", 5, k))
    return false;
  out.intrinsics = {k[0], k[1], k[2], k[3], k[4]};
  out.t_d = 0.0;
  if (y.has("timeshift_cam_imu") && !y.number("timeshift_cam_imu", out.t_d)) return false;
  out.has_distortion = y.has("distortion_coeffs");
  return !out.has_distortion || y.numbers("distortion_coeffs", 4, out.intrinsics.coeffs.data());
}

namespace {

// The IMU's intrinsics a result estimated and their rows of the joint covariance (its imu section:
// T_a, T_g, T_s and covariance, whose columns are the result's `dim` calibration states, then the
// intrinsics), as the start of a later calibration takes them: the block up to the camera's
// intrinsics, then theirs. Results written before the file carried the rows have none.
bool parse_start_imu_intrinsics(const YamlMap& imu, std::size_t dim, CalibrationStart& out) {
  const auto ni = static_cast<std::size_t>(imu_intrinsics_dim(out.imu_model));
  if (ni == 0 || !imu.has("covariance")) return true;
  Eigen::MatrixXd t_a, t_g, t_s, rows;
  if (!imu.matrix("T_a", 3, 3, t_a) || !imu.matrix("T_g", 3, 3, t_g) ||
      !imu.matrix("T_s", 3, 3, t_s) || !imu.matrix("covariance", ni, dim + ni, rows))
    return false;
  const long n = out.covariance.rows(), k = long(ni);
  Eigen::MatrixXd joint(n + k, n + k);
  joint << out.covariance, rows.leftCols(n).transpose(), rows.leftCols(n), rows.rightCols(k);
  const double scale = joint.diagonal().cwiseAbs().maxCoeff();
  if ((rows.rightCols(k) - rows.rightCols(k).transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale)
    return imu.fail(imu.node("covariance"), "covariance", "is not symmetric");
  if (joint.llt().info() != Eigen::Success)
    return imu.fail(imu.node("covariance"), "covariance",
                    "is not positive definite with the calibration states' covariance");
  if (t_a.determinant() <= 0.0 || t_g.determinant() <= 0.0)
    return imu.fail(imu.node("T_a"), "T_a", "and T_g must have a positive determinant");
  // The model's entries only: the file's rounding leaves the others a few 1e-13 from zero.
  out.imu_intrinsics.d_a = t_a.inverse().triangularView<Eigen::Lower>();
  out.imu_intrinsics.d_g = t_g.inverse();
  if (ni < 15) out.imu_intrinsics.d_g = out.imu_intrinsics.d_g.triangularView<Eigen::Lower>();
  out.imu_intrinsics.t_s = ni < 24 ? Eigen::Matrix3d::Zero() : Eigen::Matrix3d(t_s);
  out.imu_covariance.resize(k, n + k);
  out.imu_covariance << rows.leftCols(n), rows.rightCols(k);
  return true;
}

}  // namespace

bool parse_calibration_start(std::string_view text, const std::string& file, CalibrationStart& out,
                             std::string& error) {
  YamlMap y(file, error);
  if (!y.load(text) || !y.vec3("p_b_c", out.p_b_c) || !y.quaternion("q_b_c_wxyz", out.q_b_c) ||
      !y.vec3_list("features_c", out.features_c))
    return false;
  // Results written before the covariance was added to the file lack it.
  if (!y.has("covariance")) return y.missing("covariance");
  // The calibration block: p_b_c, rotation, markers, the time offset (results written before it
  // was estimated have none), then the intrinsics it estimated (if any).
  out.has_t_d = y.has("timeshift_cam_imu");
  if (out.has_t_d && !y.number("timeshift_cam_imu", out.t_d)) return false;
  const auto n = static_cast<std::size_t>(out.layout().size());
  const YAML::Node rows = y.node("covariance");
  const std::size_t dim = rows.IsSequence() ? rows.size() : 0;
  if (dim != n && dim != n + 4 && dim != n + 5 && dim != n + 8)
    return y.fail(rows, "covariance",
                  "expected " + std::to_string(n) + " rows (p_b_c, rotation, " +
                      std::to_string(out.features_c.size()) +
                      (out.features_c.size() == 1 ? " marker" : " markers") +
                      (out.has_t_d ? ", time offset), " : "), ") + std::to_string(n + 4) + ", " +
                      std::to_string(n + 5) + " (and intrinsics) or " + std::to_string(n + 8) +
                      " (and the lens)");
  Eigen::MatrixXd full;
  if (!y.matrix("covariance", dim, dim, full)) return false;
  out.covariance = full.topLeftCorner(long(n), long(n));
  const double scale = out.covariance.diagonal().cwiseAbs().maxCoeff();
  if ((out.covariance - out.covariance.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale)
    return y.fail(rows, "covariance", "is not symmetric");
  if (out.covariance.llt().info() != Eigen::Success)
    return y.fail(rows, "covariance", "is not positive definite");
  out.recording_fingerprint.clear();
  if (y.has("recording_fingerprint") &&
      !y.string("recording_fingerprint", out.recording_fingerprint))
    return false;
  out.trusted = true;
  if (y.has("consistent") && !y.flag("consistent", out.trusted)) return false;
  // The IMU model it estimated (its imu section's; results written before it had none).
  out.imu_model = ImuModel::kCalibrated;
  out.imu_covariance.resize(0, 0);
  if (y.has("imu")) {
    YamlMap imu(file, error);
    if (!imu.sub(y, "imu") || (imu.has("model") && !imu_model_key(imu, "model", out.imu_model)) ||
        !parse_start_imu_intrinsics(imu, dim, out))
      return false;
  }
  out.has_camera = y.has("intrinsics");
  return !out.has_camera || read_camera(y, "skew", out.camera);
}

}  // namespace mirrorcal::io
