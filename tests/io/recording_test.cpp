// Recordings: what the writer writes reads back bit-identically (streams, sensors, priors), and
// the writer refuses what could not be read back.
#include <gtest/gtest.h>

#include <cstring>

#include "mirrorcal/calibration/result.hpp"
#include "recording_support.hpp"

using namespace rectest;

namespace {

bool same_bits(double a, double b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

void expect_same(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const char* what) {
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(same_bits(a(i), b(i))) << what << "(" << i << ")";
}

}  // namespace

TEST(Recording, StreamsReadBackBitIdentical) {
  const auto s = short_scenario();
  const auto data = mc::sim::simulate(s, 21);
  const TempDir tmp("streams");
  const std::string& dir = tmp.path;
  write_recording(dir, s, data, 21);

  mc::io::Recording r;
  std::string err;
  ASSERT_TRUE(mc::io::read_recording(dir, 3, r, err)) << err;
  ASSERT_EQ(r.imu.size(), data.imu.size());
  for (std::size_t k = 0; k < r.imu.size(); ++k) {
    ASSERT_EQ(r.imu[k].t_ns, data.imu[k].t_ns);
    expect_same(r.imu[k].gyro, data.imu[k].gyro, "gyro");
    expect_same(r.imu[k].accel, data.imu[k].accel, "accel");
  }
  ASSERT_EQ(r.frames.size(), data.frames.size());
  EXPECT_EQ(r.frames_outside_imu, 0u);
  for (std::size_t k = 0; k < r.frames.size(); ++k) {
    ASSERT_EQ(r.frames[k].t_ns, data.frames[k].t_ns);
    ASSERT_EQ(r.frames[k].markers.size(), data.frames[k].markers.size());
    for (std::size_t j = 0; j < r.frames[k].markers.size(); ++j) {
      EXPECT_EQ(r.frames[k].markers[j].id, data.frames[k].markers[j].id);
      EXPECT_TRUE(same_bits(r.frames[k].markers[j].u, data.frames[k].markers[j].u));
      EXPECT_TRUE(same_bits(r.frames[k].markers[j].v, data.frames[k].markers[j].v));
    }
  }
  // The sensors as written.
  const auto want = sensors_of(s);
  EXPECT_EQ(r.sensors.imu_rate_hz, want.imu_rate_hz);
  EXPECT_EQ(r.sensors.imu.gyro_noise_density, want.imu.gyro_noise_density);
  EXPECT_EQ(r.sensors.imu.gyro_random_walk, want.imu.gyro_random_walk);
  EXPECT_EQ(r.sensors.imu.accel_noise_density, want.imu.accel_noise_density);
  EXPECT_EQ(r.sensors.imu.accel_random_walk, want.imu.accel_random_walk);
  EXPECT_EQ(r.sensors.intrinsics.fu, want.intrinsics.fu);
  EXPECT_EQ(r.sensors.intrinsics.cv, want.intrinsics.cv);
  EXPECT_EQ(r.sensors.intrinsics.skew, want.intrinsics.skew);
  EXPECT_EQ(r.sensors.width, want.width);
  EXPECT_EQ(r.sensors.height, want.height);
  // Every key was written, so no default was used.
  EXPECT_TRUE(r.notes.empty()) << r.notes.front();
  // No images were given, so there is no image folder.
  EXPECT_FALSE(fs::exists(dir + "/mav0/cam0/data"));
}

TEST(Recording, PriorsRoundTripThroughTheFilePriorExactly) {
  const auto s = short_scenario();
  const auto data = mc::sim::simulate(s, 4);
  const auto prior = mc::sim::simulation_prior<mc::sim::kPaperMarkers>(s, data, 4);
  const TempDir tmp("priors");
  const std::string& dir = tmp.path;
  std::string err;
  ASSERT_TRUE(
      mc::io::write_priors_yaml(dir, mc::io::from_prior(prior, s.gravity_n, 0.75, true, true), err))
      << err;

  mc::io::RecordingPriors read;
  std::vector<std::string> notes;
  const mc::Pinhole<double> camera{1, 2, 3, 4, 5};  // not used: the file gives intrinsics_guess
  ASSERT_TRUE(mc::io::parse_priors_yaml(slurp(dir + "/mirrorcal.yaml"), "mirrorcal.yaml", camera,
                                        read, notes, err))
      << err;
  EXPECT_TRUE(notes.empty());
  EXPECT_TRUE(read.estimate_intrinsics);
  EXPECT_TRUE(read.hold_skew);
  EXPECT_EQ(read.pixel_sigma, 0.75);
  expect_same(read.gravity_n, s.gravity_n, "gravity_n");

  mc::Prior<3> back;
  ASSERT_TRUE(mc::io::to_prior(read, back, err)) << err;
  expect_same(back.p, prior.p, "p");
  expect_same(back.v, prior.v, "v");
  EXPECT_TRUE(back.q_n_b.coeffs() == prior.q_n_b.coeffs());
  expect_same(back.p_b_c, prior.p_b_c, "p_b_c");
  EXPECT_TRUE(back.q_b_c.coeffs() == prior.q_b_c.coeffs());
  for (int i = 0; i < 3; ++i) {
    expect_same(back.markers[i], prior.markers[i], "marker");
    expect_same(back.sigma_markers[i], prior.sigma_markers[i], "sigma_marker");
  }
  expect_same(back.sigma_p, prior.sigma_p, "sigma_p");
  expect_same(back.sigma_v, prior.sigma_v, "sigma_v");
  expect_same(back.sigma_theta, prior.sigma_theta, "sigma_theta");
  expect_same(back.sigma_b_a, prior.sigma_b_a, "sigma_b_a");
  expect_same(back.sigma_b_g, prior.sigma_b_g, "sigma_b_g");
  expect_same(back.sigma_p_b_c, prior.sigma_p_b_c, "sigma_p_b_c");
  expect_same(back.sigma_rot_b_c, prior.sigma_rot_b_c, "sigma_rot_b_c");
  EXPECT_EQ(back.intrinsics.fu, prior.intrinsics.fu);
  EXPECT_EQ(back.intrinsics.skew, prior.intrinsics.skew);
  EXPECT_EQ(back.sigma_intrinsics, prior.sigma_intrinsics);

  // The initial estimate the filter starts from is the same to the bit.
  using F = mc::CalibrationFilter<double, 3, 0>;
  F::State xa, xb;
  F::Covariance pa, pb;
  mc::initialise(prior, xa, pa);
  mc::initialise(back, xb, pb);
  EXPECT_TRUE(pa == pb);
  EXPECT_TRUE(xa.markers == xb.markers && xa.p == xb.p && xa.q_n_b.coeffs() == xb.q_n_b.coeffs());
}

TEST(Recording, WriterRefusesTimestampsThatDoNotIncrease) {
  const TempDir tmp("writer-order");
  const std::string& dir = tmp.path;
  std::string err;
  mc::io::RecordingWriter w;
  ASSERT_TRUE(w.open(dir, err)) << err;
  mc::ImuSample a;
  a.t_ns = 10;
  EXPECT_TRUE(w.add_imu(a));
  EXPECT_FALSE(w.add_imu(a));  // repeated
  mc::io::ObservedFrame f;
  f.t_ns = 7;
  EXPECT_TRUE(w.add_frame(f));
  f.t_ns = 6;
  EXPECT_FALSE(w.add_frame(f));  // backwards
  EXPECT_FALSE(w.close(err));
  EXPECT_NE(err.find("must increase"), std::string::npos) << err;
}

// A recording abandoned before close() (an error, the end of the program) leaves the earlier
// recording's files as they were, and no temporary file.
TEST(Recording, AWriterNeverClosedLeavesTheEarlierRecording) {
  const TempDir tmp("writer-abandoned");
  const std::string imu_csv = tmp.path + "/mav0/imu0/data.csv";
  std::string err;
  mc::ImuSample s;
  s.t_ns = 10;
  {
    mc::io::RecordingWriter w;
    ASSERT_TRUE(w.open(tmp.path, err) && w.add_imu(s) && w.close(err)) << err;
  }
  const std::string before = slurp(imu_csv);
  ASSERT_NE(before.find("\n10,"), std::string::npos) << before;
  {
    mc::io::RecordingWriter w;
    ASSERT_TRUE(w.open(tmp.path, err)) << err;
    s.t_ns = 20;
    ASSERT_TRUE(w.add_imu(s));
  }
  EXPECT_EQ(slurp(imu_csv), before);
  EXPECT_EQ(
      std::distance(fs::directory_iterator(tmp.path + "/mav0/imu0"), fs::directory_iterator()), 1);
}

TEST(Recording, ImagesGoToCam0DataAsPngNamedInDataCsv) {
  const TempDir tmp("images");
  const std::string& dir = tmp.path;
  std::string err;
  mc::io::RecordingWriter w;
  ASSERT_TRUE(w.open(dir, err)) << err;
  const std::uint8_t pixels[6] = {0, 1, 2, 250, 254, 255};
  const mc::io::GrayImage img{3, 2, pixels};
  mc::io::ObservedFrame f;
  f.t_ns = 1234;
  f.markers.push_back({1, 10.5, 20.25});
  ASSERT_TRUE(w.add_frame(f, &img));
  ASSERT_TRUE(w.close(err)) << err;
  const std::string png = slurp(dir + "/mav0/cam0/data/1234.png");
  EXPECT_EQ(png.substr(0, 8), "\x89PNG\r\n\x1a\n");
  mc::io::ImageReader reader(3, 2);
  mc::io::GrayImage back;
  ASSERT_TRUE(reader.read((dir + "/mav0/cam0/data/1234.png").c_str(), back)) << reader.error();
  ASSERT_EQ(back.width, 3);
  ASSERT_EQ(back.height, 2);
  EXPECT_TRUE(std::equal(pixels, pixels + 6, back.pixels));
  EXPECT_EQ(slurp(dir + "/mav0/cam0/data.csv"), "#timestamp [ns],filename\n1234,1234.png\n");
  EXPECT_EQ(slurp(dir + "/mav0/cam0/features.csv"),
            "#timestamp [ns],feature_id,u [px],v [px]\n1234,1,10.5,20.25\n");
}

TEST(Recording, LoopFramesAreWrittenAsTheirObservedFrames) {
  // The board records the loop's MarkerFrame; the simulator its ObservedFrame: same bytes.
  mc::MarkerFrame<3> loop_frame;
  loop_frame.t_ns = 5'000'001;
  loop_frame.seen = {true, false, true};
  loop_frame.uv[0] = Eigen::Vector2d(1.25, 479.5);
  loop_frame.uv[1] = Eigen::Vector2d(7.0, 7.0);  // not seen: not written
  loop_frame.uv[2] = Eigen::Vector2d(0.1, 1e-3);
  mc::io::ObservedFrame observed;
  observed.t_ns = loop_frame.t_ns;
  observed.markers = {{0, 1.25, 479.5}, {2, 0.1, 1e-3}};

  const TempDir a("loop-frame"), b("observed-frame");
  std::string err;
  mc::io::RecordingWriter wa, wb;
  ASSERT_TRUE(wa.open(a.path, err) && wb.open(b.path, err)) << err;
  ASSERT_TRUE(wa.add_frame(loop_frame));
  ASSERT_TRUE(wb.add_frame(observed));
  ASSERT_TRUE(wa.close(err) && wb.close(err)) << err;
  for (const char* f : {"/mav0/cam0/data.csv", "/mav0/cam0/features.csv"})
    EXPECT_EQ(slurp(a.path + f), slurp(b.path + f)) << f;
  EXPECT_EQ(
      slurp(a.path + "/mav0/cam0/features.csv"),
      "#timestamp [ns],feature_id,u [px],v [px]\n5000001,0,1.25,479.5\n5000001,2,0.1,0.001\n");
}

// A calibration written to mirrorcal-result.yaml starts the next one exactly where it ended: the
// estimate and the calibration block's covariance read back as the same doubles.
TEST(CalibrationStart, ResultFileReadsBackBitIdentical) {
  mc::calibration::CalibrationResult r;
  r.p_b_c = Eigen::Vector3d(0.01 / 3.0, -0.05, 0.1 + 1e-17);
  r.q_b_c = Eigen::Quaterniond(Eigen::AngleAxisd(1.0 / 7.0, Eigen::Vector3d(1, 2, 3).normalized()));
  r.markers = {Eigen::Vector3d(0.02, -1.0 / 30.0, -0.03), Eigen::Vector3d(0.05, 0.04, -0.03),
               Eigen::Vector3d(-0.08, 0.06, std::nextafter(0.01, 1.0))};
  r.t_d = std::nextafter(0.0123, 1.0);
  r.width = 640;  // the camera is read too (for export), and checked
  r.height = 480;
  r.params = mc::calibration::calibration_params(3, 5);
  const int n = static_cast<int>(r.params.size());
  Eigen::MatrixXd a = Eigen::MatrixXd::Random(n, n);
  r.covariance = 1e-6 * (a * a.transpose() + Eigen::MatrixXd::Identity(n, n));
  for (int j = 0; j < n; ++j) r.sigma.push_back(std::sqrt(r.covariance(j, j)));
  const TempDir tmp("start");
  std::string err;
  mc::io::OutputSet out;
  ASSERT_TRUE(
      mc::calibration::write_result_yaml(out, tmp.path + "/mirrorcal-result.yaml", r, err) &&
      out.commit(err))
      << err;

  mc::io::CalibrationStart start;
  ASSERT_TRUE(mc::io::read_calibration_start(tmp.path, 3, start, err)) << err;  // the folder
  expect_same(start.p_b_c, r.p_b_c, "p_b_c");
  EXPECT_TRUE(start.q_b_c.coeffs() == r.q_b_c.coeffs());
  ASSERT_EQ(start.features_c.size(), 3u);
  for (int i = 0; i < 3; ++i) expect_same(start.features_c[i], r.markers[i], "marker");
  // The block of the camera pose, markers and time offset; the intrinsics' rows are not part of a
  // start.
  EXPECT_TRUE(start.has_t_d);
  EXPECT_EQ(start.t_d, r.t_d);
  ASSERT_EQ(start.covariance.rows(), 16);
  EXPECT_TRUE(start.covariance == r.covariance.topLeftCorner(16, 16));
  EXPECT_EQ(start.trusted, mc::calibration::consistent(r));  // its self-check's verdict
}

// With the IMU's intrinsics estimated, the next stage starts from them jointly with the camera's
// pose (the gyro's axes and the camera's rotation are seen together): the result file carries
// their rows of the joint covariance, which read back as the same doubles, the intrinsics to the
// file's twelve decimals; and a joint covariance that is not positive definite is refused.
TEST(CalibrationStart, TheImuIntrinsicsReadBackWithTheirJointCovariance) {
  namespace cal = mc::calibration;
  constexpr int kImu = mc::imu_intrinsics_dim(mc::ImuModel::kScaleMisalignment);
  cal::CalibrationResult r;
  r.markers = {Eigen::Vector3d(0.02, -0.03, 0.4), Eigen::Vector3d(0.05, 0.04, 0.4),
               Eigen::Vector3d(-0.08, 0.06, 0.4)};
  r.width = 640;
  r.height = 480;
  r.params = cal::calibration_params(3, 4);  // stage 2's block: the intrinsics' rows are skipped
  const int n = static_cast<int>(r.params.size());
  const Eigen::MatrixXd a = Eigen::MatrixXd::Random(n + kImu, n + kImu);
  const Eigen::MatrixXd joint =
      1e-6 * (a * a.transpose() + Eigen::MatrixXd::Identity(n + kImu, n + kImu));
  r.covariance = joint.topLeftCorner(n, n);
  for (int j = 0; j < n; ++j) r.sigma.push_back(std::sqrt(r.covariance(j, j)));
  r.imu.model = mc::ImuModel::kScaleMisalignment;
  r.imu.intrinsics.d_a << 1.003, 0, 0, 1e-3, 0.998, 0, -2e-3, 5e-4, 1.01;
  r.imu.intrinsics.d_g << 0.995, 0, 0, -1e-3, 1.002, 0, 3e-3, 2e-3, 0.99;
  r.imu.covariance = joint.bottomRows(kImu);
  for (int j = 0; j < kImu; ++j) r.imu.sigma.push_back(std::sqrt(joint(n + j, n + j)));
  const TempDir tmp("start-imu");
  std::string err;
  const auto written = [&](const cal::CalibrationResult& result) {
    mc::io::OutputSet out;
    return cal::write_result_yaml(out, tmp.path + "/mirrorcal-result.yaml", result, err) &&
           out.commit(err);
  };
  ASSERT_TRUE(written(r)) << err;

  mc::io::CalibrationStart start;
  ASSERT_TRUE(mc::io::read_calibration_start(tmp.path, 3, start, err)) << err;
  const mc::io::CalibrationStart expected = cal::calibration_start(r);
  ASSERT_EQ(start.imu_model, mc::ImuModel::kScaleMisalignment);
  ASSERT_EQ(expected.imu_covariance.rows(), kImu);
  ASSERT_EQ(expected.imu_covariance.cols(), 16 + kImu);  // up to the camera's intrinsics
  EXPECT_TRUE(start.imu_covariance == expected.imu_covariance);
  EXPECT_LT((start.imu_intrinsics.d_a - r.imu.intrinsics.d_a).cwiseAbs().maxCoeff(), 1e-11);
  EXPECT_LT((start.imu_intrinsics.d_g - r.imu.intrinsics.d_g).cwiseAbs().maxCoeff(), 1e-11);
  EXPECT_EQ(start.imu_intrinsics.d_a(0, 1), 0.0);  // the model's entries only
  EXPECT_TRUE(start.imu_intrinsics.t_s.isZero());

  // Rows that contradict the calibration block's covariance.
  r.imu.covariance.leftCols(1).setConstant(1.0);
  ASSERT_TRUE(written(r)) << err;
  EXPECT_FALSE(mc::io::read_calibration_start(tmp.path, 3, start, err));
  EXPECT_NE(err.find("imu.covariance: is not positive definite with the calibration states'"),
            std::string::npos)
      << err;
}

TEST(CalibrationStart, BadResultFilesAreRefusedWithFileLineAndReason) {
  const std::string head =
      "p_b_c: [0.01, -0.05, 0.1]\nq_b_c_wxyz: [1, 0, 0, 0]\nfeatures_c:\n  - [0, 0, 1]\n";
  const auto rows = [](const Eigen::MatrixXd& c) {
    std::string t = "covariance:\n";
    for (long i = 0; i < c.rows(); ++i) {
      t += "  - [";
      for (long j = 0; j < c.cols(); ++j) t += (j ? ", " : "") + std::to_string(c(i, j));
      t += "]\n";
    }
    return t;
  };
  const auto refused = [](const std::string& text, const std::string& want) {
    mc::io::CalibrationStart s;
    std::string err;
    EXPECT_FALSE(mc::io::parse_calibration_start(text, "r.yaml", s, err)) << text;
    EXPECT_NE(err.find(want), std::string::npos) << err << "\nlacks: " << want;
  };
  const Eigen::MatrixXd good = 1e-4 * Eigen::MatrixXd::Identity(9, 9);  // 6 + 3 x 1 marker
  mc::io::CalibrationStart s;
  std::string err;
  EXPECT_TRUE(mc::io::parse_calibration_start(head + rows(good), "r.yaml", s, err)) << err;
  refused(head, "r.yaml: missing required key 'covariance'");  // a result of an older mirrorcal
  refused(head + rows(Eigen::MatrixXd::Identity(8, 8)),
          "r.yaml:6: covariance: expected 9 rows (p_b_c, rotation, 1 marker), 13, 14 (and "
          "intrinsics) or 17 (and the lens)");
  Eigen::MatrixXd asym = good;
  asym(0, 1) = 1e-5;
  refused(head + rows(asym), "covariance: is not symmetric");
  Eigen::MatrixXd indefinite = good;
  indefinite(2, 2) = -1e-4;
  refused(head + rows(indefinite), "covariance: is not positive definite");
  std::string short_row = head + rows(good);
  short_row.replace(short_row.find("0.000100, 0.000000"), 18, "0.000100");
  refused(short_row, "covariance: expected a list of 9 numbers");
  refused(head + "covariance: [[nan]]", "r.yaml:5: covariance");
  const std::string missing = "/nonexistent/mirrorcal-result.yaml";
  EXPECT_FALSE(mc::io::read_calibration_start(missing, 1, s, err));
  EXPECT_NE(err.find(missing + ": cannot open"), std::string::npos) << err;
  // A start for another number of markers than the build's.
  const TempDir tmp("start-markers");
  spit(tmp.path + "/mirrorcal-result.yaml", head + rows(good));
  EXPECT_FALSE(mc::io::read_calibration_start(tmp.path, 3, s, err));
  EXPECT_NE(err.find("mirrorcal-result.yaml: lists 1 markers; this build calibrates M = 3"),
            std::string::npos)
      << err;
}

// The camera a calibration ends with reads back through mirrorcal's own readers: from
// camchain-imucam.yaml (the %YAML directive and the rows Kalibr's and OpenVINS's readers need)
// as a recording's camchain.yaml, and from mirrorcal-result.yaml for `export`.
TEST(CameraFiles, WrittenCamerasReadBackInMirrorcalsReaders) {
  mc::calibration::CalibrationResult r;
  r.intrinsics = {831.25, 829.5, 321.75, 247.125, 2.5};
  r.intrinsics.distortion = mc::Distortion::kEquidistant;
  r.intrinsics.coeffs = {-0.01, 0.002, -0.0003, 0.00004};
  r.width = 752;
  r.height = 480;
  r.rostopic = "/rig/front/image_raw";
  r.params = mc::calibration::calibration_params(3, 0);
  const int n = static_cast<int>(r.params.size());
  r.covariance = 1e-6 * Eigen::MatrixXd::Identity(n, n);
  r.sigma.assign(std::size_t(n), 1e-3);
  r.markers.assign(3, Eigen::Vector3d(0.02, 0.03, -0.04));
  const TempDir tmp("camera-files");
  std::string err;
  const std::string chain = tmp.path + "/camchain-imucam.yaml";
  r.intrinsics.line_delay_s = 2.5e-5;
  r.intrinsics.exposure_s = 4e-3;
  mc::io::OutputSet out;
  ASSERT_TRUE(
      mc::calibration::write_camchain_imucam(out, chain, r, err) &&
      mc::calibration::write_result_yaml(out, tmp.path + "/mirrorcal-result.yaml", r, err) &&
      out.commit(err))
      << err;
  EXPECT_EQ(slurp(chain).rfind("%YAML 1.0\n---\n", 0), 0u);  // OpenCV needs the directive first

  const auto expect_camera = [&](const mc::io::CameraInfo& c, const char* file) {
    const mc::Pinhole<double>& k = c.intrinsics;
    EXPECT_NEAR(k.fu, r.intrinsics.fu, 1e-6) << file;
    EXPECT_NEAR(k.fv, r.intrinsics.fv, 1e-6) << file;
    EXPECT_NEAR(k.cu, r.intrinsics.cu, 1e-6) << file;
    EXPECT_NEAR(k.cv, r.intrinsics.cv, 1e-6) << file;
    EXPECT_NEAR(k.skew, r.intrinsics.skew, 1e-6) << file;
    EXPECT_EQ(k.distortion, mc::Distortion::kEquidistant) << file;
    for (std::size_t i = 0; i < 4; ++i) EXPECT_NEAR(k.coeffs[i], r.intrinsics.coeffs[i], 1e-12);
    EXPECT_EQ(c.width, 752) << file;
    EXPECT_EQ(c.height, 480) << file;
    EXPECT_EQ(c.rostopic, "/rig/front/image_raw") << file;
    EXPECT_EQ(k.line_delay_s, 2.5e-5) << file;
    EXPECT_EQ(k.exposure_s, 4e-3) << file;
  };
  mc::io::SensorInfo sensors;
  std::vector<std::string> notes;
  ASSERT_TRUE(mc::io::parse_camchain_yaml(slurp(chain), chain, sensors, notes, err)) << err;
  expect_camera(sensors, "camchain-imucam.yaml");
  mc::io::CalibrationStart result;
  ASSERT_TRUE(mc::io::read_calibration_result(tmp.path, result, err)) << err;
  ASSERT_TRUE(result.has_camera);
  expect_camera(result.camera, "mirrorcal-result.yaml");
  // A camchain.yaml that names no topic gets Kalibr's default.
  const std::string bare =
      "cam0:\n  camera_model: pinhole\n  intrinsics: [800, 800, 320, 240]\n"
      "  resolution: [640, 480]\n";
  ASSERT_TRUE(mc::io::parse_camchain_yaml(bare, "camchain.yaml", sensors, notes, err)) << err;
  EXPECT_EQ(sensors.rostopic, "/cam0/image_raw");
}
