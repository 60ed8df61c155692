// What the host's build of the program has and the board's does not (firmware/evaluation, which
// the board's program does not link, and the bag readers' libraries): the sim and montecarlo
// commands, report.html's plots, imu-noise's allan.png and recordings in ROS bags.
// host_tools.cpp or board_tools.cpp defines these (MIRRORCAL_HOST_TOOLS).
#pragma once

#include "mirrorcal/calibration/imu_noise_files.hpp"
#include "mirrorcal/calibration/report.hpp"
#include "mirrorcal/sim_host/bags.hpp"

namespace mirrorcal::app {

using calibration::ReportPlots;

int cmd_sim(int argc, char** argv);
int cmd_montecarlo(int argc, char** argv);

// How report.html gets its plots in this build (draw: false for --no-plots).
ReportPlots report_plots(bool draw = true);

// What draws imu-noise's allan.png in this build (nullptr: none).
calibration::AllanPlotter allan_plotter();

// sim::open_bag_recording in the host's build; the board's says to calibrate bags on the host.
bool open_bag(const std::string& path, const sim::BagOptions& options, int markers,
              sim::Recording& out, std::string& error);

}  // namespace mirrorcal::app
