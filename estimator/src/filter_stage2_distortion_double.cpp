// One of the filter configurations the product uses, compiled once here and nowhere else (see
// the extern template declarations in calibration_filter.hpp). Each configuration has a unit of
// its own so that the heavy Eigen instantiations build in parallel.
#include "mirrorcal/estimator/calibration_filter.hpp"

namespace mirrorcal {
template class CalibrationFilter<double, 3, 8>;  // stage 2 with the lens's coefficients, skew held
}  // namespace mirrorcal
