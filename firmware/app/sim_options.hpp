// Options of the host's simulation commands (sim, montecarlo): the rendered frames of the
// simulated runs (--frames and its settings).
#pragma once

#include "cli.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/hal/blink_code.hpp"

namespace mirrorcal::app {

using evaluation::FrameMode;

// --frames, --format grey|yuyv, --spot-noise PX, --pixel-sigma PX, --identical-leds, --room and
// --blink PERIOD of sim and montecarlo; an error for a format that is not one, a noise that is
// negative, a sigma that is not positive, a period that is not 2..hal::BlinkCode::kMaxPeriod
// frames, or any of them without --frames.
bool frame_mode_option(const Options& o, FrameMode& frames, std::string& error);
// Whether --blink's period holds a dark frame for each of the rig's markers and one with all lit.
bool blink_fits(const FrameMode& frames, int markers, std::string& error);

}  // namespace mirrorcal::app
