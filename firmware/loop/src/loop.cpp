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

template class CalibrationLoop<double, 3, 0>;
template class CalibrationLoop<double, 3, 4>;  // stage 2 holding skew
template class CalibrationLoop<double, 3, 5>;
template class CalibrationLoop<double, 3, 8>;  // stage 2 with the lens

}  // namespace mirrorcal::firmware
