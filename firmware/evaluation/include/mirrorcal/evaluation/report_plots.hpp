// report.html's plots, drawn with gnuplot (Debian's gnuplot-nox): the settled residuals against
// their 3-sigma circle and their histogram, the residuals and the normalised innovation squared
// over time, each calibration group's estimate with its +-3 sigma band, the IMU biases and the
// excitation. The host's program hands draw_report_figures to the report (ReportPlots::drawer).
#pragma once

#include <string>
#include <vector>

#include "mirrorcal/calibration/report.hpp"

namespace mirrorcal::evaluation {

using calibration::ReportData;
using calibration::ReportFigure;

// The figures, drawn in a temporary folder that is removed after; none, with the reason in why,
// if there is nothing to draw or gnuplot cannot draw it.
std::vector<ReportFigure> draw_report_figures(const ReportData& d, std::string& why);

}  // namespace mirrorcal::evaluation
