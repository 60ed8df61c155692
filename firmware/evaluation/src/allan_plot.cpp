#include "mirrorcal/evaluation/allan_plot.hpp"

#include <algorithm>
#include <fstream>

#include "mirrorcal/evaluation/plots.hpp"
#include "mirrorcal/evaluation/process.hpp"
#include "mirrorcal/io/files.hpp"

namespace mirrorcal::evaluation {

using namespace calibration;

namespace {

const char* const kAxisColours[3] = {"#cc2222", "#228833", "#2255cc"};

// One sensor's panel: its three curves, and each axis's fitted lines dashed in its colour.
void write_panel(std::ostream& g, const ImuNoiseAnalysis& a, int first_axis, const char* title,
                 const char* unit) {
  double lo = 1e300, hi = 0.0;
  for (int axis = first_axis; axis < first_axis + 3; ++axis)
    for (double v : a.adev[std::size_t(axis)])
      if (v > 0.0) {
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
  g << "set title " << gnuplot_quoted(title) << "\nset ylabel "
    << gnuplot_quoted(std::string("Allan deviation [") + unit + "]") << "\nset yrange [" << lo / 3.0
    << ":" << hi * 3.0 << "]\nplot ";
  for (int i = 0; i < 3; ++i) {
    const int axis = first_axis + i;
    g << (i ? ", " : "") << "'allan.dat' using 1:" << axis + 2 << " with linespoints lc rgb '"
      << kAxisColours[i] << "' pt 7 ps 0.5 title " << gnuplot_quoted(imu_axis_name(axis));
  }
  for (int i = 0; i < 3; ++i) {
    const AxisNoise& x = a.axes[std::size_t(first_axis + i)];
    const std::string style =
        std::string(" with lines dt 2 lw 1.5 lc rgb '") + kAxisColours[i] + "' notitle";
    if (x.white.resolved) g << ", " << x.white.value << "/sqrt(x)" << style;
    if (x.random_walk.resolved) g << ", " << x.random_walk.value << "*sqrt(x/3.0)" << style;
  }
  g << "\n";
}

}  // namespace

bool draw_allan_plot(const ImuNoiseAnalysis& a, std::string& png, std::string& why) {
  if (a.tau_s.empty()) {
    why = "no Allan deviation to draw";
    return false;
  }
  const PlotFolder folder("mirrorcal-allan");
  if (folder.path.empty()) {
    why = "cannot create a temporary folder";
    return false;
  }
  {
    std::ofstream d(folder.path + "/allan.dat");
    d.precision(9);
    for (std::size_t k = 0; k < a.tau_s.size(); ++k) {
      d << a.tau_s[k];
      for (const auto& curve : a.adev) d << ' ' << curve[k];
      d << '\n';
    }
    // The script names only files in the folder: the recording's name enters as a quoted string.
    std::ofstream g(folder.path + "/allan.gp");
    g << "set terminal pngcairo size 1400,600 font 'DejaVu Sans,10' noenhanced\n"
      << "set output 'allan.png'\nset logscale xy\nset grid xtics ytics mxtics mytics\n"
      << "set format y '%.0e'\nset samples 200\nset key top right\n"
      << "set xlabel 'cluster time tau [s]'\nset xrange [" << a.tau_s.front() << ":"
      << a.tau_s.back() << "]\n"
      << "set multiplot layout 1,2 title "
      << gnuplot_quoted("Allan deviation of " + a.file +
                        " (dashed: the fitted white-noise "
                        "and random-walk lines)")
      << "\n";
    write_panel(g, a, 0, "gyroscope", "rad/s");
    write_panel(g, a, 3, "accelerometer", "m/s^2");
    g << "unset multiplot\n";
    if (!d.flush() || !g.flush()) {
      why = "cannot write the plot's data in " + folder.path;
      return false;
    }
  }
  const ProgramExit gnuplot =
      run_program({"gnuplot", "allan.gp"}, folder.path, folder.path + "/gnuplot.log");
  if (gnuplot.status != 0) {
    std::string log, ignored;
    io::read_file(folder.path + "/gnuplot.log", log, ignored);
    why = gnuplot.error + (gnuplot.status < 0 ? " (Debian: apt-get install gnuplot-nox)"
                                              : ": " + log.substr(0, 500));
    return false;
  }
  return io::read_file(folder.path + "/allan.png", png, why);
}

}  // namespace mirrorcal::evaluation
