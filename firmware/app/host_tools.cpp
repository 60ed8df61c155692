#include "build_tools.hpp"

#include "mirrorcal/evaluation/allan_plot.hpp"
#include "mirrorcal/evaluation/report_plots.hpp"

namespace mirrorcal::app {

using namespace calibration;
using namespace evaluation;

ReportPlots report_plots(bool draw) {
  ReportPlots plots;
  plots.draw = draw;
  plots.drawer = draw_report_figures;
  return plots;
}

AllanPlotter allan_plotter() {
  return draw_allan_plot;
}

}  // namespace mirrorcal::app
