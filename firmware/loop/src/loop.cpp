#include "mirrorcal/loop/loop_impl.hpp"

namespace mirrorcal::loop {

ImuSample interpolate(const ImuSample& a, const ImuSample& b, std::int64_t t_ns) {
  if (b.t_ns == a.t_ns) return b;
  const double f = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  ImuSample s;
  s.t_ns = t_ns;
  s.gyro = a.gyro + f * (b.gyro - a.gyro);
  s.accel = a.accel + f * (b.accel - a.accel);
  return s;
}

// For every filter the product uses (marker_counts.hpp).
#define MIRRORCAL_LOOP_(M, NK, NI) template class CalibrationLoop<double, M, NK, NI>;
MIRRORCAL_FOR_EACH_FILTER(MIRRORCAL_LOOP_)
#undef MIRRORCAL_LOOP_

}  // namespace mirrorcal::loop
