#include "mirrorcal/evaluation/plots.hpp"

#include <stdlib.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "mirrorcal/evaluation/process.hpp"

namespace mirrorcal::evaluation {

using namespace calibration;

std::vector<PlotGroup> plot_groups(const std::vector<ParamInfo>& params) {
  std::vector<PlotGroup> g = {
      {"error_p.png", "camera position in the IMU frame p_b_c", {}},
      {"error_rot.png", "camera rotation error log(R_true^T R_est)", {}},
      {"error_markers.png", "marker positions in the camera frame", {}},
      {"error_timeshift.png", "camera-IMU time offset timeshift_cam_imu", {}},
      {"error_intrinsics.png", "camera intrinsics", {}}};
  // In CalibrationGroup's order; the lens's coefficients with the intrinsics.
  for (std::size_t j = 0; j < params.size(); ++j) {
    const CalibrationGroup group = params[j].group;
    g[group == CalibrationGroup::kLens ? 4 : static_cast<std::size_t>(group)].params.push_back(j);
  }
  std::vector<PlotGroup> used;
  for (auto& x : g)
    if (!x.params.empty()) used.push_back(x);
  return used;
}

PlotFolder::PlotFolder(const std::string& prefix) {
  std::string pattern = (std::filesystem::temp_directory_path() / (prefix + "-XXXXXX")).string();
  if (mkdtemp(pattern.data()) != nullptr) path = pattern;
}

PlotFolder::~PlotFolder() {
  std::error_code ec;
  if (!path.empty()) std::filesystem::remove_all(path, ec);
}

std::string gnuplot_quoted(const std::string& text) {
  std::string q = "'";
  for (char c : text) {
    if (c == '\n') c = ' ';
    q += c == '\'' ? std::string("''") : std::string(1, c);
  }
  return q + "'";
}

namespace {

// errors.dat: one block per run (gnuplot's "index"), columns t, then error of each parameter.
// band.dat: t, the RMS over runs of 3 sigma for each parameter, then the mean NEES.
bool write_plot_data(const std::string& dir, const std::vector<ParamInfo>& params,
                     const std::vector<ErrorSeries>& runs, std::string& error) {
  std::ofstream e(dir + "/errors.dat"), b(dir + "/band.dat");
  for (const auto& r : runs) {
    for (std::size_t i = 0; i < r.t_s.size(); ++i) {
      e << r.t_s[i];
      for (std::size_t j = 0; j < params.size(); ++j) e << ' ' << r.error[j][i];
      e << '\n';
    }
    e << "\n\n";
  }
  const std::size_t n = runs[0].t_s.size();
  for (std::size_t i = 0; i < n; ++i) {
    b << runs[0].t_s[i];
    for (std::size_t j = 0; j < params.size(); ++j) {
      double s2 = 0;
      for (const auto& r : runs) s2 += i < r.t_s.size() ? r.sigma[j][i] * r.sigma[j][i] : 0.0;
      b << ' ' << 3.0 * std::sqrt(s2 / double(runs.size()));
    }
    double nees = 0;
    for (const auto& r : runs) nees += i < r.nees.size() ? r.nees[i] : 0.0;
    b << ' ' << nees / double(runs.size()) << '\n';
  }
  if (!e || !b) {
    error = "cannot write plot data in " + dir;
    return false;
  }
  return true;
}

// plots.gp: a picture of each parameter group's errors and +-3 sigma band, and one of the NEES.
// The script names only files in dir, where gnuplot runs: the folder's name (quotes, newlines,
// anything) never enters gnuplot's language, nor a shell's. The pictures it draws, or none with
// the error when it cannot be written.
std::vector<std::string> write_error_plot_script(const std::string& dir, const std::string& title,
                                                 const std::vector<ParamInfo>& params,
                                                 std::size_t runs, double nees_lo, double nees_hi,
                                                 std::string& error) {
  std::vector<std::string> written;
  std::ofstream g(dir + "/plots.gp");
  // noenhanced: titles render as written (enhanced text took the names' underscores for
  // subscripts: "timeshift_cam_imu" came out as "timeshift_c am_i mu").
  g << "set terminal pngcairo size 1500,900 font 'DejaVu Sans,10' noenhanced\nset grid\n"
    << "set key off\nset xlabel 'time [s]'\n";
  const std::string line = runs > 1 ? "lc rgb '#a0336699' lw 0.6" : "lc rgb '#336699' lw 1.2";
  // Each group twice: scaled to the converged estimate (+-4 times its smallest 3-sigma band, the
  // early errors running off the plot), and whole from the prior's sigmas, in which the converged
  // part is a flat line (<group>_from_prior.png).
  for (const bool from_prior : {false, true})
    for (const PlotGroup& grp : plot_groups(params)) {
      const std::size_t n = grp.params.size(), cols = 3, rows = (n + cols - 1) / cols;
      const std::string file =
          from_prior ? grp.file.substr(0, grp.file.size() - 4) + "_from_prior.png" : grp.file;
      g << "set output '" << file << "'\n"
        << "set multiplot layout " << rows << "," << cols << " title "
        << gnuplot_quoted(title + ": " + grp.label + " error and +-3 sigma" +
                          (from_prior ? ", from the prior" : ", converged"))
        << "\n";
      for (std::size_t j : grp.params) {
        const std::size_t c = j + 2;  // 1-based column in both files
        // stats keeps to the y range set last: the parameter before's range, which may hold
        // none of this one's band (then STATS_min is undefined and gnuplot stops).
        g << "set autoscale y\n";
        if (!from_prior)
          g << "stats 'band.dat' using " << c << " nooutput\n"
            << "if (STATS_min > 0) { set yrange [-4 * STATS_min : 4 * STATS_min] }\n";
        g << "set title " << gnuplot_quoted(params[j].name) << "\nset ylabel "
          << gnuplot_quoted(params[j].unit) << "\nplot 'errors.dat' using 1:" << c << " with lines "
          << line << ", 'band.dat' using 1:" << c << " with lines lc rgb '#cc2222' lw 1.5"
          << ", '' using 1:(-$" << c << ") with lines lc rgb '#cc2222' lw 1.5\n";
      }
      g << "unset multiplot\n";
      written.push_back(dir + "/" + file);
    }
  g << "set autoscale y\n";
  const std::size_t nc = params.size() + 2;
  g << "set output 'nees.png'\nset terminal pngcairo size 900,500 noenhanced\n"
    << "set title 'NEES of the " << params.size() << " calibration states, mean over " << runs
    << " run(s), with its 95 % interval'\nset ylabel 'NEES'\nset logscale y\n"
    << "plot 'band.dat' using 1:" << nc << " with lines lc rgb '#336699' lw 1.5, " << nees_lo
    << " lc rgb '#cc2222' dt 2, " << nees_hi << " lc rgb '#cc2222' dt 2\n";
  written.push_back(dir + "/nees.png");
  if (!g.flush()) {
    error = "cannot write " + dir + "/plots.gp";
    written.clear();
  }
  return written;
}

}  // namespace

std::vector<std::string> plot_errors(const std::string& dir, const std::string& title,
                                     const std::vector<ParamInfo>& params,
                                     const std::vector<ErrorSeries>& runs, double nees_lo,
                                     double nees_hi, std::string& error) {
  std::vector<std::string> written;
  if (runs.empty() || runs[0].t_s.empty()) {
    error = "nothing to plot";
    return written;
  }
  if (!write_plot_data(dir, params, runs, error)) return written;
  written = write_error_plot_script(dir, title, params, runs.size(), nees_lo, nees_hi, error);
  if (written.empty()) return written;
  const ProgramExit gnuplot = run_program({"gnuplot", "plots.gp"}, dir, dir + "/gnuplot.log");
  if (gnuplot.status != 0) {
    error = gnuplot.error +
            (gnuplot.status < 0 ? " (Debian: apt-get install gnuplot-nox)"
                                : " (see " + dir + "/gnuplot.log)") +
            "; data left in " + dir;
    written.clear();
    return written;
  }
  // The plot data of a large campaign runs to tens of MB: keep only the pictures.
  for (const char* f : {"/errors.dat", "/band.dat", "/plots.gp", "/gnuplot.log"})
    std::remove((dir + f).c_str());
  return written;
}

}  // namespace mirrorcal::evaluation
