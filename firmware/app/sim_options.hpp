// Options of the host's simulation commands (sim, montecarlo, record of the simulated rig): the
// scenario and its variations, and the rendered frames of the simulated runs (--frames and its
// settings).
#pragma once

#include "cli.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/hal/blink_code.hpp"
#include "mirrorcal/sim/scenario.hpp"

namespace mirrorcal::app {

using evaluation::FrameMode;

// The scenario named by --scenario (default "paper"); the random family's draw for seed, with
// --markers N markers (a built count; the paper's rig has three). With --duration S (s, within
// kMinSimulatedDurationS..kMaxSimulatedDurationS), S seconds of its motion instead of its minute
// (sim and record take it; a campaign's runs keep their minute). With
// --timeshift S (s, within +-kMaxSimulatedTimeshiftS), the true camera-IMU time offset is S; with
// --distortion MODEL, the camera has that lens (sim::set_lens); with --line-delay S, a rolling
// shutter reading each row S seconds after the one above (a whole frame within
// kMaxSimulatedReadoutS); with --outliers P, in the share P of frames (at most
// kMaxSimulatedMistakeShare; "0.02" or "2%") one marker's pixel is a random one, as a detector
// that took a room light for an LED gives it; with --label-swaps P, markers 0's and 1's labels
// are swapped in that share.
constexpr double kMinSimulatedDurationS = 1.0;
constexpr double kMaxSimulatedDurationS = 600.0;
constexpr double kMaxSimulatedTimeshiftS = 0.5;
constexpr double kMaxSimulatedReadoutS = 0.1;
constexpr double kMaxSimulatedMistakeShare = 0.5;
bool scenario_option(const Options& o, std::uint64_t seed, sim::Scenario& s, std::string& error);
// ", N markers" for a rig with other than the paper's three markers, "" for three: what the
// simulating commands add to their titles.
std::string markers_note(const sim::Scenario& s);

// The model of a simulated scenario's IMU, which sim, montecarlo and record use by default: the
// default model for a MEMS part (the mems family), the ideal IMU's for an ideal one (the paper's
// factory-calibrated ADIS16448, the random family).
ImuModel simulated_imu_model(const sim::Scenario& s);

// --frames, --format grey|yuyv, --spot-noise PX, --pixel-sigma PX, --identical-leds, --room and
// --blink PERIOD of sim and montecarlo; an error for a format that is not one, a noise that is
// negative, a sigma that is not positive, a period that is not 2..hal::BlinkCode::kMaxPeriod
// frames, or any of them without --frames.
bool frame_mode_option(const Options& o, FrameMode& frames, std::string& error);
// Whether --blink's period holds a dark frame for each of the rig's markers and one with all lit.
bool blink_fits(const FrameMode& frames, int markers, std::string& error);

}  // namespace mirrorcal::app
