// mirrorcal: IMU-camera self-calibration in front of a plane mirror.
//   mirrorcal sim [--scenario paper] [--seed N] [--out DIR]
//   mirrorcal montecarlo --runs N [--jobs J] [--seed S] [--out DIR]
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "mirrorcal/sim_host/simulator.hpp"
#include "plots.hpp"
#include "sim_run.hpp"

namespace mc = mirrorcal;
using mirrorcal::app::ErrorSeries;
using mirrorcal::app::ParamInfo;

namespace {

const char* kUsage =
    "usage: mirrorcal <command> [options]\n"
    "  sim         calibrate a simulated rig in front of a mirror\n"
    "              [--scenario paper] [--seed N] [--out DIR] [--no-plots]\n"
    "  montecarlo  N independent simulated calibrations, statistics against the paper\n"
    "              --runs N [--jobs J] [--seed S] [--scenario paper] [--out DIR] [--no-plots]\n";

struct Options {
  std::map<std::string, std::string> values;
  bool flag(const std::string& k) const { return values.count(k) != 0; }
  std::string get(const std::string& k, const std::string& def) const {
    auto it = values.find(k);
    return it == values.end() ? def : it->second;
  }
};

[[noreturn]] void fail(const std::string& msg, int code = 2) {
  std::fprintf(stderr, "mirrorcal: %s\n", msg.c_str());
  std::exit(code);
}

// Parses --key value and --flag; anything else is an error naming the argument.
Options parse(int argc, char** argv, int first, const std::vector<std::string>& with_value,
              const std::vector<std::string>& flags) {
  Options o;
  for (int i = first; i < argc; ++i) {
    const std::string a = argv[i];
    auto in = [&](const std::vector<std::string>& v) {
      for (const auto& s : v)
        if (a == "--" + s) return true;
      return false;
    };
    if (in(with_value)) {
      if (i + 1 >= argc) fail("option " + a + " needs a value\n" + kUsage);
      o.values[a.substr(2)] = argv[++i];
    } else if (in(flags)) {
      o.values[a.substr(2)] = "1";
    } else {
      fail("unknown argument '" + a + "'\n" + kUsage);
    }
  }
  return o;
}

std::uint64_t parse_count(const Options& o, const std::string& key, std::uint64_t def,
                          std::uint64_t min) {
  const std::string s = o.get(key, "");
  if (s.empty()) return def;
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(s.c_str(), &end, 10);
  if (errno != 0 || end == s.c_str() || *end != '\0' || s[0] == '-' || v < min)
    fail("--" + key + " must be an integer >= " + std::to_string(min) + ", not '" + s + "'");
  return v;
}

mc::sim::Scenario scenario_from(const Options& o) {
  mc::sim::Scenario s;
  const std::string name = o.get("scenario", "paper");
  if (!mc::sim::scenario_by_name(name, s)) fail("unknown scenario '" + name + "' (known: paper)");
  return s;
}

std::string make_out_dir(const Options& o, const std::string& def) {
  const std::string dir = o.get("out", def);
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) fail("cannot create output directory " + dir + ": " + ec.message(), 1);
  return dir;
}

// Display value of the truth of each calibration parameter: p and markers in cm, the rotation as
// the scenario's three angles in deg (R = Rz(c) Ry(b) Rx(a)).
std::vector<double> truth_display(const mc::sim::Scenario& s) {
  std::vector<double> t;
  for (int i = 0; i < 3; ++i) t.push_back(100.0 * s.truth.p_b_c(i));
  const Eigen::Vector3d zyx = s.truth.q_b_c.toRotationMatrix().eulerAngles(2, 1, 0);
  for (int i = 2; i >= 0; --i) t.push_back(zyx(i) * 180.0 / M_PI);
  for (const auto& m : s.truth.markers)
    for (int i = 0; i < 3; ++i) t.push_back(100.0 * m(i));
  return t;
}

// The paper's Tables I and II, final value and sigma, in our row order (rotation columns read as
// about x, y, z: see paper_scenario()).
struct PaperRow {
  double final_value, sigma;
};
const std::vector<PaperRow> kPaperTables = {
    {0.69, 0.53},   {-5.08, 0.16}, {10.12, 0.31}, {-89.99, 0.01}, {0.0, 0.02},
    {-89.98, 0.06}, {1.98, 0.03},  {-2.99, 0.03}, {-3.00, 0.03},  {4.98, 0.05},
    {4.00, 0.04},   {-3.00, 0.03}, {-8.01, 0.08}, {6.00, 0.06},   {0.99, 0.01}};

// Quantile of the chi-square distribution (Wilson-Hilferty; accurate to <1 % for k > 10).
double chi2_quantile(double p, double k) {
  // Standard normal quantile by Acklam's rational approximation is overkill here: the 2.5 % and
  // 97.5 % points are all we need.
  const double z = p < 0.5 ? -1.959963985 : 1.959963985;
  const double a = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - a + z * std::sqrt(a), 3.0);
}

void print_progress(const char* what, double f) {
  std::fprintf(stderr, "\r%s %3.0f %%", what, 100.0 * f);
  std::fflush(stderr);
}

int cmd_sim(int argc, char** argv) {
  const Options o = parse(argc, argv, 2, {"scenario", "seed", "out"}, {"no-plots"});
  const mc::sim::Scenario s = scenario_from(o);
  const std::uint64_t seed = parse_count(o, "seed", 1, 0);
  const std::string dir = make_out_dir(o, "out/sim");
  std::printf(
      "mirrorcal sim: scenario '%s', seed %llu, %.0f s of data (IMU %.0f Hz, camera %.0f Hz)\n",
      s.name.c_str(), static_cast<unsigned long long>(seed), s.duration_s, s.imu_rate_hz,
      s.camera_rate_hz);
  const auto t0 = std::chrono::steady_clock::now();
  const auto run =
      mc::app::run_simulation(s, seed, [](double f) { print_progress("calibrating", f); });
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::fprintf(stderr, "\rcalibrating done   \n");

  const auto& params = run.result.params;
  const auto truth = truth_display(s);
  const auto& first = run.history.front();
  const auto& last = run.history.back();
  std::printf("\n%-8s %-5s %12s %20s %20s %10s\n", "param", "unit", "truth", "after 1st frame +-1s",
              "final +-1sigma", "error/sig");
  for (std::size_t j = 0; j < params.size(); ++j) {
    const double sc = params[j].scale;
    std::printf("%-8s %-5s %12.4f %12.4f +-%-6.3f %12.4f +-%-6.4f %+10.2f\n",
                params[j].name.c_str(), params[j].unit.c_str(), truth[j],
                truth[j] + first.error(int(j)) * sc, first.sigma(int(j)) * sc,
                truth[j] + last.error(int(j)) * sc, last.sigma(int(j)) * sc,
                last.error(int(j)) / last.sigma(int(j)));
  }
  const auto& lc = run.loop_counters;
  const auto& fc = run.filter_counters;
  std::printf("\nNEES of the %zu calibration states: %.2f (95 %% interval %.2f..%.2f)\n",
              params.size(), last.nees, chi2_quantile(0.025, double(params.size())),
              chi2_quantile(0.975, double(params.size())));
  std::printf(
      "loop: %llu IMU samples, %llu frames (%llu without markers), %llu IMU gaps, "
      "%llu markers used, %llu gated, %llu filter failures; %.2f s wall\n",
      (unsigned long long)lc.imu_samples, (unsigned long long)lc.frames,
      (unsigned long long)lc.frames_without_markers, (unsigned long long)lc.imu_gaps,
      (unsigned long long)fc.markers_used, (unsigned long long)fc.markers_gated,
      (unsigned long long)fc.failures, wall);

  std::string err;
  if (!mc::app::write_camchain_imucam(dir + "/camchain-imucam.yaml", run.result, err) ||
      !mc::app::write_result_yaml(dir + "/mirrorcal-result.yaml", run.result, err) ||
      !mc::app::write_estimates_csv(dir + "/estimates.csv", run.history, err))
    fail(err, 1);
  std::printf("wrote %s/camchain-imucam.yaml, mirrorcal-result.yaml, estimates.csv\n", dir.c_str());
  if (!o.flag("no-plots")) {
    const std::vector<ErrorSeries> series = {mc::app::error_series(run.history, params)};
    const auto pngs =
        mc::app::plot_errors(dir, "mirrorcal sim, seed " + std::to_string(seed), params, series,
                             chi2_quantile(0.025, double(params.size())),
                             chi2_quantile(0.975, double(params.size())), err);
    if (pngs.empty()) std::fprintf(stderr, "mirrorcal: no plots: %s\n", err.c_str());
    for (const auto& p : pngs) std::printf("plot: %s\n", p.c_str());
  }
  return 0;
}

int cmd_montecarlo(int argc, char** argv) {
  const Options o = parse(argc, argv, 2, {"runs", "jobs", "seed", "out", "scenario"}, {"no-plots"});
  if (!o.flag("runs")) fail(std::string("montecarlo needs --runs N\n") + kUsage);
  const mc::sim::Scenario s = scenario_from(o);
  const std::uint64_t runs = parse_count(o, "runs", 0, 1);
  const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
  const std::uint64_t jobs = std::min<std::uint64_t>(parse_count(o, "jobs", hw, 1), runs);
  const std::uint64_t seed = parse_count(o, "seed", 1, 0);
  const std::string dir = make_out_dir(o, "out/montecarlo");
  std::printf("mirrorcal montecarlo: scenario '%s', %llu runs on %llu jobs, seed %llu\n",
              s.name.c_str(), (unsigned long long)runs, (unsigned long long)jobs,
              (unsigned long long)seed);

  struct Outcome {
    std::uint64_t seed = 0;
    std::vector<double> error, sigma;  // display units
    double nees = 0, wall_s = 0;
    std::uint64_t gated = 0, failures = 0;
    ErrorSeries series;
  };
  std::vector<Outcome> out(runs);
  std::vector<ParamInfo> params;
  std::atomic<std::uint64_t> next{0}, done{0};
  std::mutex mu;
  const auto t0 = std::chrono::steady_clock::now();
  auto worker = [&] {
    for (std::uint64_t i; (i = next++) < runs;) {
      const std::uint64_t run_seed = mc::sim::derive_seed(seed, 1000 + i);
      const auto t = std::chrono::steady_clock::now();
      const auto r = mc::app::run_simulation(s, run_seed);
      Outcome& oc = out[i];
      oc.seed = run_seed;
      oc.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
      const auto& last = r.history.back();
      for (std::size_t j = 0; j < r.result.params.size(); ++j) {
        oc.error.push_back(last.error(int(j)) * r.result.params[j].scale);
        oc.sigma.push_back(last.sigma(int(j)) * r.result.params[j].scale);
      }
      oc.nees = last.nees;
      oc.gated = r.filter_counters.markers_gated;
      oc.failures = r.filter_counters.failures;
      oc.series = mc::app::error_series(r.history, r.result.params);
      std::lock_guard<std::mutex> lock(mu);
      if (params.empty()) params = r.result.params;
      print_progress("runs done:", double(++done) / double(runs));
    }
  };
  std::vector<std::thread> pool;
  for (std::uint64_t j = 0; j < jobs; ++j) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::fprintf(stderr, "\n");

  const std::size_t np = params.size();
  const auto truth = truth_display(s);
  const double n = double(runs);
  std::vector<double> mean(np, 0), std_(np, 0), rms(np, 0), sig(np, 0);
  for (const auto& oc : out)
    for (std::size_t j = 0; j < np; ++j) {
      mean[j] += oc.error[j] / n;
      rms[j] += oc.error[j] * oc.error[j] / n;
      sig[j] += oc.sigma[j] * oc.sigma[j] / n;
    }
  for (const auto& oc : out)
    for (std::size_t j = 0; j < np; ++j)
      std_[j] += (oc.error[j] - mean[j]) * (oc.error[j] - mean[j]) / std::max(1.0, n - 1.0);
  double nees = 0;
  for (const auto& oc : out) nees += oc.nees / n;
  const double nees_lo = chi2_quantile(0.025, n * double(np)) / n;
  const double nees_hi = chi2_quantile(0.975, n * double(np)) / n;

  std::printf("\nTables I and II: final estimates over %llu runs (ours) beside the paper's\n",
              (unsigned long long)runs);
  std::printf("%-7s %-4s %9s | %9s %7s | %9s %8s %8s %8s | %s\n", "param", "unit", "truth", "paper",
              "sigma", "mean", "std", "rms err", "filter s", "rms < paper sigma");
  int beaten = 0;
  for (std::size_t j = 0; j < np; ++j) {
    const double r = std::sqrt(rms[j]);
    const PaperRow& p = kPaperTables[j];
    const bool ok = r < p.sigma;
    beaten += ok ? 1 : 0;
    std::printf("%-7s %-4s %9.3f | %9.2f %7.2f | %9.4f %8.4f %8.4f %8.4f | %s\n",
                params[j].name.c_str(), params[j].unit.c_str(), truth[j], p.final_value, p.sigma,
                truth[j] + mean[j], std::sqrt(std_[j]), r, std::sqrt(sig[j]), ok ? "yes" : "NO");
  }
  std::printf("\n%d of %zu parameters below the paper's sigma\n", beaten, np);
  std::printf("average NEES of the %zu calibration states: %.2f (95 %% interval %.2f..%.2f): %s\n",
              np, nees, nees_lo, nees_hi,
              nees >= nees_lo && nees <= nees_hi ? "consistent" : "NOT consistent");
  std::printf("wall time %.1f s (%.2f s per run on %llu jobs)\n", wall, wall / n * double(jobs),
              (unsigned long long)jobs);

  std::FILE* f = std::fopen((dir + "/summary.csv").c_str(), "w");
  if (!f) fail("cannot write " + dir + "/summary.csv", 1);
  std::fprintf(f, "parameter,unit,truth,mean_estimate,std,rms_error,paper_std\n");
  for (std::size_t j = 0; j < np; ++j)
    std::fprintf(f, "%s,%s,%.6f,%.6f,%.6f,%.6f,%.6f\n", params[j].name.c_str(),
                 params[j].unit.c_str(), truth[j], truth[j] + mean[j], std::sqrt(std_[j]),
                 std::sqrt(rms[j]), kPaperTables[j].sigma);
  std::fprintf(f,
               "# nees_mean=%.4f nees_95_lo=%.4f nees_95_hi=%.4f runs=%llu wall_s=%.2f jobs=%llu\n",
               nees, nees_lo, nees_hi, (unsigned long long)runs, wall, (unsigned long long)jobs);
  std::fclose(f);
  f = std::fopen((dir + "/runs.csv").c_str(), "w");
  if (!f) fail("cannot write " + dir + "/runs.csv", 1);
  std::fprintf(f, "run,seed");
  for (const auto& p : params) std::fprintf(f, ",err_%s [%s]", p.name.c_str(), p.unit.c_str());
  for (const auto& p : params) std::fprintf(f, ",sigma_%s [%s]", p.name.c_str(), p.unit.c_str());
  std::fprintf(f, ",nees,markers_gated,filter_failures,wall_s\n");
  for (std::size_t i = 0; i < out.size(); ++i) {
    std::fprintf(f, "%zu,%llu", i, (unsigned long long)out[i].seed);
    for (double e : out[i].error) std::fprintf(f, ",%.6g", e);
    for (double e : out[i].sigma) std::fprintf(f, ",%.6g", e);
    std::fprintf(f, ",%.4f,%llu,%llu,%.3f\n", out[i].nees, (unsigned long long)out[i].gated,
                 (unsigned long long)out[i].failures, out[i].wall_s);
  }
  std::fclose(f);
  std::printf("wrote %s/summary.csv, %s/runs.csv\n", dir.c_str(), dir.c_str());
  if (!o.flag("no-plots")) {
    std::vector<ErrorSeries> series;
    for (auto& oc : out) series.push_back(std::move(oc.series));
    std::string err;
    const auto pngs =
        mc::app::plot_errors(dir, "mirrorcal Monte Carlo, " + std::to_string(runs) + " runs",
                             params, series, nees_lo, nees_hi, err);
    if (pngs.empty()) std::fprintf(stderr, "mirrorcal: no plots: %s\n", err.c_str());
    for (const auto& p : pngs) std::printf("plot: %s\n", p.c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    std::fputs(kUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  const std::string cmd = argv[1];
  if (cmd == "sim") return cmd_sim(argc, argv);
  if (cmd == "montecarlo") return cmd_montecarlo(argc, argv);
  fail("unknown command '" + cmd + "'\n" + kUsage);
}
