// Plots people look at rather than read: calibration errors over time against their +-3 sigma
// bands, for one run and for a Monte Carlo set, drawn with gnuplot (Debian's gnuplot-nox).
#pragma once

#include <string>
#include <vector>

#include "mirrorcal/calibration/history.hpp"

namespace mirrorcal::evaluation {

using calibration::HistoryRow;
using calibration::ParamInfo;
using calibration::RecordStore;

// Error and 1-sigma of every calibration parameter over time, in display units.
struct ErrorSeries {
  std::vector<double> t_s;
  std::vector<std::vector<double>> error;  // [param][time]
  std::vector<std::vector<double>> sigma;  // [param][time]
  std::vector<double> nees;                // [time]
};

template <class Filter>
ErrorSeries error_series(const RecordStore<HistoryRow<Filter>>& rows,
                         const std::vector<ParamInfo>& params) {
  ErrorSeries s;
  s.error.resize(params.size());
  s.sigma.resize(params.size());
  for (const auto& r : rows) {
    s.t_s.push_back(double(r.t_ns) * 1e-9);
    s.nees.push_back(r.nees);
    for (std::size_t j = 0; j < params.size(); ++j) {
      s.error[j].push_back(r.error(int(j)) * params[j].scale);
      s.sigma[j].push_back(r.sigma(int(j)) * params[j].scale);
    }
  }
  return s;
}

// The calibration parameters drawn together, one picture per group (ParamInfo::group): p_b_c, the
// rotation, the markers, the time offset, the intrinsics with the lens (file: the error plot's PNG
// name).
struct PlotGroup {
  std::string file, label;
  std::vector<std::size_t> params;
};
std::vector<PlotGroup> plot_groups(const std::vector<ParamInfo>& params);

// A temporary folder for gnuplot's files, removed with it (path empty if it cannot be created).
struct PlotFolder {
  explicit PlotFolder(const std::string& prefix);  // $TMPDIR/<prefix>-XXXXXX
  ~PlotFolder();
  PlotFolder(const PlotFolder&) = delete;
  PlotFolder& operator=(const PlotFolder&) = delete;
  std::string path;
};

// text as a gnuplot string: single-quoted, where only a doubled quote is special.
std::string gnuplot_quoted(const std::string& text);

// Writes DIR/errors.dat and one PNG per parameter group (error_p.png, error_rot.png,
// error_markers.png, error_intrinsics.png). For several runs (Monte Carlo) every run is drawn and
// the band is the root mean square of the runs' sigmas; nees_bounds gives the NEES plot's 95 %
// interval. Returns the PNGs written, or an empty list with a reason in error.
std::vector<std::string> plot_errors(const std::string& dir, const std::string& title,
                                     const std::vector<ParamInfo>& params,
                                     const std::vector<ErrorSeries>& runs, double nees_lo,
                                     double nees_hi, std::string& error);

}  // namespace mirrorcal::evaluation
