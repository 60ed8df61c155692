// Options of the host's simulation commands (sim, montecarlo): the rendered frames of the
// simulated runs (--frames and its settings).
#pragma once

#include "cli.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"

namespace mirrorcal::app {

using evaluation::FrameMode;

// --frames, --format grey|yuyv, --spot-noise PX and --pixel-sigma PX of sim and montecarlo; an
// error for a format that is not one, a noise that is negative or a sigma that is not positive, or
// any of them without --frames.
bool frame_mode_option(const Options& o, FrameMode& frames, std::string& error);

}  // namespace mirrorcal::app
