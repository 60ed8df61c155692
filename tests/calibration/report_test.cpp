// What the tables print: the paper's Euler angles of the camera rotation, and chi-square
// quantiles for the NEES intervals, against published values; the report's statistics and the
// base64 of its embedded plots.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "mirrorcal/calibration/report.hpp"
#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/sim/scenario.hpp"

namespace {

using mirrorcal::calibration::chi2_quantile;
using mirrorcal::calibration::display_angles;

TEST(Report, PaperRotationShowsThePapersAngles) {
  const Eigen::Vector3d a = display_angles(mirrorcal::sim::paper_scenario().truth.q_b_c);
  EXPECT_NEAR(a(0), -90.0, 1e-9);
  EXPECT_NEAR(a(1), 0.0, 1e-9);
  EXPECT_NEAR(a(2), -90.0, 1e-9);
}

TEST(Report, DisplayAnglesRebuildTheRotation) {
  const double deg = M_PI / 180.0;
  for (const Eigen::Vector3d& xyz : {Eigen::Vector3d(10, 20, 30), Eigen::Vector3d(-170, 80, 5),
                                     Eigen::Vector3d(100, -60, -120)}) {
    const Eigen::Quaterniond q(Eigen::AngleAxisd(xyz(2) * deg, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(xyz(1) * deg, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(xyz(0) * deg, Eigen::Vector3d::UnitX()));
    const Eigen::Vector3d a = display_angles(q) * deg;
    const Eigen::Quaterniond back(Eigen::AngleAxisd(a(2), Eigen::Vector3d::UnitZ()) *
                                  Eigen::AngleAxisd(a(1), Eigen::Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(a(0), Eigen::Vector3d::UnitX()));
    EXPECT_NEAR(std::abs(q.dot(back)), 1.0, 1e-12);
    EXPECT_LE(std::abs(a(1)), M_PI / 2 + 1e-12);
  }
}

// Published chi-square quantiles (e.g. NIST/SEMATECH e-Handbook, table 1.3.6.7.4).
TEST(Report, ChiSquareQuantilesMatchTables) {
  EXPECT_NEAR(chi2_quantile(0.025, 15), 6.262, 0.02 * 6.262);
  EXPECT_NEAR(chi2_quantile(0.975, 15), 27.488, 0.01 * 27.488);
  EXPECT_NEAR(chi2_quantile(0.001, 100), 61.918, 0.01 * 61.918);
  EXPECT_NEAR(chi2_quantile(0.999, 100), 149.449, 0.01 * 149.449);
  EXPECT_NEAR(chi2_quantile(0.05, 50), 34.764, 0.01 * 34.764);
}

// RFC 4648, section 10.
TEST(Report, Base64MatchesTheRfcsTestVectors) {
  using mirrorcal::calibration::base64;
  EXPECT_EQ(base64(""), "");
  EXPECT_EQ(base64("f"), "Zg==");
  EXPECT_EQ(base64("fo"), "Zm8=");
  EXPECT_EQ(base64("foo"), "Zm9v");
  EXPECT_EQ(base64("foob"), "Zm9vYg==");
  EXPECT_EQ(base64("fooba"), "Zm9vYmE=");
  EXPECT_EQ(base64("foobar"), "Zm9vYmFy");
  EXPECT_EQ(base64(std::string("\xff\xfe\x00", 3)), "//4A");
}

TEST(Report, SampleStatisticsOfKnownSamples) {
  using mirrorcal::calibration::sample_stats;
  const auto s = sample_stats({4.0, 1.0, 3.0, 2.0});
  EXPECT_EQ(s.n, 4u);
  EXPECT_DOUBLE_EQ(s.mean, 2.5);
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.std, std::sqrt(1.25));
  EXPECT_DOUBLE_EQ(s.max, 4.0);
  EXPECT_DOUBLE_EQ(sample_stats({5.0, 1.0, 9.0}).median, 5.0);
  EXPECT_EQ(sample_stats(std::vector<double>{}).n, 0u);
}

// The report's medians are exact however many residuals there are: kth_smallest, which keeps a
// bounded batch in memory and narrows the rest down pass by pass, against a full sort, on samples
// beyond its batch (65536 values) with long runs of equal values, a heavy tail and negatives.
TEST(Report, KthSmallestIsExactOnSamplesLargerThanItsBatch) {
  using mirrorcal::calibration::kth_smallest;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::cauchy_distribution<double> cauchy(0.0, 1.0);
  for (int kind = 0; kind < 3; ++kind) {
    std::vector<double> values(200'001);
    for (std::size_t i = 0; i < values.size(); ++i) {
      if (kind == 0) values[i] = std::hypot(normal(rng), normal(rng));  // residual lengths
      if (kind == 1) values[i] = cauchy(rng);
      if (kind == 2) values[i] = double(i % 7 == 0 ? 3 : std::int64_t(normal(rng) * 2.0));
    }
    int passes = 0;
    const mirrorcal::calibration::Sample sample = [&](const std::function<void(double)>& f) {
      ++passes;
      for (double v : values) f(v);
    };
    std::vector<double> sorted = values;
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t k : {std::size_t(0), std::size_t(1), values.size() / 2, values.size() - 1,
                          std::size_t(12345), std::size_t(187654)}) {
      passes = 0;
      EXPECT_EQ(kth_smallest(sample, k), sorted[k]) << "kind " << kind << " k " << k;
      EXPECT_LE(passes, 8) << "kind " << kind << " k " << k;
    }
    EXPECT_EQ(mirrorcal::calibration::sample_stats(sample).median, sorted[values.size() / 2]);
  }
}

// A diverged run's values span more than a double can (infinities, +-1e308): the narrowing stops
// instead of binning everything into one bin for ever, and the answer is still exact.
TEST(Report, KthSmallestEndsOnValuesTooFarApartToBin) {
  using mirrorcal::calibration::kth_smallest;
  std::mt19937_64 rng(6);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (const double extreme : {double(INFINITY), 1e308}) {
    std::vector<double> values(100'001);
    for (double& v : values) v = normal(rng);
    values[17] = extreme;
    values[99] = -extreme;
    const mirrorcal::calibration::Sample sample = [&](const std::function<void(double)>& f) {
      for (double v : values) f(v);
    };
    std::vector<double> sorted = values;
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t k : {std::size_t(0), values.size() / 2, values.size() - 1})
      EXPECT_EQ(kth_smallest(sample, k), sorted[k]) << "extreme " << extreme << " k " << k;
  }
}

// The report says the IMU's gaps and restarts (issue: hiccups counted and reported).
TEST(Report, ExcitationSaysTheImuGapsAndRestarts) {
  mirrorcal::calibration::ReportData d = mirrorcal::calibration::report_data_without_history(
      mirrorcal::calibration::CalibrationResult{}, "test");
  d.rows.push_back(mirrorcal::calibration::ReportRow{});
  d.loop.imu_samples = 1200;
  d.loop.imu_gaps = 3;
  d.loop.imu_restarts = 1;
  d.loop.frames_before_filter = 7;
  const std::string text = mirrorcal::calibration::report_text(d);
  EXPECT_NE(text.find("IMU: 1200 samples, 3 gaps (1 too long to cross"), std::string::npos) << text;
  EXPECT_NE(text.find("7 frames behind the filter skipped"), std::string::npos) << text;
}

// The markers' common scale: the covariance's variance along the markers' own direction, relative
// to their size. Against covariances whose answer is known in closed form: isotropic, where
// f^T P f = s^2 |f|^2, and one of the scale alone, P = c^2 f f^T, whose relative sigma is c.
TEST(Report, ExcitationSaysHowWellTheMarkersScaleIsKnown) {
  namespace mc = mirrorcal::calibration;
  mc::CalibrationResult r;
  r.markers = {Eigen::Vector3d(0.06, 0.0, -0.02), Eigen::Vector3d(-0.03, 0.05, 0.01)};
  const mirrorcal::IndexRange block = r.layout()[mirrorcal::CalibrationGroup::kMarkers];
  const auto report_of = [](const mc::CalibrationResult& result) {
    mc::ReportData d = mc::report_data_without_history(result, "test");
    d.rows.push_back(mc::ReportRow{});
    return mc::report_text(d);
  };
  EXPECT_EQ(mc::marker_scale_sigma(r), 0.0);  // no covariance: nothing said
  EXPECT_EQ(report_of(r).find("common scale"), std::string::npos);

  Eigen::VectorXd f(6);
  f << r.markers[0], r.markers[1];
  const double s = 0.5e-3;  // 0.5 mm on every coordinate
  r.covariance = Eigen::MatrixXd::Identity(r.layout().size(), r.layout().size()) * 1e-4;
  r.covariance.block(block.begin, block.begin, 6, 6) = Eigen::MatrixXd::Identity(6, 6) * s * s;
  EXPECT_NEAR(mc::marker_scale_sigma(r), s / f.norm(), 1e-15);
  std::string text = report_of(r);
  char want[64];
  std::snprintf(want, sizeof want, "known to %.2f %% (1 sigma)\n", 100.0 * s / f.norm());
  EXPECT_NE(text.find(want), std::string::npos) << text;
  EXPECT_EQ(text.find("not trusted"), std::string::npos) << text;
  EXPECT_FALSE(mc::scale_unresolved(r));

  const double c = 0.07;  // the scale alone, 7 %: beyond kLooseMarkerScale
  r.covariance.block(block.begin, block.begin, 6, 6) = c * c * f * f.transpose();
  EXPECT_NEAR(mc::marker_scale_sigma(r), c, 1e-15);
  text = report_of(r);
  EXPECT_NE(text.find("known to 7.00 % (1 sigma); beyond 4 %: not trusted"), std::string::npos)
      << text;
  // And the verdict says so: a scale that loose is no calibration to trust.
  EXPECT_TRUE(mc::scale_unresolved(r));
  EXPECT_FALSE(mc::consistent(r));
  EXPECT_NE(text.find("WARNING: the markers' size against the mirror's distance, which only the "
                      "IMU's acceleration fixes, is known to 7.0 %"),
            std::string::npos)
      << text;
}

// What the input checks warned of stands beside the verdict, which the self-check alone sets.
TEST(Report, TheInputsWarningsStandBesideTheVerdict) {
  mirrorcal::calibration::ReportData d = mirrorcal::calibration::report_data_without_history(
      mirrorcal::calibration::CalibrationResult{}, "test");
  d.input_warnings = {"imu.yaml: gyroscope_noise_density: 14 times more than the data's"};
  const std::string text = mirrorcal::calibration::report_text(d);
  const std::size_t verdict = text.find("VERDICT"), calibration = text.find("CALIBRATION");
  const std::size_t warning = text.find(
      "WARNING (the input): imu.yaml: gyroscope_noise_density: 14 times more than the data's");
  ASSERT_NE(warning, std::string::npos) << text;
  EXPECT_LT(verdict, warning);
  EXPECT_LT(warning, calibration);
}

}  // namespace
