// imu-noise's allan.png, drawn with gnuplot (Debian's gnuplot-nox): the six Allan deviations on
// log-log axes with the white-noise and random-walk lines fitted to them. The host's program hands
// draw_allan_plot to write_imu_noise (calibration's AllanPlotter).
#pragma once

#include <string>

#include "mirrorcal/calibration/imu_noise.hpp"

namespace mirrorcal::evaluation {

// allan.png's bytes into png, drawn in a temporary folder removed after; false with the reason in
// why if gnuplot cannot draw it.
bool draw_allan_plot(const calibration::ImuNoiseAnalysis& a, std::string& png, std::string& why);

}  // namespace mirrorcal::evaluation
