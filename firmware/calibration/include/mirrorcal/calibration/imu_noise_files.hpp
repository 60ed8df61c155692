// `mirrorcal imu-noise`'s files: a still recording's IMU samples read, and the figures written as
// Kalibr's imu.yaml with the Allan deviations (allan.csv) and their plot (allan.png), as one set.
#pragma once

#include <string>
#include <vector>

#include "mirrorcal/calibration/imu_noise.hpp"

namespace mirrorcal::calibration {

// The IMU data of path: a recording's folder (its mav0/imu0/data.csv) or that CSV file itself.
// file gets the CSV file's path; false with a message naming it if it cannot be read or parsed.
bool read_imu_samples(const std::string& path, std::vector<ImuSample>& out, std::string& file,
                      std::string& error);

// Draws allan.png's bytes into png; false with the reason in why. The host's program draws with
// gnuplot (firmware/evaluation's allan_plot.hpp); the board's has none.
using AllanPlotter = bool (*)(const ImuNoiseAnalysis& a, std::string& png, std::string& why);

// imu.yaml's text: the figures (upper bounds where not resolved) and the measured update_rate,
// with comments saying which are bounds. parse_imu_yaml reads it back.
std::string imu_noise_yaml(const ImuNoiseAnalysis& a);

// imu.yaml, allan.csv and, with a plotter, allan.png into dir, written whole or not at all. A plot
// that cannot be drawn leaves the others to be written, with the reason in plot_note.
bool write_imu_noise(const std::string& dir, const ImuNoiseAnalysis& a, AllanPlotter plotter,
                     std::string& plot_note, std::string& error);

}  // namespace mirrorcal::calibration
