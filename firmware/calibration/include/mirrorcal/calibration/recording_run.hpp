// Calibrating a recording: the same loop (run_loop) as the simulation, on data read from files.
#pragma once

#include <functional>
#include <string>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::calibration {

// The filter's configuration a recording describes (imu.yaml, camchain.yaml, mirrorcal.yaml).
CalibrationConfig recording_config(const io::Recording& r);

// The data of a recording as the loop consumes it.
LoopData recording_loop_data(const io::Recording& r);

// Runs the filter of M markers and NK intrinsics (0: stage 1; 5: intrinsics too; 4: intrinsics,
// skew held at camchain.yaml's; 8: fu fv cu cv and the lens's coefficients, skew held:
// estimate_distortion) on a recording from its priors. False, with a message, if the priors do not
// fit this build (e.g. another number of markers). With from, the camera pose and markers start
// from that earlier calibration (start_from). passes: as run_loop's (estimate_noise).
template <int M, int NK, int NI = 0>
bool calibrate_recording(const io::Recording& r, CalibrationRun<M, NK, NI>& run, std::string& error,
                         const std::function<void(double)>& progress = {},
                         const io::CalibrationStart* from = nullptr, Passes passes = {});

#define MIRRORCAL_CALIBRATE_RECORDING(M, NK, NI)                                        \
  bool calibrate_recording<M, NK, NI>(const io::Recording&, CalibrationRun<M, NK, NI>&, \
                                      std::string&, const std::function<void(double)>&, \
                                      const io::CalibrationStart*, Passes)
#define MIRRORCAL_EXTERN_CALIBRATE_RECORDING_(M, NK, NI) \
  extern template MIRRORCAL_CALIBRATE_RECORDING(M, NK, NI);
MIRRORCAL_FOR_EACH_FILTER(MIRRORCAL_EXTERN_CALIBRATE_RECORDING_)
#undef MIRRORCAL_EXTERN_CALIBRATE_RECORDING_

}  // namespace mirrorcal::calibration
