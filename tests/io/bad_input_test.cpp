// Bad recordings: each kind of damage gives a message naming the file, the line and what is
// wrong, never a crash or a silent wrong answer; frames outside the IMU data are skipped and
// counted.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <utility>
#include <vector>

#include <sys/stat.h>

#include "mirrorcal/io/files.hpp"
#include "recording_support.hpp"

using namespace rectest;

namespace {

std::vector<std::string> lines_of(const std::string& path) {
  std::vector<std::string> v;
  std::istringstream in(slurp(path));
  for (std::string l; std::getline(in, l);) v.push_back(l);
  return v;
}

void write_lines(const std::string& path, const std::vector<std::string>& lines) {
  std::string t;
  for (const auto& l : lines) t += l + "\n";
  spit(path, t);
}

// A valid two-second recording of the paper scenario, damaged by each test.
class BadInput : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto s = short_scenario();
    write_recording(dir(), s, mc::sim::simulate(s, 17), 17);
    std::string err;
    ASSERT_TRUE(mc::io::read_recording(dir(), 3, rec, err)) << err;  // undamaged, it reads
    frames = rec.frames.size();
  }

  const std::string& dir() const { return tmp.path; }
  std::string imu() const { return dir() + "/mav0/imu0/data.csv"; }
  std::string cam() const { return dir() + "/mav0/cam0/data.csv"; }
  std::string features() const { return dir() + "/mav0/cam0/features.csv"; }
  std::string priors() const { return dir() + "/mirrorcal.yaml"; }

  // Replaces line n (1-based) of a file.
  void set_line(const std::string& path, std::size_t n, const std::string& text) {
    auto l = lines_of(path);
    ASSERT_LE(n, l.size());
    l[n - 1] = text;
    write_lines(path, l);
  }
  std::string line(const std::string& path, std::size_t n) { return lines_of(path).at(n - 1); }
  // Replaces the first line of a YAML file that starts with key.
  void set_key(const std::string& path, const std::string& key, const std::string& text) {
    auto l = lines_of(path);
    for (auto& s : l)
      if (s.rfind(key + ":", 0) == 0) s = text;
    write_lines(path, l);
  }
  void drop_key(const std::string& path, const std::string& key) { set_key(path, key, ""); }
  // Gives cam0's key of camchain.yaml (which the recording's has) this value.
  void set_cam0(const std::string& key, const std::string& value) {
    auto l = lines_of(dir() + "/camchain.yaml");
    bool found = false;
    for (auto& s : l)
      if (s.find(key + ":") != std::string::npos) {
        s = "  " + key + ": " + value;
        found = true;
      }
    ASSERT_TRUE(found) << key;
    write_lines(dir() + "/camchain.yaml", l);
  }

  // cam0's key given each of the bad values is refused with the reason; given good, the
  // recording is read, and returned.
  mc::io::Recording refused_then_read(const std::string& key, const std::vector<std::string>& bad,
                                      const std::string& good, const std::string& reason) {
    for (const std::string& value : bad) {
      set_cam0(key, value);
      expect_error({dir() + "/camchain.yaml:", "cam0." + key + ": " + reason});
    }
    set_cam0(key, good);
    mc::io::Recording r;
    std::string err;
    EXPECT_TRUE(mc::io::read_recording(dir(), 3, r, err)) << err;
    return r;
  }

  // Reading fails with a message holding each of parts.
  void expect_error(const std::vector<std::string>& parts) {
    mc::io::Recording r;
    std::string err;
    EXPECT_FALSE(mc::io::read_recording(dir(), 3, r, err));
    for (const auto& p : parts)
      EXPECT_NE(err.find(p), std::string::npos) << err << "\nlacks: " << p;
  }

  TempDir tmp{"bad-input-" +
              std::string(::testing::UnitTest::GetInstance()->current_test_info()->name())};
  mc::io::Recording rec;
  std::size_t frames = 0;
};

}  // namespace

TEST_F(BadInput, MissingFile) {
  for (const char* f : {"/mav0/imu0/data.csv", "/mav0/cam0/data.csv", "/mav0/cam0/features.csv",
                        "/imu.yaml", "/camchain.yaml", "/mirrorcal.yaml"}) {
    const std::string path = dir() + f;
    const std::string keep = slurp(path);
    fs::remove(path);
    expect_error({path + ": cannot open"});
    spit(path, keep);
  }
}

TEST_F(BadInput, EmptyFile) {
  spit(imu(), "");
  expect_error({imu() + ":1: empty file"});
}

TEST_F(BadInput, MalformedLine) {
  set_line(imu(), 5, "20000000,0.1,abc,0.3,0.4,0.5,9.8");
  expect_error({imu() + ":5:", "w_RS_S_y", "'abc' is not a number"});
}

TEST_F(BadInput, NumberWithTrailingGarbage) {
  set_line(features(), 3, line(features(), 3) + "px");
  expect_error({features() + ":3:", "v: ", "is not a number"});
}

TEST_F(BadInput, TimestampThatIsNotAnInteger) {
  set_line(cam(), 2, "2.5e6,x.pgm");
  expect_error({cam() + ":2:", "timestamp: '2.5e6' is not an integer"});
}

TEST_F(BadInput, TruncatedLastLine) {
  auto l = lines_of(imu());
  l.back() = l.back().substr(0, l.back().find(',', l.back().find(',') + 1));  // two fields left
  spit(imu(), [&] {
    std::string t;
    for (std::size_t i = 0; i + 1 < l.size(); ++i) t += l[i] + "\n";
    return t + l.back();  // no final newline: the file was cut off
  }());
  expect_error({imu() + ":" + std::to_string(l.size()) + ":",
                "expected 7 comma-separated fields, found 2 (truncated file?)"});
}

// A file without line ends (a binary file, /dev/zero copied) is refused at its first long line:
// the reader's memory is bounded, not the file's size.
TEST_F(BadInput, ALineLongerThanAnyRowIsRefused) {
  set_line(features(), 4, line(features(), 4) + std::string(70000, '0'));
  expect_error({features() + ":4:", "a line longer than 65536 characters"});
}

TEST_F(BadInput, LineWithTooManyFields) {
  set_line(features(), 4, line(features(), 4) + ",7");
  expect_error({features() + ":4:", "expected 4 comma-separated fields, found 5"});
}

TEST_F(BadInput, HeaderThatIsNotEuroc) {
  set_line(imu(), 1, "timestamp,gx,gy,gz,ax,ay,az");
  expect_error({imu() + ":1:", "header 'timestamp,gx,gy,gz,ax,ay,az' is not EuRoC's"});
}

TEST_F(BadInput, FeaturesHeaderThatIsNotOurs) {
  set_line(features(), 1, "#timestamp [ns],id,u,v");
  expect_error({features() + ":1:", "is not EuRoC's"});
}

TEST_F(BadInput, NanInImu) {
  set_line(imu(), 7, "30000000,0.1,0.2,nan,0.4,0.5,9.8");
  expect_error({imu() + ":7:", "w_RS_S_z: 'nan' is not finite"});
}

TEST_F(BadInput, InfinityInFeatures) {
  std::string l = line(features(), 2);
  l = l.substr(0, l.rfind(',')) + ",-inf";
  set_line(features(), 2, l);
  expect_error({features() + ":2:", "v: '-inf' is not finite"});
}

TEST_F(BadInput, NanInPriors) {
  set_key(priors(), "p_b_c", "p_b_c: [0.01, nan, 0.1]");
  expect_error({priors() + ":", "p_b_c: 'nan' is not finite"});
}

TEST_F(BadInput, ImuTimestampRepeats) {
  const std::string prev = line(imu(), 3);
  set_line(imu(), 4,
           prev.substr(0, prev.find(',')) + line(imu(), 4).substr(line(imu(), 4).find(',')));
  expect_error({imu() + ":4:", "repeats"});
}

TEST_F(BadInput, ImuTimestampGoesBackwards) {
  set_line(imu(), 6, "1" + line(imu(), 6).substr(line(imu(), 6).find(',')));
  expect_error({imu() + ":6:", "timestamp 1 goes backwards"});
}

TEST_F(BadInput, FrameTimestampRepeats) {
  set_line(cam(), 3, line(cam(), 2));
  expect_error({cam() + ":3:", "repeats"});
}

TEST_F(BadInput, FeatureTimestampGoesBackwards) {
  // Swap the first feature row with one of a later frame.
  auto l = lines_of(features());
  std::swap(l[1], l.back());
  write_lines(features(), l);
  expect_error({features() + ":3:", "goes backwards"});
}

TEST_F(BadInput, FeatureOfNoFrame) {
  std::string l = line(features(), 2);
  set_line(features(), 2, "1" + l.substr(l.find(',')));  // t = 1 ns: not in data.csv
  expect_error({features() + ":2:", "timestamp 1 is not a frame of cam0/data.csv"});
}

TEST_F(BadInput, MarkerTwiceInAFrame) {
  auto l = lines_of(features());
  l.insert(l.begin() + 2, l[1]);
  write_lines(features(), l);
  expect_error({features() + ":3:", "repeats in the frame"});
}

TEST_F(BadInput, MarkerIdAtOrAboveM) {
  std::string l = line(features(), 2);
  const auto a = l.find(','), b = l.find(',', a + 1);
  set_line(features(), 2, l.substr(0, a + 1) + "3" + l.substr(b));
  expect_error({features() + ":2:", "feature_id 3 is not a marker of this calibration", "M = 3"});
}

TEST_F(BadInput, NegativeMarkerId) {
  std::string l = line(features(), 2);
  const auto a = l.find(','), b = l.find(',', a + 1);
  set_line(features(), 2, l.substr(0, a + 1) + "-1" + l.substr(b));
  expect_error({features() + ":2:", "feature_id -1"});
}

TEST_F(BadInput, MarkerSeenInNoFrame) {
  auto l = lines_of(features());
  std::vector<std::string> kept;
  for (const auto& s : l)
    if (s.find(",2,") == std::string::npos || s[0] == '#') kept.push_back(s);
  ASSERT_LT(kept.size(), l.size());
  write_lines(features(), kept);
  expect_error({features() + ": marker 2 is seen in no frame"});
}

TEST_F(BadInput, RecordingShorterThanTheFilterNeeds) {
  auto l = lines_of(imu());
  write_lines(imu(), {l[0], l[1]});  // one IMU sample: nothing to propagate over
  expect_error({imu() + ": 1 IMU samples; the filter needs at least 2"});
}

TEST_F(BadInput, NoFrameWithinTheImuData) {
  // IMU data only after the last frame.
  auto l = lines_of(imu());
  const auto cams = lines_of(cam());
  const std::int64_t last_frame = std::stoll(cams.back().substr(0, cams.back().find(',')));
  std::vector<std::string> kept = {l[0]};
  for (std::size_t i = 1; i < l.size(); ++i)
    if (std::stoll(l[i].substr(0, l[i].find(','))) > last_frame) kept.push_back(l[i]);
  kept.push_back("999999999999," + l[1].substr(l[1].find(',') + 1));
  write_lines(imu(), kept);
  expect_error({cam() + ": no frame within the IMU data"});
}

TEST_F(BadInput, FramesOutsideTheImuDataAreSkippedAndCounted) {
  // One frame (with a marker) before the first IMU sample and one after the last.
  auto c = lines_of(cam());
  c.insert(c.begin() + 1, "-5000,early.pgm");
  c.push_back("999999999999,late.pgm");
  write_lines(cam(), c);
  auto f = lines_of(features());
  f.insert(f.begin() + 1, "-5000,0,300,200");
  f.push_back("999999999999,1,300,200");
  write_lines(features(), f);
  mc::io::Recording r;
  std::string err;
  ASSERT_TRUE(mc::io::read_recording(dir(), 3, r, err)) << err;
  EXPECT_EQ(r.frames_outside_imu, 2u);
  EXPECT_EQ(r.frames.size(), frames);
  EXPECT_EQ(r.frames.front().t_ns, rec.frames.front().t_ns);
  EXPECT_EQ(r.frames.back().t_ns, rec.frames.back().t_ns);
  ASSERT_FALSE(r.notes.empty());
  EXPECT_NE(r.notes.back().find("2 frames outside the IMU data"), std::string::npos);
}

TEST_F(BadInput, InvalidYaml) {
  set_key(priors(), "gravity_n", "gravity_n: [0, -9.81");
  expect_error({priors() + ":", "not valid YAML"});
}

TEST_F(BadInput, MissingRequiredPrior) {
  drop_key(priors(), "gravity_n");
  expect_error({priors() + ": missing required key 'gravity_n'"});
  write_recording(dir(), short_scenario(), mc::sim::simulate(short_scenario(), 17), 17);
  drop_key(priors(), "sigma_rot_b_c");
  expect_error({"missing required key 'sigma_rot_b_c'"});
}

TEST_F(BadInput, MissingOptionalPriorsUseTheirDefaultsAndSaySo) {
  drop_key(priors(), "b_a");
  drop_key(priors(), "sigma_b_g");
  drop_key(priors(), "pixel_sigma");
  mc::io::Recording r;
  std::string err;
  ASSERT_TRUE(mc::io::read_recording(dir(), 3, r, err)) << err;
  EXPECT_EQ(r.priors.b_a, Eigen::Vector3d::Zero());
  EXPECT_EQ(r.priors.sigma_b_g, Eigen::Vector3d::Constant(0.002));
  EXPECT_EQ(r.priors.pixel_sigma, 1.0);
  std::string all;
  for (const auto& n : r.notes) all += n + "\n";
  for (const char* k : {"b_a not given", "sigma_b_g not given", "pixel_sigma not given"})
    EXPECT_NE(all.find(k), std::string::npos) << all;
}

TEST_F(BadInput, WrongShapeOfAPrior) {
  set_key(priors(), "p_b_c", "p_b_c: [0.01, 0.02]");
  expect_error({priors() + ":", "p_b_c: expected a list of 3 numbers"});
}

TEST_F(BadInput, SigmaThatIsNotPositive) {
  set_key(priors(), "sigma_p_b_c", "sigma_p_b_c: [0.01, 0, 0.01]");
  expect_error({priors() + ":", "sigma_p_b_c: every 1-sigma must be > 0"});
}

TEST_F(BadInput, HoldSkewThatIsNotABoolean) {
  set_key(priors(), "hold_skew", "hold_skew: maybe");
  expect_error({priors() + ":", "hold_skew: expected true or false"});
}

TEST_F(BadInput, QuaternionThatIsNotUnit) {
  set_key(priors(), "q_b_c_wxyz", "q_b_c_wxyz: [1, 1, 0, 0]");
  expect_error({priors() + ":", "q_b_c_wxyz: expected a unit quaternion"});
}

TEST_F(BadInput, SigmaListOfAnotherLengthThanTheMarkers) {
  auto l = lines_of(priors());
  for (std::size_t i = 0; i < l.size(); ++i)
    if (l[i] == "sigma_features_c:") l.erase(l.begin() + long(i) + 1);
  write_lines(priors(), l);
  expect_error({priors() + ":", "sigma_features_c: lists 2 entries, features_c lists 3"});
}

TEST_F(BadInput, PriorsForAnotherNumberOfMarkers) {
  auto l = lines_of(priors());
  for (std::size_t i = 0; i < l.size(); ++i)
    if (l[i] == "features_c:" || l[i] == "sigma_features_c:")
      l.insert(l.begin() + long(i) + 1, l[i + 1]);
  write_lines(priors(), l);
  mc::io::Recording r;
  std::string err;
  ASSERT_TRUE(mc::io::read_recording(dir(), 3, r, err)) << err;
  mc::Prior<3> p;
  EXPECT_FALSE(mc::io::to_prior(r.priors, p, err));
  EXPECT_NE(err.find("lists 4 markers; this build calibrates M = 3"), std::string::npos) << err;
}

TEST_F(BadInput, UnknownKeyIsNoted) {
  auto l = lines_of(priors());
  l.push_back("sigma_pbc: 0.5");
  write_lines(priors(), l);
  mc::io::Recording r;
  std::string err;
  ASSERT_TRUE(mc::io::read_recording(dir(), 3, r, err)) << err;
  ASSERT_FALSE(r.notes.empty());
  EXPECT_NE(r.notes.front().find(":" + std::to_string(l.size()) + ": unknown key 'sigma_pbc'"),
            std::string::npos)
      << r.notes.front();
}

TEST_F(BadInput, ImuYamlWithoutUpdateRate) {
  drop_key(dir() + "/imu.yaml", "update_rate");
  expect_error({dir() + "/imu.yaml: missing required key 'update_rate'"});
}

// A rate no IMU has (a period of 0 ns, or one that overflows, would loop for ever) is refused
// with the file and line; the bounds themselves are rates.
TEST_F(BadInput, UpdateRateOutsideAnyImusIsRefused) {
  const std::string imu_yaml = dir() + "/imu.yaml";
  for (const char* rate : {"1e12", "2e9", "1e-12", "0.5", "10001"}) {
    set_key(imu_yaml, "update_rate", std::string("update_rate: ") + rate);
    expect_error({imu_yaml + ":",
                  "update_rate: must lie within 1..10000 Hz, not '" + std::string(rate) + "'"});
  }
  // (The bounds parse; the recording's 200 Hz data would then contradict them.)
  for (const char* rate : {"1", "10000"}) {
    set_key(imu_yaml, "update_rate", std::string("update_rate: ") + rate);
    mc::io::SensorInfo sensors;
    std::string err;
    std::vector<std::string> notes;
    EXPECT_TRUE(mc::io::parse_imu_yaml(slurp(imu_yaml), imu_yaml, sensors, notes, err)) << err;
  }
  // Within them, a rate the data do not have is refused too, naming both.
  set_key(imu_yaml, "update_rate", "update_rate: 100");
  expect_error({imu() + ": its timestamps step by 5e+06 ns (median), 200 Hz, but " + imu_yaml +
                "'s update_rate is 100 Hz"});
}

// imu.yaml's IMU model and tolerances (mirrorcal's keys): a tolerance of 0, a negative one, a
// percentage given as a number and a model no one knows are refused, naming the file and the key;
// good ones read back as written, and imu_yaml_text writes them as parse_imu_yaml reads them.
TEST_F(BadInput, ImuToleranceOrModelThatIsWrongIsRefused) {
  const std::string imu_yaml = dir() + "/imu.yaml";
  const std::string text = slurp(imu_yaml);
  const auto with = [&](const std::string& extra) { spit(imu_yaml, text + extra); };
  for (const char* bad : {"0", "-0.01", "0.0"}) {
    with(std::string("gyroscope_scale_tolerance: ") + bad + "\n");
    expect_error({imu_yaml + ":", "gyroscope_scale_tolerance: must be > 0"});
  }
  with("accelerometer_cross_axis_tolerance: 2\n");
  expect_error({imu_yaml + ":", "accelerometer_cross_axis_tolerance:", "a fraction"});
  with("imu_model: scale-and-whatever\n");
  expect_error({imu_yaml + ":", "imu_model:", "'scale-and-whatever' is not an IMU model"});

  with("imu_model: scale-misalignment\ngyroscope_scale_tolerance: 0.005\n");
  mc::io::SensorInfo sensors;
  std::vector<std::string> notes;
  std::string err;
  ASSERT_TRUE(mc::io::parse_imu_yaml(slurp(imu_yaml), imu_yaml, sensors, notes, err)) << err;
  ASSERT_TRUE(sensors.imu_model.has_value());
  EXPECT_EQ(*sensors.imu_model, mc::ImuModel::kScaleMisalignment);
  EXPECT_EQ(sensors.imu_tolerances.gyro_scale, 0.005);
  EXPECT_EQ(sensors.imu_tolerances.accel_scale, mc::ImuIntrinsicsSigma{}.accel_scale);
  EXPECT_TRUE(sensors.imu_tolerances_defaulted);

  sensors.imu_tolerances.g_sensitivity = 1.5e-4;
  mc::io::SensorInfo back;
  ASSERT_TRUE(mc::io::parse_imu_yaml(mc::io::imu_yaml_text(sensors), "written", back, notes, err))
      << err;
  EXPECT_EQ(*back.imu_model, mc::ImuModel::kScaleMisalignment);
  EXPECT_EQ(back.imu_tolerances.gyro_scale, 0.005);
  EXPECT_EQ(back.imu_tolerances.g_sensitivity, 1.5e-4);
  EXPECT_FALSE(back.imu_tolerances_defaulted);
}

// Only regular files are read: a FIFO would block the read for ever, /dev/zero would fill the
// memory.
TEST_F(BadInput, AFifoOrADeviceForAFileIsRefused) {
  fs::remove(features());
  ASSERT_EQ(mkfifo(features().c_str(), 0644), 0);
  expect_error({features() + ": not a regular file (a FIFO)"});
  fs::remove(imu());
  fs::create_symlink("/dev/zero", imu());
  expect_error({imu() + ": not a regular file (a character device)"});
}

TEST_F(BadInput, CameraModelThatIsNotPinhole) {
  set_cam0("camera_model", "omni");
  expect_error({dir() + "/camchain.yaml:", "cam0.camera_model: 'omni' is not supported"});
}

// A Kalibr camchain of two cameras is refused, not calibrated as its cam0 alone.
TEST_F(BadInput, ACamchainOfTwoCamerasIsRefused) {
  auto l = lines_of(dir() + "/camchain.yaml");
  std::vector<std::string> two = l;
  for (const auto& s : l) two.push_back(s.rfind("cam0:", 0) == 0 ? "cam1:" : s);
  write_lines(dir() + "/camchain.yaml", two);
  expect_error(
      {dir() + "/camchain.yaml:", "cam1: a second camera; mirrorcal calibrates one camera"});
}

// A time offset in milliseconds where seconds are meant, or a non-positive sigma, is refused.
TEST_F(BadInput, TimeOffsetsInTheWrongUnitAreRefused) {
  set_key(priors(), "timeshift_cam_imu", "timeshift_cam_imu: 12");
  expect_error({priors() + ":", "timeshift_cam_imu: must lie within +-1 s"});
  set_key(priors(), "timeshift_cam_imu", "timeshift_cam_imu: 0.012");
  set_key(priors(), "sigma_timeshift_cam_imu", "sigma_timeshift_cam_imu: 0");
  expect_error({priors() + ":", "sigma_timeshift_cam_imu: must be > 0"});
}

// Kalibr's pinhole lenses are read (radtan, equidistant); anything else is refused with a reason.
TEST_F(BadInput, UnknownLensesAndBadCoefficientsAreRefused) {
  const auto with_lens = [&](const std::string& model, const std::string& coeffs) {
    set_cam0("distortion_model", model);
    set_cam0("distortion_coeffs", coeffs);
  };
  with_lens("fov", "[0.9, 0, 0, 0]");
  expect_error({dir() + "/camchain.yaml:", "distortion_model: 'fov' is not supported"});
  with_lens("radtan", "[0.1, 0]");
  expect_error({dir() + "/camchain.yaml:", "distortion_coeffs: expected a list of 4 numbers"});
  with_lens("none", "[0.1, 0, 0, 0]");
  expect_error({dir() + "/camchain.yaml:", "given without a distortion_model"});
}

// estimate_distortion needs the intrinsics estimated and a lens model to estimate the coefficients
// of: each missing one is refused at its line with the reason; sigma_distortion is checked as the
// other sigmas. With both, the flag and the sigmas are read (the refusals are not blanket ones).
TEST_F(BadInput, EstimateDistortionWithoutALensOrTheIntrinsicsIsRefused) {
  const auto append = [&](const std::vector<std::string>& extra) {
    auto l = lines_of(priors());
    const std::size_t first = l.size() + 1;
    l.insert(l.end(), extra.begin(), extra.end());
    write_lines(priors(), l);
    return std::to_string(first);
  };
  const std::vector<std::string> original = lines_of(priors());
  set_key(priors(), "estimate_intrinsics", "estimate_intrinsics: true");
  std::string at = append({"estimate_distortion: true"});
  // The recording's camchain.yaml says distortion_model: none.
  expect_error({priors() + ":" + at + ": estimate_distortion: needs a lens model",
                "distortion_model is none"});

  auto l = lines_of(dir() + "/camchain.yaml");
  for (auto& c : l) {
    if (c.find("distortion_model") != std::string::npos) c = "  distortion_model: radtan";
    if (c.find("distortion_coeffs") != std::string::npos)
      c = "  distortion_coeffs: [-0.28, 0.07, 0.0002, 0.00002]";
  }
  write_lines(dir() + "/camchain.yaml", l);
  write_lines(priors(), original);
  set_key(priors(), "estimate_intrinsics", "estimate_intrinsics: false");
  at = append({"estimate_distortion: true"});
  expect_error({priors() + ":" + at + ": estimate_distortion: needs estimate_intrinsics: true"});

  write_lines(priors(), original);
  set_key(priors(), "estimate_intrinsics", "estimate_intrinsics: true");
  append({"estimate_distortion: true", "sigma_distortion: [0.1, 0, 0.001, 0.001]"});
  expect_error({priors() + ":", "sigma_distortion: every 1-sigma must be > 0"});
  write_lines(priors(), original);
  set_key(priors(), "estimate_intrinsics", "estimate_intrinsics: true");
  append({"estimate_distortion: true", "sigma_distortion: [0.1, 0.1, 5, 0.001]"});
  expect_error({priors() + ":", "sigma_distortion: a 1-sigma of 5 (unitless) is no guess"});

  write_lines(priors(), original);
  set_key(priors(), "estimate_intrinsics", "estimate_intrinsics: true");
  append({"estimate_distortion: true", "sigma_distortion: [0.1, 0.05, 0.001, 0.002]"});
  mc::io::Recording r;
  std::string err;
  ASSERT_TRUE(mc::io::read_recording(dir(), 3, r, err)) << err;
  EXPECT_TRUE(r.priors.estimate_distortion);
  EXPECT_EQ(r.priors.sigma_distortion, (std::array<double, 4>{0.1, 0.05, 0.001, 0.002}));
  EXPECT_EQ(r.priors.intrinsics_guess.distortion, mc::Distortion::kRadtan);
  EXPECT_EQ(r.priors.intrinsics_guess.coeffs[0], -0.28);  // camchain.yaml's coefficients
}

// The markers' LEDs (led_brightness, blink_period, led_lines): a list that is not one entry per
// marker, a brightness that is not positive, a code too short for every marker to go dark in its
// own frame, and LED lines without a code are each refused at their line; given right, they are
// read, and written back as they were read.
TEST_F(BadInput, MarkerLedsThatCannotBeDrivenOrToldApartAreRefused) {
  const std::vector<std::string> original = lines_of(priors());
  const auto with = [&](const std::vector<std::string>& extra) {
    auto l = original;
    const std::string at = std::to_string(l.size() + 1);
    l.insert(l.end(), extra.begin(), extra.end());
    write_lines(priors(), l);
    return priors() + ":" + at + ": ";
  };
  std::string at = with({"led_brightness: [1, 1]"});
  expect_error({at + "led_brightness: expected a list of 3 entries, one per marker"});
  at = with({"led_brightness: [1, 0, 1]"});
  expect_error({at + "led_brightness: every brightness must be > 0"});
  at = with({"blink_period: 3"});
  expect_error({at + "blink_period: must be 4..64 frames"});
  at = with({"blink_period: 8.5"});
  expect_error({at + "blink_period: expected an integer"});
  at = with({"led_lines: [gpiochip0:5, gpiochip0:6, gpiochip0:13]"});
  expect_error({at + "led_lines: needs blink_period"});
  at = with({"blink_period: 8", "led_lines: [gpiochip0:5, gpiochip0:6]"});
  expect_error({"led_lines: expected a list of 3 entries, one per marker"});

  with({"led_brightness: [1, 1, 1]", "blink_period: 8",
        "led_lines: [gpiochip0:5, gpiochip0:6, gpiochip0:13]"});
  mc::io::Recording r;
  std::string err;
  ASSERT_TRUE(mc::io::read_recording(dir(), 3, r, err)) << err;
  EXPECT_EQ(r.priors.leds.brightness, (std::vector<double>{1, 1, 1}));
  EXPECT_EQ(r.priors.leds.blink_period, 8);
  EXPECT_EQ(r.priors.leds.lines,
            (std::vector<std::string>{"gpiochip0:5", "gpiochip0:6", "gpiochip0:13"}));
  const std::string again = dir() + "/again";
  ASSERT_EQ(::mkdir(again.c_str(), 0755), 0);
  ASSERT_TRUE(mc::io::write_priors_yaml(again, r.priors, err)) << err;
  mc::io::RecordingPriors read_back;
  std::string text;
  std::vector<std::string> notes;
  ASSERT_TRUE(mc::io::read_file(again + "/mirrorcal.yaml", text, err)) << err;
  ASSERT_TRUE(mc::io::parse_priors_yaml(text, "again", r.sensors.intrinsics, read_back, notes, err))
      << err;
  EXPECT_EQ(read_back.leds.brightness, r.priors.leds.brightness);
  EXPECT_EQ(read_back.leds.blink_period, 8);
  EXPECT_EQ(read_back.leds.lines, r.priors.leds.lines);
}

// A rolling shutter's line_delay is seconds per row: microseconds given as seconds, or a negative
// delay, are refused; a real one is read.
TEST_F(BadInput, LineDelaysInTheWrongUnitAreRefused) {
  const mc::io::Recording r =
      refused_then_read("line_delay", {"30", "-3e-5"}, "3e-5", "must be seconds per row");
  EXPECT_EQ(r.sensors.intrinsics.line_delay_s, 3e-5);
}

// The exposure is seconds: milliseconds given as seconds, or a negative one, are refused; a real
// one is read (the recording's camchain.yaml has the key, as record writes it).
TEST_F(BadInput, ExposureTimesInTheWrongUnitAreRefused) {
  const mc::io::Recording r =
      refused_then_read("exposure_time", {"4", "-0.004"}, "0.004", "must be the frames' exposure");
  EXPECT_EQ(r.sensors.intrinsics.exposure_s, 0.004);
}

TEST_F(BadInput, TruthFileThatIsDamaged) {
  spit(dir() + "/truth.yaml", "p_b_c: [0.01, 0.02]\n");
  expect_error({dir() + "/truth.yaml:1:", "p_b_c: expected a list of 3 numbers"});
}

// --- the data against what the files say they are --------------------------------------------

namespace {

// Rewrites each data line's timestamp (the first field) of a CSV file.
void map_times(const std::string& path, const std::function<std::int64_t(std::int64_t)>& f) {
  auto l = lines_of(path);
  for (std::size_t i = 1; i < l.size(); ++i) {
    const std::size_t comma = l[i].find(',');
    l[i] = std::to_string(f(std::stoll(l[i].substr(0, comma)))) + l[i].substr(comma);
  }
  write_lines(path, l);
}

// Multiplies the gyro (columns 1-3) or accelerometer (4-6) readings of imu0/data.csv by factor.
void scale_imu(const std::string& path, bool gyro, double factor) {
  auto l = lines_of(path);
  for (std::size_t i = 1; i < l.size(); ++i) {
    std::vector<std::string> f;
    std::istringstream in(l[i]);
    for (std::string s; std::getline(in, s, ',');) f.push_back(s);
    for (std::size_t j = gyro ? 1 : 4; j < (gyro ? 4u : 7u); ++j)
      f[j] = std::to_string(std::stod(f[j]) * factor);
    std::string joined = f[0];
    for (std::size_t j = 1; j < f.size(); ++j) joined += "," + f[j];
    l[i] = joined;
  }
  write_lines(path, l);
}

}  // namespace

TEST_F(BadInput, AnUndamagedRecordingHasNoWarnings) {
  EXPECT_TRUE(rec.warnings.empty()) << rec.warnings.front();
  EXPECT_EQ(rec.fingerprint.size(), 16u);
}

// EuRoC's classic slip: the IMU's timestamps in us or ms; its rate is then 1000 or 10^6 times
// imu.yaml's.
TEST_F(BadInput, ImuTimestampsInAnotherUnitThanNsAreRefused) {
  const std::string original = slurp(imu());
  for (const auto& [divisor, unit] :
       {std::pair<std::int64_t, std::string>{1000, "microseconds"}, {1000000, "milliseconds"}}) {
    spit(imu(), original);
    map_times(imu(), [d = divisor](std::int64_t t) { return t / d; });
    expect_error({imu() + ": its timestamps step by", dir() + "/imu.yaml's update_rate is 200 Hz",
                  unit + " instead of nanoseconds?"});
  }
}

// The camera's timestamps alone in us: squeezed into the IMU data's first thousandth, or, on a
// clock with an epoch, far before it.
TEST_F(BadInput, CameraTimestampsInAnotherUnitThanNsAreRefused) {
  map_times(cam(), [](std::int64_t t) { return t / 1000; });
  map_times(features(), [](std::int64_t t) { return t / 1000; });
  expect_error({cam() + ": the frames within the IMU data span", "microseconds instead of nano"});

  constexpr std::int64_t kEpoch = 1'400'000'000'000'000'000;  // 2014, in ns
  map_times(imu(), [](std::int64_t t) { return t + kEpoch; });
  map_times(cam(), [](std::int64_t t) { return t + kEpoch / 1000; });
  map_times(features(), [](std::int64_t t) { return t + kEpoch / 1000; });
  expect_error({cam() + ": no frame within the IMU data", "microseconds instead of nanoseconds?"});
}

// An IMU-only recording (record without a camera) is told so first, whatever its IMU data.
TEST_F(BadInput, ARecordingWithoutFramesSaysSoFirst) {
  write_lines(cam(), {line(cam(), 1)});
  write_lines(features(), {line(features(), 1)});
  set_key(dir() + "/imu.yaml", "update_rate", "update_rate: 100");
  expect_error({cam() + ": no frame within the IMU data; the filter needs at least one"});
}

TEST_F(BadInput, GyroInDegreesPerSecondIsRefused) {
  scale_imu(imu(), true, 180.0 / M_PI);
  expect_error({imu() + ": the gyro's median rate is", "deg/s given for rad/s?"});
}

TEST_F(BadInput, AccelerometerInGIsRefused) {
  scale_imu(imu(), false, 1.0 / 9.81);
  expect_error({imu() + ": the accelerometer's median magnitude is", "g given for m/s^2?"});
}

// Kalibr's mix-up: the per-sample sigma given for the density, sqrt(200) = 14 times too large;
// densities and random walks 1000 times too large. Warned of, naming imu.yaml and the factor.
TEST_F(BadInput, NoiseDensitiesThatAreNotTheDatasAreWarnedOf) {
  const std::string imu_yaml = dir() + "/imu.yaml";
  const double g = rec.sensors.imu.gyro_noise_density, a = rec.sensors.imu.accel_noise_density;
  const auto warnings = [&] {
    mc::io::Recording r;
    std::string err;
    EXPECT_TRUE(mc::io::read_recording(dir(), 3, r, err)) << err;
    std::string all;
    for (const auto& w : r.warnings) all += w + "\n";
    return all;
  };
  set_key(imu_yaml, "gyroscope_noise_density",
          "gyroscope_noise_density: " + std::to_string(g * std::sqrt(200.0)));
  std::string w = warnings();
  EXPECT_NE(w.find(imu_yaml + ": gyroscope_noise_density"), std::string::npos) << w;
  EXPECT_NE(w.find("times more than " + imu()), std::string::npos) << w;
  EXPECT_NE(w.find("per-sample sigma given for the density"), std::string::npos) << w;
  EXPECT_EQ(w.find("accelerometer_noise_density"), std::string::npos) << w;

  set_key(imu_yaml, "gyroscope_noise_density", "gyroscope_noise_density: " + std::to_string(g));
  set_key(imu_yaml, "accelerometer_noise_density",
          "accelerometer_noise_density: " + std::to_string(a * 1000.0));
  w = warnings();
  EXPECT_NE(w.find(imu_yaml + ": accelerometer_noise_density"), std::string::npos) << w;
  EXPECT_NE(w.find("outside what real MEMS parts have"), std::string::npos) << w;

  set_key(imu_yaml, "accelerometer_noise_density",
          "accelerometer_noise_density: " + std::to_string(a));
  set_key(imu_yaml, "gyroscope_random_walk",
          "gyroscope_random_walk: " + std::to_string(rec.sensors.imu.gyro_random_walk * 1000.0));
  w = warnings();
  EXPECT_NE(w.find(imu_yaml + ": gyroscope_random_walk"), std::string::npos) << w;
  EXPECT_EQ(w.find("noise_density"), std::string::npos) << w;
}

// A 1-sigma no guess can have (another unit, or a typo) is refused with the file and line.
TEST_F(BadInput, AbsurdSigmasAreRefused) {
  auto l = lines_of(priors());
  std::size_t n = 0;
  while (l[n].rfind("sigma_features_c:", 0) != 0) ++n;
  l[n + 2] = "  - [0.01, 1e200, 0.01]";
  write_lines(priors(), l);
  expect_error({priors() + ":" + std::to_string(n + 3) + ": sigma_features_c: a 1-sigma of",
                "m is no guess (at most 1 m"});
  write_recording(dir(), short_scenario(), mc::sim::simulate(short_scenario(), 17), 17);
  set_key(priors(), "pixel_sigma", "pixel_sigma: 500");
  expect_error({priors() + ":", "pixel_sigma: a 1-sigma of 500 px is no guess (at most 100 px"});
  set_key(priors(), "pixel_sigma", "pixel_sigma: 100");
  mc::io::Recording r;
  std::string err;
  EXPECT_TRUE(mc::io::read_recording(dir(), 3, r, err)) << err;
}
