#include "mirrorcal/evaluation/report_plots.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/evaluation/plots.hpp"
#include "mirrorcal/evaluation/process.hpp"

namespace mirrorcal::evaluation {

using namespace calibration;

namespace {

constexpr double kDeg = 180.0 / M_PI;

int marker_count(const ReportData& d) {
  return static_cast<int>(d.result.markers.size());
}

struct Figure {
  std::string file, caption;
};

constexpr double kHistogramBin = 0.25;  // sigmas
constexpr int kHistogramBins = 40;      // over +-5 sigma

// The density of the settled residuals' u and v components in pixel sigmas, per bin.
void write_histogram(std::ostream& h, const ReportData& d) {
  std::vector<double> u(kHistogramBins, 0.0), v(kHistogramBins, 0.0);
  double n = 0.0;
  const auto add = [](std::vector<double>& bins, double x) {
    const double at = std::floor(x / kHistogramBin) + kHistogramBins / 2;
    if (at >= 0.0 && at < kHistogramBins) bins[std::size_t(at)] += 1.0;
  };
  for (const ResidualSample r : d.residuals) {
    if (!r.settled) continue;
    n += 1.0;
    add(u, r.du / d.pixel_sigma);
    add(v, r.dv / d.pixel_sigma);
  }
  for (int b = 0; b < kHistogramBins; ++b)
    h << (b - kHistogramBins / 2 + 0.5) * kHistogramBin << ' '
      << u[std::size_t(b)] / (std::max(n, 1.0) * kHistogramBin) << ' '
      << v[std::size_t(b)] / (std::max(n, 1.0) * kHistogramBin) << '\n';
}

void write_plot_data(const std::string& dir, const ReportData& d) {
  // residuals.dat: one block per marker (gnuplot's "index"), its settled residuals.
  std::ofstream r(dir + "/residuals.dat");
  for (int m = 0; m < marker_count(d); ++m) {
    for (const ResidualSample s : d.residuals)
      if (s.marker == m && s.settled)
        r << s.t_s << ' ' << s.du << ' ' << s.dv << ' ' << std::hypot(s.du, s.dv) << '\n';
    r << "\n\n";
  }
  std::ofstream h(dir + "/histogram.dat");
  write_histogram(h, d);
  // series.dat: t, then estimate and sigma of each state, accel bias xyz, gyro bias xyz (deg/s),
  // rotation from the first pose xyz (deg), position along the normal (cm), markers seen.
  std::ofstream s(dir + "/series.dat");
  for (const ReportRow row : d.rows) {
    s << row.t_s;
    for (std::size_t j = 0; j < d.result.params.size(); ++j)
      s << ' ' << row.estimate[j] << ' ' << row.sigma[j];
    for (int i = 0; i < 3; ++i) s << ' ' << row.accel_bias(i);
    for (int i = 0; i < 3; ++i) s << ' ' << row.gyro_bias(i) * kDeg;
    for (int i = 0; i < 3; ++i) s << ' ' << row.rotation(i) * kDeg;
    s << ' ' << 100.0 * row.normal_position << ' ';
    if (row.markers_seen >= 0)
      s << row.markers_seen;
    else
      s << "NaN";
    s << '\n';
  }
  // imu_residuals.dat: t, the gyro's residual xyz and the accelerometer's, each sensor's white
  // noise 1-sigma over the interval.
  std::ofstream imu(dir + "/imu_residuals.dat");
  const ImuNoise& noise = d.result.imu.noise;
  if (d.imu_residuals)
    for (const ImuResidual r : *d.imu_residuals) {
      if (!(r.dt_s > 0.0)) continue;
      imu << double(r.t_ns) * 1e-9;
      for (int i = 0; i < 3; ++i) imu << ' ' << r.gyro(i);
      for (int i = 0; i < 3; ++i) imu << ' ' << r.accel(i);
      imu << ' ' << noise.gyro_noise_density / std::sqrt(r.dt_s) << ' '
          << noise.accel_noise_density / std::sqrt(r.dt_s) << '\n';
    }
  std::ofstream n(dir + "/nis.dat");
  for_each_nis_window(d, [&n](const NisWindow& w) {
    n << w.t_s << ' ' << w.nis / w.dof << ' ' << chi2_quantile(0.025, w.dof) / w.dof << ' '
      << chi2_quantile(0.975, w.dof) / w.dof << '\n';
  });
}

// The range of state j's +-3 sigma band once the estimate settled, with a margin: the first
// frames' wide band would hide the rest.
std::pair<double, double> settled_band(const ReportData& d, std::size_t j) {
  double lo = INFINITY, hi = -INFINITY;
  for (const ReportRow row : d.rows) {
    if (row.t_s < d.settled_from_s) continue;
    lo = std::min(lo, row.estimate[j] - 3.0 * row.sigma[j]);
    hi = std::max(hi, row.estimate[j] + 3.0 * row.sigma[j]);
  }
  if (!(lo < hi)) return {-1.0, 1.0};
  const double margin = 0.1 * (hi - lo);
  return {lo - margin, hi + margin};
}

// The residuals: scattered against their 3-sigma circle, their histogram against the normal
// density, their length over time, and the normalised innovation squared against its band.
void write_residual_plots(std::ostream& g, const ReportData& d, std::vector<Figure>& figures) {
  const double sigma = d.pixel_sigma;
  const int count = marker_count(d);
  g << "set output 'residual_scatter.png'\nset size ratio -1\nset key outside right\n"
    << "set title 'Reprojection residuals (measured - predicted) once the estimate settled, with "
       "the 3-sigma circle'\nset xlabel 'u [px]'\nset ylabel 'v [px]'\nset parametric\nplot ";
  for (int m = 0; m < count; ++m)
    g << "'residuals.dat' index " << m << " using 2:3 with points pt 7 ps 0.3 title 'f" << m + 1
      << "', ";
  g << 3.0 * sigma << "*cos(t), " << 3.0 * sigma << "*sin(t) lc rgb '#cc2222' lw 2 title "
    << "'3 sigma'\nunset parametric\nset size noratio\n";
  figures.push_back({"residual_scatter.png", "Reprojection residuals of every marker"});

  g << "set output 'residual_histogram.png'\nset title 'Residual components in pixel sigmas, "
       "against the standard normal density'\nset xlabel 'residual / pixel sigma'\n"
    << "set ylabel 'density'\nset style fill transparent solid 0.4\nset boxwidth " << kHistogramBin
    << "\nset xrange [-5:5]\n"
    << "plot 'histogram.dat' using 1:2 with boxes lc rgb '#336699' title 'u', '' using 1:3 with "
       "boxes lc rgb '#66aa66' title 'v', exp(-x * x / 2) / sqrt(2 * pi) lw 2 lc rgb '#cc2222' "
       "title 'N(0, 1)'\nset style fill empty\nset autoscale x\n";
  figures.push_back({"residual_histogram.png", "Histogram of the residuals' components"});

  g << "set output 'residual_time.png'\nset title 'Residual length over time, once the estimate "
       "settled'\n"
    << "set xlabel 'time [s]'\nset ylabel '|residual| [px]'\nset logscale y\nplot ";
  for (int m = 0; m < count; ++m)
    g << (m > 0 ? ", " : "") << "'residuals.dat' index " << m
      << " using 1:4 with points pt 7 ps 0.2 title 'f" << m + 1 << "'";
  g << "\nunset logscale y\n";
  figures.push_back({"residual_time.png", "Residuals over time"});

  g << "set output 'residual_axes.png'\nset multiplot layout 2,1 title 'Reprojection residuals "
       "per axis over time, once the estimate settled, with +-3 pixel sigmas'\n";
  for (int axis = 0; axis < 2; ++axis) {
    g << "set title '" << (axis == 0 ? "u" : "v") << "'\nset ylabel 'px'\nset yrange ["
      << -5.0 * sigma << ":" << 5.0 * sigma << "]\nplot ";
    for (int m = 0; m < count; ++m)
      g << "'residuals.dat' index " << m << " using 1:" << 2 + axis
        << " with points pt 7 ps 0.2 title 'f" << m + 1 << "', ";
    g << 3.0 * sigma << " lc rgb '#cc2222' dt 2 title '+-3 sigma', " << -3.0 * sigma
      << " lc rgb '#cc2222' dt 2 notitle\n";
  }
  g << "unset multiplot\nset autoscale y\n";
  figures.push_back({"residual_axes.png", "Reprojection residuals per axis over time"});

  g << "set output 'nis.png'\nset title 'Normalised innovation squared per dof over windows of "
    << kNisWindowFrames << " frames, with its 95 % chi-square band'\nset ylabel 'NIS / dof'\n"
    << "plot 'nis.dat' using 1:2 with linespoints pt 7 ps 0.5 lc rgb '#336699' title 'NIS / dof', "
       "'' using 1:3 with lines dt 2 lc rgb '#cc2222' title '2.5 %', '' using 1:4 with lines dt "
       "2 lc rgb '#cc2222' title '97.5 %'\n";
  figures.push_back({"nis.png", "Normalised innovation squared against its chi-square band"});
}

// Each calibration group's estimate over time with its +-3 sigma band.
void write_estimate_plots(std::ostream& g, const ReportData& d, std::vector<Figure>& figures) {
  g << "set key off\n";
  const std::vector<ParamInfo>& params = d.result.params;
  for (const PlotGroup& grp : plot_groups(params)) {
    const std::string file = "estimate_" + grp.file.substr(grp.file.find('_') + 1);
    const std::size_t rows = (grp.params.size() + 2) / 3;
    const bool rotation = params[grp.params[0]].group == CalibrationGroup::kCameraRotation;
    g << "set output '" << file << "'\nset multiplot layout " << rows << ",3 title "
      << gnuplot_quoted(rotation ? "camera rotation relative to the final estimate, "
                                   "log(R_final^T R), with +-3 sigma"
                                 : grp.label.substr(0, grp.label.find(" error")) +
                                       ": estimate with +-3 sigma")
      << "\n";
    for (std::size_t j : grp.params) {
      const std::size_t c = 2 + 2 * j;  // estimate's column; sigma's is c + 1
      const auto [lo, hi] = settled_band(d, j);
      g << "set title " << gnuplot_quoted(params[j].name) << "\nset ylabel "
        << gnuplot_quoted(params[j].unit) << "\nset yrange [" << lo << ":" << hi << "]\n"
        << "plot 'series.dat' using 1:" << c << " with lines lc rgb '#336699' lw 1.2, '' using 1:($"
        << c << " + 3 * $" << c + 1 << ") with lines dt 2 lc rgb '#cc2222', '' using 1:($" << c
        << " - 3 * $" << c + 1 << ") with lines dt 2 lc rgb '#cc2222'\n";
    }
    g << "unset multiplot\nset autoscale y\n";
    figures.push_back({file, grp.label.substr(0, grp.label.find(" error")) +
                                 " over time (the first seconds, before the estimate settled, "
                                 "may run off the scale)"});
  }
}

// The IMU's biases, and the excitation: rotation, motion along the mirror's normal, markers seen.
void write_motion_plots(std::ostream& g, const ReportData& d, std::vector<Figure>& figures) {
  const int count = marker_count(d);
  const std::vector<ParamInfo>& params = d.result.params;
  const std::size_t extra = 2 + 2 * params.size();  // first column after the states'
  g << "set output 'imu_bias.png'\nset key on\nset multiplot layout 1,2 title 'IMU bias "
       "estimates'\n";
  const char* axes[3] = {"x", "y", "z"};
  for (int part = 0; part < 2; ++part) {
    g << "set title '" << (part == 0 ? "accelerometer" : "gyro") << "'\nset ylabel '"
      << (part == 0 ? "m/s^2" : "deg/s") << "'\nplot ";
    for (int i = 0; i < 3; ++i)
      g << (i > 0 ? ", " : "") << "'series.dat' using 1:" << extra + std::size_t(3 * part + i)
        << " with lines title '" << axes[i] << "'";
    g << "\n";
  }
  g << "unset multiplot\n";
  figures.push_back({"imu_bias.png", "IMU bias estimates"});

  g << "set output 'excitation.png'\nset multiplot layout 3,1 title 'Excitation'\n"
    << "set title 'rotation from the first pose, about the IMU axes'\nset ylabel 'deg'\nplot ";
  for (int i = 0; i < 3; ++i)
    g << (i > 0 ? ", " : "") << "'series.dat' using 1:" << extra + 6 + std::size_t(i)
      << " with lines title '" << axes[i] << "'";
  g << "\nset key off\nset title 'position along the mirror normal'\nset ylabel 'cm'\n"
    << "plot 'series.dat' using 1:" << extra + 9 << " with lines lc rgb '#336699'\n"
    << "set title 'markers per frame'\nset ylabel 'markers'\nset yrange [-0.5:" << count + 0.5
    << "]\nplot 'series.dat' using 1:" << extra + 10
    << " with points pt 7 ps 0.2 lc rgb '#336699'\nunset multiplot\n";
  figures.push_back({"excitation.png", "Motion and markers seen"});
}

// The IMU's residuals per axis over time, scaled to themselves, with +-3 of the white noise's
// sigmas over each interval when those lie inside (Kalibr's accelerometer and gyroscope error
// plots); the title gives that bound when it lies outside, as it does where the frames pin the
// motion less than the IMU's noise would.
void write_imu_residual_plot(std::ostream& g, const ReportData& d, std::vector<Figure>& figures) {
  if (!d.imu_residuals) return;
  std::array<double, 2> largest{}, bound{};  // per sensor: the largest |residual|, 3 sigmas
  for (int part = 0; part < 2; ++part)
    for (int axis = 0; axis < 3; ++axis)
      for_each_imu_residual(d, part, axis, [&](double value, double sigmas) {
        largest[std::size_t(part)] = std::max(largest[std::size_t(part)], std::abs(value));
        if (sigmas != 0.0)
          bound[std::size_t(part)] = std::max(bound[std::size_t(part)], 3.0 * value / sigmas);
      });
  if (!(largest[0] > 0.0)) return;
  g << "set output 'imu_residuals.png'\nset key on\nset multiplot layout 2,1 title 'IMU residuals "
       "along the smoothed motion per axis'\n";
  const char* axes[3] = {"x", "y", "z"};
  for (int part = 0; part < 2; ++part) {
    const double range = 1.15 * std::max(largest[std::size_t(part)], 1e-12);
    const bool bound_shown = bound[std::size_t(part)] <= range;
    const char* unit = part == 0 ? "rad/s" : "m/s^2";
    std::ostringstream bound_text;
    bound_text << std::setprecision(3) << bound[std::size_t(part)] << ' ' << unit;
    g << "set title "
      << gnuplot_quoted(std::string(part == 0 ? "gyroscope" : "accelerometer") +
                        (bound_shown ? ", with +-3 sigmas of the white noise"
                                     : ": +-3 sigmas of the white noise, " + bound_text.str() +
                                           ", lie beyond the scale"))
      << "\nset ylabel '" << unit << "'\nset yrange [" << -range << ":" << range << "]\nplot ";
    for (int i = 0; i < 3; ++i)
      g << (i > 0 ? ", " : "") << "'imu_residuals.dat' using 1:" << 2 + 3 * part + i
        << " with points pt 7 ps 0.2 title '" << axes[i] << "'";
    if (bound_shown)
      g << ", '' using 1:(3 * $" << 8 + part << ") with lines dt 2 lc rgb '#cc2222' title "
        << "'+-3 sigma', '' using 1:(-3 * $" << 8 + part
        << ") with lines dt 2 lc rgb '#cc2222' notitle";
    g << "\n";
  }
  g << "unset multiplot\nset autoscale y\n";
  figures.push_back({"imu_residuals.png", "IMU residuals per axis over time"});
}

// The gnuplot script, and the figures it draws.
std::vector<Figure> write_plot_script(std::ostream& g, const ReportData& d) {
  std::vector<Figure> figures;
  // Titles hold names such as p_b_c: no subscripts.
  g << "set terminal pngcairo size 1200,700 font 'DejaVu Sans,10' noenhanced\nset grid\n";
  write_residual_plots(g, d, figures);
  write_imu_residual_plot(g, d, figures);
  write_estimate_plots(g, d, figures);
  write_motion_plots(g, d, figures);
  return figures;
}

}  // namespace

std::vector<ReportFigure> draw_report_figures(const ReportData& d, std::string& why) {
  std::vector<ReportFigure> drawn;
  if (d.rows.empty()) {
    why = "no frame was calibrated from";
    return drawn;
  }
  const PlotFolder folder("mirrorcal-report");
  if (folder.path.empty()) {
    why = "cannot create a temporary folder";
    return drawn;
  }
  write_plot_data(folder.path, d);
  std::vector<Figure> figures;
  {
    std::ofstream g(folder.path + "/report.gp");
    figures = write_plot_script(g, d);
    if (!g.flush()) {
      why = "cannot write the plot script";
      return drawn;
    }
  }
  const ProgramExit gnuplot =
      run_program({"gnuplot", "report.gp"}, folder.path, folder.path + "/gnuplot.log");
  if (gnuplot.status != 0) {
    std::string log, ignored;
    io::read_file(folder.path + "/gnuplot.log", log, ignored);
    why = gnuplot.error + (gnuplot.status < 0 ? " (Debian: apt-get install gnuplot-nox)"
                                              : ": " + log.substr(0, 500));
    return drawn;
  }
  for (const Figure& f : figures) {
    std::string png, error;
    if (io::read_file(folder.path + "/" + f.file, png, error)) drawn.push_back({f.caption, png});
  }
  return drawn;
}

}  // namespace mirrorcal::evaluation
