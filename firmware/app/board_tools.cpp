// The board's build of the program: no simulation commands (nor record of the simulated rig), no
// plots (firmware/evaluation is the host's; a board has neither gnuplot nor a use for Monte Carlo
// campaigns).
#include <cstdio>

#include "build_tools.hpp"
#include "record.hpp"

namespace mirrorcal::app {

using namespace calibration;

namespace {

int host_only(const char* command) {
  std::fprintf(stderr,
               "mirrorcal %s: not in the board's build of mirrorcal; run it with the host's build "
               "(docs/usage.md)\n",
               command);
  return 2;
}

}  // namespace

int cmd_sim(int, char**) {
  return host_only("sim");
}
int cmd_montecarlo(int, char**) {
  return host_only("montecarlo");
}
int cmd_batch(int, char**) {
  return host_only("batch");
}
int record_simulated(const Options&, const std::string&) {
  std::fprintf(stderr,
               "mirrorcal record: the board's devices are recorded with --imu DEV (the "
               "simulated rig is the host's build's)\n");
  return 2;
}

ReportPlots report_plots(bool draw) {
  ReportPlots plots;
  plots.draw = draw;
  return plots;
}

AllanPlotter allan_plotter() {
  return nullptr;
}

}  // namespace mirrorcal::app
