// What the host's build of the program has and the board's does not (firmware/evaluation, which
// the board's program does not link): the sim and montecarlo commands, report.html's plots and
// imu-noise's allan.png.
// host_tools.cpp or board_tools.cpp defines these (MIRRORCAL_HOST_TOOLS).
#pragma once

#include "mirrorcal/calibration/imu_noise_files.hpp"
#include "mirrorcal/calibration/report.hpp"

namespace mirrorcal::app {

using calibration::ReportPlots;

int cmd_sim(int argc, char** argv);
int cmd_montecarlo(int argc, char** argv);
// The batch maximum-likelihood reference (cmd_batch.cpp; a build without Ceres says so).
int cmd_batch(int argc, char** argv);

// How report.html gets its plots in this build (draw: false for --no-plots).
ReportPlots report_plots(bool draw = true);

// What draws imu-noise's allan.png in this build (nullptr: none).
calibration::AllanPlotter allan_plotter();

}  // namespace mirrorcal::app
