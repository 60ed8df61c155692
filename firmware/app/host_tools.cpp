#include "build_tools.hpp"

#include <cstdio>

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

#ifndef MIRRORCAL_BATCH
int cmd_batch(int, char**) {
  std::fprintf(stderr,
               "mirrorcal batch: this build has no batch solver (MIRRORCAL_BATCH off: Ceres, "
               "Debian's libceres-dev, was not built in)\n");
  return 2;
}
#endif

}  // namespace mirrorcal::app
