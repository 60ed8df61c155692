// What the tables a user reads are computed with: a rotation as three angles, and the chi-square
// quantiles the NEES and the normalised innovation squared are judged against.
#pragma once

#include <Eigen/Geometry>

namespace mirrorcal::calibration {

// A rotation R_b_c as the three angles (deg) the scenarios state it by: R = Rz(c) Ry(b) Rx(a),
// returned as (a, b, c).
Eigen::Vector3d display_angles(const Eigen::Quaterniond& q);

// Quantile of the chi-square distribution with k degrees of freedom at probability p
// (Wilson-Hilferty; accurate to <1 % for k > 10).
double chi2_quantile(double p, double k);

}  // namespace mirrorcal::calibration
