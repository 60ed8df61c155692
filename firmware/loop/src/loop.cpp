#include "mirrorcal/firmware/loop_impl.hpp"

namespace mirrorcal::firmware {

ImuSample interpolate(const ImuSample& a, const ImuSample& b, std::int64_t t_ns) {
  if (b.t_ns == a.t_ns) return b;
  const double f = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  ImuSample s;
  s.t_ns = t_ns;
  s.gyro = a.gyro + f * (b.gyro - a.gyro);
  s.accel = a.accel + f * (b.accel - a.accel);
  return s;
}

// For every built M (marker_counts.hpp): stage 1, stage 2 holding skew, stage 2, with the lens.
#define MIRRORCAL_LOOPS_(M)                     \
  template class CalibrationLoop<double, M, 0>; \
  template class CalibrationLoop<double, M, 4>; \
  template class CalibrationLoop<double, M, 5>; \
  template class CalibrationLoop<double, M, 8>;
MIRRORCAL_FOR_EACH_MARKER_COUNT(MIRRORCAL_LOOPS_)
#undef MIRRORCAL_LOOPS_
// Stage 1 with the IMU's intrinsics, for every built IMU model (MIRRORCAL_IMU_MODELS).
#define MIRRORCAL_IMU_LOOP_(M, NI) template class CalibrationLoop<double, M, 0, NI>;
MIRRORCAL_FOR_EACH_IMU_FILTER(MIRRORCAL_IMU_LOOP_)
#undef MIRRORCAL_IMU_LOOP_

}  // namespace mirrorcal::firmware
