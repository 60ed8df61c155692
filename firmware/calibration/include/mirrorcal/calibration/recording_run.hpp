// Calibrating a recording: the same loop (run_loop) as the simulation, on data read from files.
#pragma once

#include <functional>
#include <string>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/sim_host/recording.hpp"

namespace mirrorcal::calibration {

// The filter's configuration a recording describes (imu.yaml, camchain.yaml, mirrorcal.yaml).
CalibrationConfig recording_config(const sim::Recording& r);

// The data of a recording as the loop consumes it.
LoopData recording_loop_data(const sim::Recording& r);

// Runs the NK filter (0: stage 1; 5: intrinsics too; 4: intrinsics, skew held at camchain.yaml's;
// 8: fu fv cu cv and the lens's coefficients, skew held: estimate_distortion)
// on a recording from its priors. False, with a message, if the priors do not fit this build (e.g.
// another number of markers).
// With from, the camera pose and markers start from that earlier calibration (start_from).
template <int NK>
bool calibrate_recording(const sim::Recording& r, CalibrationRun<NK>& run, std::string& error,
                         const std::function<void(double)>& progress = {},
                         const sim::CalibrationStart* from = nullptr);

extern template bool calibrate_recording<0>(const sim::Recording&, CalibrationRun<0>&, std::string&,
                                            const std::function<void(double)>&,
                                            const sim::CalibrationStart*);
extern template bool calibrate_recording<4>(const sim::Recording&, CalibrationRun<4>&, std::string&,
                                            const std::function<void(double)>&,
                                            const sim::CalibrationStart*);
extern template bool calibrate_recording<5>(const sim::Recording&, CalibrationRun<5>&, std::string&,
                                            const std::function<void(double)>&,
                                            const sim::CalibrationStart*);
extern template bool calibrate_recording<8>(const sim::Recording&, CalibrationRun<8>&, std::string&,
                                            const std::function<void(double)>&,
                                            const sim::CalibrationStart*);

}  // namespace mirrorcal::calibration
