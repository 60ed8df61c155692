// The report the commands write beside a calibration (report.txt, report.html, residuals.csv),
// checked against the other files: the verdict against mirrorcal-result.yaml's self-check, the
// residual statistics recomputed from residuals.csv, the page parsed for its structure and, where
// Debian's chromium is installed, rendered by a real browser.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <vector>

#include <unistd.h>

#include "mirrorcal/estimator/mirror_model.hpp"
#include "mirrorcal/evaluation/process.hpp"
#include "recording_support.hpp"

using namespace rectest;

namespace {

// mirrorcal with the arguments (split at spaces) run without a shell; its exit status, and its
// output in scratch/command.log.
int run_mirrorcal(const std::string& args, const std::string& scratch) {
  std::vector<std::string> argv = {MIRRORCAL_BIN};
  std::istringstream words(args);
  for (std::string w; words >> w;) argv.push_back(w);
  return mc::evaluation::run_program(argv, "", scratch + "/command.log").status;
}

// The line of text that starts with prefix ("" if none), or the line after it.
std::string line_starting(const std::string& text, const std::string& prefix, bool next = false) {
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);)
    if (line.rfind(prefix, 0) == 0) return next && std::getline(lines, line) ? line : line;
  return "";
}

struct Row {
  std::size_t n = 0;
  double mean = -1, median = -1, std = -1, max = -1;  // px
  double mean_sigma = -1, max_sigma = -1;             // in pixel sigmas
};

// A row of the residual table: "f1", "all", "+settling".
Row residual_row(const std::string& report, const std::string& label) {
  Row r;
  const std::string line = line_starting(report, label + " ");
  double median_sigma = 0, std_sigma = 0;
  std::sscanf(line.c_str() + label.size(), "%zu %lf %lf %lf %lf %lf %lf %lf %lf", &r.n, &r.mean,
              &r.median, &r.std, &r.max, &r.mean_sigma, &median_sigma, &std_sigma, &r.max_sigma);
  return r;
}

struct CsvResidual {
  int marker = 0;
  double length = 0;
  double du = 0, dv = 0;
  bool settled = false;
};

std::vector<CsvResidual> read_residuals_csv(const std::string& path) {
  std::vector<CsvResidual> v;
  std::istringstream lines(slurp(path));
  std::string line;
  std::getline(lines, line);  // header
  while (std::getline(lines, line)) {
    CsvResidual r;
    double t = 0;
    int settled = 0;
    if (std::sscanf(line.c_str(), "%lf,%d,%lf,%lf,%d", &t, &r.marker, &r.du, &r.dv, &settled) != 5)
      continue;
    r.length = std::sqrt(r.du * r.du + r.dv * r.dv);
    r.settled = settled == 1;
    v.push_back(r);
  }
  return v;
}

// The statistics of a sample, computed here from its definition.
Row stats_of(std::vector<double> x) {
  Row r;
  r.n = x.size();
  if (x.empty()) return r;
  double sum = 0;
  for (double v : x) sum += v;
  r.mean = sum / double(x.size());
  double var = 0;
  for (double v : x) var += (v - r.mean) * (v - r.mean);
  r.std = std::sqrt(var / double(x.size()));
  std::sort(x.begin(), x.end());
  r.median = x.size() % 2 ? x[x.size() / 2] : 0.5 * (x[x.size() / 2 - 1] + x[x.size() / 2]);
  r.max = x.back();
  return r;
}

void expect_row_matches(const Row& printed, const Row& computed, const std::string& what) {
  EXPECT_EQ(printed.n, computed.n) << what;
  // Printed with three decimals.
  EXPECT_NEAR(printed.mean, computed.mean, 6e-4) << what;
  EXPECT_NEAR(printed.median, computed.median, 6e-4) << what;
  EXPECT_NEAR(printed.std, computed.std, 6e-4) << what;
  EXPECT_NEAR(printed.max, computed.max, 6e-4) << what;
}

// base64 decoded here, independently of the program's encoder; false on a character outside it.
bool decode_base64(const std::string& in, std::string& out) {
  static const std::string alphabet =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::uint32_t bits = 0;
  int count = 0;
  for (char c : in) {
    if (c == '=') break;
    const std::size_t v = alphabet.find(c);
    if (v == std::string::npos) return false;
    bits = (bits << 6) | std::uint32_t(v);
    count += 6;
    if (count >= 8) {
      count -= 8;
      out += char((bits >> count) & 0xffu);
    }
  }
  return true;
}

const std::string kPngSignature = "\x89PNG\r\n\x1a\n";

// Every start and end tag of html, checked to nest; the void elements have none. Empty, or what
// is wrong.
std::string tag_nesting_error(const std::string& html) {
  const std::vector<std::string> void_elements = {"meta", "img", "br", "link", "hr"};
  std::vector<std::string> open;
  for (std::size_t at = html.find('<'); at != std::string::npos; at = html.find('<', at + 1)) {
    const std::size_t end = html.find('>', at);
    if (end == std::string::npos) return "a tag is not closed at " + std::to_string(at);
    const std::string tag = html.substr(at + 1, end - at - 1);
    if (tag.rfind("!DOCTYPE", 0) == 0) continue;
    const bool closing = tag[0] == '/';
    const std::string name =
        tag.substr(closing ? 1 : 0, tag.find_first_of(" />", closing ? 1 : 0) - (closing ? 1 : 0));
    if (closing) {
      if (open.empty() || open.back() != name) return "</" + name + "> closes nothing open";
      open.pop_back();
    } else if (std::find(void_elements.begin(), void_elements.end(), name) == void_elements.end()) {
      open.push_back(name);
    }
  }
  return open.empty() ? "" : "<" + open.back() + "> is never closed";
}

// The values of every attribute named name (src, href) in html.
std::vector<std::string> attribute_values(const std::string& html, const std::string& name) {
  std::vector<std::string> values;
  const std::string key = " " + name + "=\"";
  for (std::size_t at = html.find(key); at != std::string::npos; at = html.find(key, at + 1)) {
    const std::size_t begin = at + key.size();
    values.push_back(html.substr(begin, html.find('"', begin) - begin));
  }
  return values;
}

// A PNG's pixels (8-bit RGB or RGBA, not interlaced, as Chromium writes its screenshots).
struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<unsigned char> pixels;
};

std::uint32_t big_endian(const std::string& s, std::size_t at) {
  return std::uint32_t(static_cast<unsigned char>(s[at])) << 24 |
         std::uint32_t(static_cast<unsigned char>(s[at + 1])) << 16 |
         std::uint32_t(static_cast<unsigned char>(s[at + 2])) << 8 |
         std::uint32_t(static_cast<unsigned char>(s[at + 3]));
}

int paeth(int a, int b, int c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}

bool decode_png(const std::string& png, Image& image, std::string& why) {
  if (png.compare(0, 8, kPngSignature) != 0) {
    why = "not a PNG";
    return false;
  }
  std::string compressed;
  for (std::size_t at = 8; at + 8 <= png.size();) {
    const std::uint32_t length = big_endian(png, at);
    const std::string type = png.substr(at + 4, 4);
    if (type == "IHDR") {
      image.width = int(big_endian(png, at + 8));
      image.height = int(big_endian(png, at + 12));
      const int depth = static_cast<unsigned char>(png[at + 16]);
      const int colour = static_cast<unsigned char>(png[at + 17]);
      image.channels = colour == 6 ? 4 : colour == 2 ? 3 : 0;
      if (depth != 8 || image.channels == 0 || png[at + 20] != 0) {
        why = "not 8-bit RGB(A) without interlace";
        return false;
      }
    } else if (type == "IDAT") {
      compressed += png.substr(at + 8, length);
    }
    at += 12 + length;
  }
  const std::size_t stride = std::size_t(image.width) * std::size_t(image.channels);
  std::vector<unsigned char> raw((stride + 1) * std::size_t(image.height));
  uLongf raw_size = raw.size();
  if (uncompress(raw.data(), &raw_size, reinterpret_cast<const Bytef*>(compressed.data()),
                 compressed.size()) != Z_OK ||
      raw_size != raw.size()) {
    why = "its image data do not inflate to its size";
    return false;
  }
  image.pixels.assign(stride * std::size_t(image.height), 0);
  const int bpp = image.channels;
  for (std::size_t y = 0; y < std::size_t(image.height); ++y) {
    const unsigned char filter = raw[y * (stride + 1)];
    const unsigned char* in = &raw[y * (stride + 1) + 1];
    unsigned char* out = &image.pixels[y * stride];
    const unsigned char* up = y > 0 ? &image.pixels[(y - 1) * stride] : nullptr;
    for (std::size_t x = 0; x < stride; ++x) {
      const int a = x >= std::size_t(bpp) ? out[x - std::size_t(bpp)] : 0;
      const int b = up != nullptr ? up[x] : 0;
      const int c = up != nullptr && x >= std::size_t(bpp) ? up[x - std::size_t(bpp)] : 0;
      const int predicted = filter == 0   ? 0
                            : filter == 1 ? a
                            : filter == 2 ? b
                            : filter == 3 ? (a + b) / 2
                                          : paeth(a, b, c);
      out[x] = static_cast<unsigned char>(in[x] + predicted);
    }
  }
  return true;
}

// A run for the tests of the page's form: a third of the paper's minute is as good a page, at a
// third of the cost (these tests run under the sanitizers too).
const std::string kQuickSim = "sim --seed 3 --duration 20";

}  // namespace

// The verdict is mirrorcal-result.yaml's self-check, said first; the calibration beside it is the
// result file's, with its sigmas.
TEST(ReportFiles, OpensWithTheVerdictAndTheCalibrationOfTheResultFile) {
  TempDir dir("report-verdict");
  const std::string& d = dir.path;
  // A run locked onto a wrong solution (two passes, no restart: see cli_test), and a good run;
  // each command's output in its own folder.
  const std::vector<std::pair<std::string, std::string>> runs = {
      {"bad", "sim --passes 2 --scenario random --seed 14543870473635789003 --no-plots"},
      {"good", "sim --seed 3 --no-plots"}};
  for (const auto& [run, args] : runs) {
    const std::string out = d + "/" + run, log = d + "/" + run + "-log";
    fs::create_directories(log);
    // 3: written, and flagged (cli.hpp's kExitNotConsistent).
    ASSERT_EQ(run_mirrorcal(args + " --out " + out, log), run == "bad" ? 3 : 0)
        << slurp(log + "/command.log");
    const YAML::Node result = YAML::LoadFile(out + "/mirrorcal-result.yaml");
    const std::string report = slurp(out + "/report.txt");
    std::istringstream lines(report);
    std::string title, blank, verdict;
    std::getline(lines, title);
    std::getline(lines, blank);
    std::getline(lines, verdict);
    const bool consistent = result["consistent"].as<bool>();
    EXPECT_EQ(consistent, run == "good");
    EXPECT_EQ(verdict.rfind(consistent ? "VERDICT: consistent" : "VERDICT: NOT consistent", 0), 0u)
        << run << ": " << verdict;
    // Below it, every warning the command printed.
    std::istringstream printed(slurp(log + "/command.log"));
    int warnings = 0;
    for (std::string line; std::getline(printed, line);) {
      const std::string prefix = "mirrorcal: WARNING: ";
      if (line.rfind(prefix, 0) != 0) continue;
      ++warnings;
      EXPECT_NE(report.find("\n  WARNING: " + line.substr(prefix.size()) + "\n"), std::string::npos)
          << line;
    }
    EXPECT_EQ(warnings > 0, !consistent);
    // Each state's estimate and sigma as the result file has them (cm, printed to 1e-4).
    for (const char* axis : {"x", "y", "z"}) {
      const std::string name = std::string("p_") + axis;
      double estimate = 0, sigma = 0;
      const std::string line = line_starting(report, name + " ");
      ASSERT_EQ(std::sscanf(line.c_str() + name.size(), " cm %lf %lf", &estimate, &sigma), 2)
          << line;
      const int i = axis[0] - 'x';
      EXPECT_NEAR(estimate, 100.0 * result["p_b_c"][i].as<double>(), 6e-5) << name;
      EXPECT_NEAR(sigma, 100.0 * result["sigma"][name].as<double>(), 6e-5) << name;
    }
    // The page says the same, and that plots were not asked for.
    const std::string html = slurp(out + "/report.html");
    EXPECT_NE(html.find(consistent ? "class=\"ok\"" : "class=\"bad\""), std::string::npos);
    EXPECT_NE(html.find("Plots unavailable: not drawn (--no-plots)"), std::string::npos);
  }
}

// calibrate on a recording without truth: the residual statistics are those of residuals.csv
// recomputed here, cover every marker the filter took (used or gated), fit the pixel sigma the
// filter assumed, and the normalised innovation squared is the result file's.
TEST(ReportFiles, ResidualStatisticsAreThoseOfTheResidualsFile) {
  TempDir dir("report-residuals");
  const std::string& d = dir.path;
  ASSERT_EQ(run_mirrorcal("record --seed 4 --out " + d + "/rec", d), 0);
  ASSERT_TRUE(fs::remove(d + "/rec/truth.yaml"));  // a user's recording has none
  ASSERT_EQ(run_mirrorcal("calibrate " + d + "/rec --out " + d + "/cal", d), 0)
      << slurp(d + "/command.log");
  const std::string report = slurp(d + "/cal/report.txt");
  const YAML::Node result = YAML::LoadFile(d + "/cal/mirrorcal-result.yaml");
  EXPECT_EQ(report.find("NEES"), std::string::npos) << "no truth, no NEES";
  const std::vector<CsvResidual> csv = read_residuals_csv(d + "/cal/residuals.csv");
  ASSERT_GT(csv.size(), 1000u);

  const auto lengths = [&](int marker, bool all_frames) {
    std::vector<double> v;
    for (const CsvResidual& r : csv)
      if ((marker == 0 || r.marker == marker) && (r.settled || all_frames)) v.push_back(r.length);
    return v;
  };
  for (int m = 1; m <= 3; ++m)
    expect_row_matches(residual_row(report, "f" + std::to_string(m)), stats_of(lengths(m, false)),
                       "f" + std::to_string(m));
  const Row all = residual_row(report, "all");
  expect_row_matches(all, stats_of(lengths(0, false)), "all");
  const Row with_settling = residual_row(report, "+settling");
  expect_row_matches(with_settling, stats_of(lengths(0, true)), "+settling");
  // Every marker the final pass took, used or gated, has its residual.
  EXPECT_EQ(with_settling.n,
            result["markers_used"].as<std::size_t>() + result["markers_gated"].as<std::size_t>());
  // In pixel sigmas: the recording's sigma is 1 px.
  EXPECT_NEAR(all.mean_sigma, all.mean, 6e-4);
  // Residuals of markers whose noise is the assumed sigma: a 2-D normal's length has mean
  // sqrt(pi / 2) sigma.
  EXPECT_NEAR(all.mean, std::sqrt(M_PI / 2.0), 0.1);
  double squares = 0;
  std::size_t settled = 0;
  for (const CsvResidual& r : csv)
    if (r.settled) {
      squares += r.du * r.du + r.dv * r.dv;
      ++settled;
    }
  double rms = -1;
  std::sscanf(line_starting(report, "RMS per coordinate: ").c_str(), "RMS per coordinate: %lf",
              &rms);
  EXPECT_NEAR(rms, std::sqrt(squares / (2.0 * double(settled))), 6e-5);
  EXPECT_NEAR(rms, 1.0, 0.1);
  // The normalised innovation squared per degree of freedom is the self-check's.
  double nis = -1;
  long dof = -1;
  std::sscanf(line_starting(report, "per dof ").c_str(), "per dof %lf over %ld dof", &nis, &dof);
  EXPECT_NEAR(nis, result["nis_per_dof"].as<double>(), 1e-4);
  EXPECT_GT(dof, 10000);
}

// The page stands alone: every tag nests, nothing is fetched from elsewhere, each image is a PNG
// held in the page.
TEST(ReportFiles, HtmlIsWellFormedAndSelfContained) {
  TempDir dir("report-html");
  const std::string& d = dir.path;
  ASSERT_EQ(run_mirrorcal(kQuickSim + " --out " + d + "/sim", d), 0) << slurp(d + "/command.log");
  const std::string html = slurp(d + "/sim/report.html");
  ASSERT_EQ(html.rfind("<!DOCTYPE html>", 0), 0u);
  EXPECT_EQ(tag_nesting_error(html), "");
  EXPECT_TRUE(attribute_values(html, "href").empty());
  const std::vector<std::string> sources = attribute_values(html, "src");
  if (mc::evaluation::run_program({"gnuplot", "--version"}, "", d + "/gnuplot.log").status != 0) {
    EXPECT_TRUE(sources.empty());
    EXPECT_NE(html.find("Plots unavailable: "), std::string::npos);
    GTEST_SKIP() << "gnuplot is not installed: the page without plots was checked";
  }
  // The report's own plots and sim's error plots against the truth.
  EXPECT_GE(sources.size(), 12u);
  for (const std::string& src : sources) {
    const std::string prefix = "data:image/png;base64,";
    ASSERT_EQ(src.rfind(prefix, 0), 0u) << src.substr(0, 80);
    std::string png;
    ASSERT_TRUE(decode_base64(src.substr(prefix.size()), png));
    Image image;
    std::string why;
    EXPECT_TRUE(decode_png(png, image, why)) << why;
    EXPECT_GT(image.width, 100);
  }
}

// A real browser renders the page (Debian's chromium, headless): the screenshot is a PNG of the
// window's size that is far from blank.
TEST(ReportFiles, ChromiumRendersTheReport) {
  if (access("/usr/bin/chromium", X_OK) != 0)
    GTEST_SKIP() << "chromium is not installed (Debian: apt-get install chromium)";
  TempDir dir("report-chromium");
  const std::string& d = dir.path;
  ASSERT_EQ(run_mirrorcal(kQuickSim + " --out " + d + "/sim", d), 0) << slurp(d + "/command.log");
  const std::string shot = d + "/screenshot.png";
  // As root (a container, CI) chromium runs only without its sandbox; timeout ends a hung one.
  const mc::evaluation::ProgramExit chromium = mc::evaluation::run_program(
      {"timeout", "300", "chromium", "--headless", "--no-sandbox", "--disable-gpu",
       "--hide-scrollbars", "--user-data-dir=" + d + "/profile", "--window-size=1200,2400",
       "--screenshot=" + shot, "file://" + d + "/sim/report.html"},
      d, d + "/chromium.log");
  ASSERT_EQ(chromium.status, 0) << chromium.error << "\n" << slurp(d + "/chromium.log");
  Image image;
  std::string why;
  ASSERT_TRUE(decode_png(slurp(shot), image, why)) << why;
  EXPECT_EQ(image.width, 1200);
  EXPECT_EQ(image.height, 2400);
  // Pixels unlike the page's background (its top-left corner): text, the verdict, plots.
  const std::size_t n = std::size_t(image.width) * std::size_t(image.height);
  const int ch = image.channels;
  std::size_t drawn = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (std::memcmp(&image.pixels[i * std::size_t(ch)], &image.pixels[0], std::size_t(ch)) != 0)
      ++drawn;
  EXPECT_GT(double(drawn), 0.05 * double(n)) << drawn << " of " << n << " pixels drawn";
  // The verdict in its colour (#176b2c for a consistent run) is on the page.
  bool green = false;
  for (std::size_t i = 0; i < n && !green; ++i) {
    const unsigned char* p = &image.pixels[i * std::size_t(ch)];
    green = p[0] == 0x17 && p[1] == 0x6b && p[2] == 0x2c;
  }
  EXPECT_TRUE(green) << "the verdict's colour is not on the screenshot";
}

// The paper's motion observes every state: none is left weakly observed, whether judged against
// the user's guesses (stage 1) or against stage 1's calibration (stage 2, whose data bring the
// camera pose and markers to about 0.71 of stage 1's sigmas).
TEST(ReportFiles, ThePapersMotionLeavesNoStateWeaklyObserved) {
  TempDir dir("report-observed");
  const std::string& d = dir.path;
  for (const std::string args :
       {"sim --seed 2 --no-plots", "sim --seed 2 --intrinsics --no-plots"}) {
    ASSERT_EQ(run_mirrorcal(args + " --out " + d + "/out", d), 0) << slurp(d + "/command.log");
    const std::string report = slurp(d + "/out/report.txt");
    EXPECT_NE(line_starting(report, "weakly observed").find("helps): none"), std::string::npos)
        << args << "\n"
        << report;
    const bool stage2 = args.find("--intrinsics") != std::string::npos;
    EXPECT_EQ(report.find("started from an earlier calibration") != std::string::npos, stage2);
    if (!stage2) continue;
    // Stage 2's sigma of p_y against stage 1's, as the table prints it.
    double estimate = 0, sigma = 0, prior = 0, ratio = 0;
    std::sscanf(line_starting(report, "p_y ").c_str(), "p_y cm %lf %lf %lf %lf", &estimate, &sigma,
                &prior, &ratio);
    EXPECT_GT(ratio, 0.5);
    EXPECT_LT(ratio, 0.9);
  }
}

// The biases and gravity of report.txt are mirrorcal-result.yaml's, with sigmas the filter could
// have (positive, below their prior's); report.txt's per-axis residual line is residuals.csv's.
TEST(ReportFiles, BiasesGravityAndResidualAxesAreTheResultFilesAndResiduals) {
  TempDir dir("report-imu");
  const std::string& d = dir.path;
  ASSERT_EQ(run_mirrorcal("sim --seed 3 --no-plots --out " + d + "/out", d), 0)
      << slurp(d + "/command.log");
  const std::string report = slurp(d + "/out/report.txt");
  const YAML::Node imu = YAML::LoadFile(d + "/out/mirrorcal-result.yaml")["imu"];
  // "accelerometer [m/s^2]: x B +- S, y ...", "gyro [deg/s]: ..." to 5 decimals.
  double a[6] = {}, g[6] = {}, gravity[3] = {};
  ASSERT_EQ(std::sscanf(line_starting(report, "accelerometer [m/s^2]:").c_str(),
                        "accelerometer [m/s^2]: x %lf +- %lf, y %lf +- %lf, z %lf +- %lf", &a[0],
                        &a[1], &a[2], &a[3], &a[4], &a[5]),
            6);
  ASSERT_EQ(std::sscanf(line_starting(report, "gyro [deg/s]:").c_str(),
                        "gyro [deg/s]: x %lf +- %lf, y %lf +- %lf, z %lf +- %lf", &g[0], &g[1],
                        &g[2], &g[3], &g[4], &g[5]),
            6);
  ASSERT_EQ(std::sscanf(line_starting(report, "gravity in the mirror's frame").c_str(),
                        "gravity in the mirror's frame [m/s^2]: %lf %lf %lf", &gravity[0],
                        &gravity[1], &gravity[2]),
            3);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(a[2 * i], imu["accel_bias"][i].as<double>(), 6e-6);
    EXPECT_NEAR(a[2 * i + 1], imu["accel_bias_sigma"][i].as<double>(), 6e-6);
    EXPECT_NEAR(g[2 * i], imu["gyro_bias"][i].as<double>() * 180.0 / M_PI, 6e-6);
    EXPECT_NEAR(g[2 * i + 1], imu["gyro_bias_sigma"][i].as<double>() * 180.0 / M_PI, 6e-6);
    EXPECT_NEAR(gravity[i], imu["gravity_n"][i].as<double>(), 6e-5);
    // Below the priors' 0.03 m/s^2 and 0.002 rad/s (prior.hpp): a minute of motion sees them.
    EXPECT_GT(a[2 * i + 1], 0.0);
    EXPECT_LT(a[2 * i + 1], 0.03);
    EXPECT_GT(g[2 * i + 1], 0.0);
    EXPECT_LT(g[2 * i + 1], 0.002 * 180.0 / M_PI);
  }
  EXPECT_NEAR(imu["gravity_n"][1].as<double>(), -9.81, 1e-9);  // the paper's wall mirror, y up
  // "per axis [px]: u mean M std S max |u| X, v mean ..." against residuals.csv's settled rows.
  double u[3] = {}, v[3] = {};
  ASSERT_EQ(std::sscanf(line_starting(report, "per axis [px]:").c_str(),
                        "per axis [px]: u mean %lf std %lf max |u| %lf, v mean %lf std %lf max "
                        "|v| %lf",
                        &u[0], &u[1], &u[2], &v[0], &v[1], &v[2]),
            6);
  std::vector<double> du, dv, abs_u, abs_v;
  for (const CsvResidual& r : read_residuals_csv(d + "/out/residuals.csv"))
    if (r.settled) {
      du.push_back(r.du);
      dv.push_back(r.dv);
      abs_u.push_back(std::abs(r.du));
      abs_v.push_back(std::abs(r.dv));
    }
  ASSERT_FALSE(du.empty());
  const Row su = stats_of(du), sv = stats_of(dv);
  EXPECT_NEAR(u[0], su.mean, 6e-5);
  EXPECT_NEAR(u[1], su.std, 6e-5);
  EXPECT_NEAR(u[2], stats_of(abs_u).max, 6e-4);
  EXPECT_NEAR(v[0], sv.mean, 6e-5);
  EXPECT_NEAR(v[1], sv.std, 6e-5);
  EXPECT_NEAR(v[2], stats_of(abs_v).max, 6e-4);
}

// The IMU residuals' statistics in report.txt are those of imu_residuals.csv, computed here: the
// intervals, and per sensor and axis the mean and RMS, in SI and in the white noise's sigmas over
// each interval (the paper scenario's IMU is imu.yaml's default, the ADIS16448's); report.html
// plots them.
TEST(ReportFiles, ImuResidualStatisticsAreThoseOfTheImuResidualsFile) {
  TempDir dir("report-imu-residuals");
  const std::string& d = dir.path;
  ASSERT_EQ(run_mirrorcal("sim --seed 4 --duration 20 --out " + d + "/out", d), 0)
      << slurp(d + "/command.log");
  const std::string report = slurp(d + "/out/report.txt");
  std::vector<std::array<double, 7>> rows;  // interval, gyro xyz, accel xyz
  std::istringstream csv(slurp(d + "/out/imu_residuals.csv"));
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line.rfind("#time [s],interval [s],gyro x [rad/s]", 0), 0u) << line;
  while (std::getline(csv, line)) {
    std::array<double, 7> r{};
    double t = 0;
    ASSERT_EQ(std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf", &t, &r[0], &r[1], &r[2],
                          &r[3], &r[4], &r[5], &r[6]),
              8)
        << line;
    rows.push_back(r);
  }
  // 20 s at 60 Hz: an interval between each two frames the filter propagated across.
  ASSERT_GT(rows.size(), 1000u);
  std::size_t intervals = 0;
  double median_ms = 0;
  ASSERT_EQ(std::sscanf(line_starting(report, "IMU RESIDUALS", true).c_str(),
                        "%zu intervals, median %lf ms", &intervals, &median_ms),
            2);
  EXPECT_EQ(intervals, rows.size());
  std::vector<double> dt;
  for (const auto& r : rows) dt.push_back(r[0]);
  EXPECT_NEAR(median_ms, 1e3 * stats_of(dt).median, 0.06);
  const mc::ImuNoise noise{};
  for (int sensor = 0; sensor < 2; ++sensor) {
    const std::string name =
        sensor == 0 ? "gyro residual [rad/s]:" : "accelerometer residual [m/s^2]:";
    const double density = sensor == 0 ? noise.gyro_noise_density : noise.accel_noise_density;
    double mean[3], rms[3], mean_sigmas[3], rms_sigmas[3];
    ASSERT_EQ(std::sscanf(line_starting(report, name, true).c_str(),
                          "  per axis x y z: mean %lf %lf %lf, RMS %lf %lf %lf; in white-noise "
                          "sigmas: mean %lf %lf %lf, RMS %lf %lf %lf",
                          &mean[0], &mean[1], &mean[2], &rms[0], &rms[1], &rms[2], &mean_sigmas[0],
                          &mean_sigmas[1], &mean_sigmas[2], &rms_sigmas[0], &rms_sigmas[1],
                          &rms_sigmas[2]),
              12)
        << name;
    for (int axis = 0; axis < 3; ++axis) {
      double sum = 0, squares = 0, sum_sigmas = 0, squares_sigmas = 0;
      for (const auto& r : rows) {
        const double v = r[std::size_t(1 + 3 * sensor + axis)];
        const double in_sigmas = v * std::sqrt(r[0]) / density;
        sum += v;
        squares += v * v;
        sum_sigmas += in_sigmas;
        squares_sigmas += in_sigmas * in_sigmas;
      }
      const double n = double(rows.size());
      const std::string what = name + " axis " + std::to_string(axis);
      // Three significant digits (%.3g), or three decimals (%.3f).
      EXPECT_NEAR(mean[axis], sum / n, 6e-3 * std::abs(sum / n)) << what;
      EXPECT_NEAR(rms[axis], std::sqrt(squares / n), 6e-3 * std::sqrt(squares / n)) << what;
      EXPECT_NEAR(mean_sigmas[axis], sum_sigmas / n, 6e-4) << what;
      EXPECT_NEAR(rms_sigmas[axis], std::sqrt(squares_sigmas / n), 6e-4) << what;
      // The model's IMU: within its white noise (the smoothing takes some of it out).
      EXPECT_GT(rms_sigmas[axis], 0.0) << what;
      EXPECT_LT(rms_sigmas[axis], 1.0) << what;
    }
  }
  EXPECT_NE(slurp(d + "/out/report.html").find("IMU residuals per axis over time"),
            std::string::npos);
}

// Without gnuplot the page says the plots are unavailable and why; the text is the same.
TEST(ReportFiles, WithoutGnuplotThePageSaysSoAndTheTextIsWhole) {
  TempDir dir("report-no-gnuplot");
  const std::string& d = dir.path;
  ASSERT_EQ(run_mirrorcal(kQuickSim + " --no-plots --out " + d + "/plain", d), 0);
  const std::string path = getenv("PATH") != nullptr ? getenv("PATH") : "";
  setenv("PATH", (d + "/no-programs-here").c_str(), 1);  // mirrorcal finds no gnuplot
  const int status = run_mirrorcal(kQuickSim + " --out " + d + "/sim", d);
  setenv("PATH", path.c_str(), 1);
  ASSERT_EQ(status, 0) << slurp(d + "/command.log");
  const std::string html = slurp(d + "/sim/report.html");
  EXPECT_NE(html.find("<p>Plots unavailable: cannot run gnuplot"), std::string::npos);
  EXPECT_TRUE(attribute_values(html, "src").empty());
  EXPECT_EQ(tag_nesting_error(html), "");
  EXPECT_EQ(slurp(d + "/sim/report.txt"), slurp(d + "/plain/report.txt"));
}
