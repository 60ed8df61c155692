// The models under the filter: SO(3) maps, the mirror image (paper eq. 11), the pinhole
// projection, the error-state manifold of MirrorState and the IMU integration.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "mirrorcal/estimator/mirror_model.hpp"
#include "mirrorcal/estimator/so3.hpp"
#include "test_support.hpp"

namespace mirrorcal {
namespace {

using test::kDeg;
using test::kPi;

Eigen::Vector3d random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector3d v(n(rng), n(rng), n(rng));
  return v.normalized();
}

Eigen::Quaterniond random_rotation(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> a(0.0, kPi);
  return test::rotvec(a(rng) * random_unit(rng));
}

// Angle between two rotations, independent of so3::log.
double angle_between(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return Eigen::AngleAxisd(a.conjugate() * b).angle();
}

// ---------------------------------------------------------------------------------------------
// so3

TEST(So3, ExpMatchesAngleAxis) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> a(0.0, kPi);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector3d phi = a(rng) * random_unit(rng);
    const Eigen::Quaterniond q = so3::exp<double>(phi);
    EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    EXPECT_LT(angle_between(q, test::rotvec(phi)), 1e-14);
  }
  // Tiny angles, below and above the series threshold: the quaternion is (1 - a^2/8, phi/2 ...).
  for (double angle : {1e-14, 1e-10, 1e-6, 0.99e-4, 1.01e-4, 1e-3}) {
    const Eigen::Vector3d phi = angle * Eigen::Vector3d(1, -2, 2) / 3.0;
    const Eigen::Quaterniond q = so3::exp<double>(phi);
    EXPECT_NEAR(q.w(), std::cos(0.5 * angle), 1e-16);
    EXPECT_LT((q.vec() - std::sin(0.5 * angle) * phi / angle).norm(), 1e-16 * angle + 1e-300);
  }
}

TEST(So3, LogInvertsExpRandomAndTinyAndNearPi) {
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> a(0.0, kPi);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector3d phi = a(rng) * random_unit(rng);
    const Eigen::Vector3d back = so3::log<double>(so3::exp<double>(phi));
    EXPECT_LT((back - phi).norm(), 1e-13) << phi.transpose();
    // q and -q are the same rotation.
    Eigen::Quaterniond neg = so3::exp<double>(phi);
    neg.coeffs() = -neg.coeffs();
    EXPECT_LT((so3::log<double>(neg) - phi).norm(), 1e-13);
  }
  for (double angle : {0.0, 1e-15, 1e-12, 1e-8, 1e-5, 0.99e-4, 1.01e-4, 1e-2, 1.0, kPi - 1e-3,
                       kPi - 1e-6, kPi - 1e-9}) {
    const Eigen::Vector3d dir = Eigen::Vector3d(0.3, -0.5, 0.8).normalized();
    const Eigen::Vector3d phi = angle * dir;
    const Eigen::Vector3d back = so3::log<double>(so3::exp<double>(phi));
    // A few ulps relative at every angle: the series keep tiny angles exact, atan2 keeps the
    // near-half-turns well conditioned.
    EXPECT_LE((back - phi).norm(), 1.5e-15 * angle) << "angle " << angle;
    // And the angle from log is the one Eigen finds.
    EXPECT_NEAR(back.norm(), Eigen::AngleAxisd(test::rotvec(phi)).angle(), 1e-15 + 1e-15 * angle);
  }
}

TEST(So3, BoxplusBoxminusRoundTrip) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> a(0.0, kPi - 1e-6);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Quaterniond q = random_rotation(rng);
    const Eigen::Vector3d d = a(rng) * random_unit(rng);
    const Eigen::Quaterniond p = so3::boxplus<double>(q, d);
    EXPECT_LT((so3::boxminus<double>(p, q) - d).norm(), 1e-14);
    // Right perturbation: p = q Exp(d), so R_p = R_q R(d).
    EXPECT_LT(
        (p.toRotationMatrix() - q.toRotationMatrix() * test::rotvec(d).toRotationMatrix()).norm(),
        1e-14);
    // boxplus(q, boxminus(p, q)) = p.
    EXPECT_LT(angle_between(so3::boxplus<double>(q, so3::boxminus<double>(p, q)), p), 1e-14);
  }
  const Eigen::Quaterniond q = random_rotation(rng);
  for (double angle : {1e-15, 1e-9, 1e-5, 1e-4, 1e-3, kPi - 1e-4, kPi - 1e-7}) {
    const Eigen::Vector3d d = angle * Eigen::Vector3d(-0.2, 0.9, 0.4).normalized();
    const Eigen::Vector3d back = so3::boxminus<double>(so3::boxplus<double>(q, d), q);
    // The quaternion product rounds at ~1e-16 absolute whatever the angle (measured: <= 2.3e-16
    // from 1e-15 rad to pi - 1e-7), so the round trip is absolute-accurate to a few ulps.
    EXPECT_LT((back - d).norm(), 1e-15) << "angle " << angle;
  }
}

TEST(So3, FloatRoundTrip) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<float> a(0.0f, 3.0f);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Quaternionf q = random_rotation(rng).cast<float>();
    const Eigen::Vector3f d = a(rng) * random_unit(rng).cast<float>();
    const Eigen::Vector3f back = so3::boxminus<float>(so3::boxplus<float>(q, d), q);
    EXPECT_LT((back - d).norm(), 2e-6f);
  }
  for (float angle : {1e-9f, 1e-6f, 0.99e-2f, 1.01e-2f, 0.1f}) {
    const Eigen::Vector3f d = angle * Eigen::Vector3f(0.6f, 0.0f, -0.8f);
    const Eigen::Vector3f back = so3::log<float>(so3::exp<float>(d));
    EXPECT_LT((back - d).norm(), 4e-7f * angle) << "angle " << angle;
  }
}

// ---------------------------------------------------------------------------------------------
// Mirror image and projection

// A random camera on the reflective side of the mirror (z > 0 in n) looking at it: its optical
// axis within ~40 deg of -z_n, any roll about the axis.
void random_camera(std::mt19937_64& rng, Eigen::Matrix3d& r_n_c, Eigen::Vector3d& p_n_c) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_real_distribution<double> height(0.2, 2.0);
  p_n_c = Eigen::Vector3d(0.5 * u(rng), 0.5 * u(rng), height(rng));
  Eigen::Matrix3d base;  // optical axis (z_c) along -z_n
  base << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  const Eigen::Vector3d tilt = 40.0 * kDeg * std::abs(u(rng)) * random_unit(rng);
  const double roll = kPi * u(rng);
  r_n_c = test::rotvec(tilt).toRotationMatrix() * base *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

TEST(MirrorImage, MatchesReflectionInMirrorFrame) {
  std::mt19937_64 rng(10);
  std::uniform_real_distribution<double> u(-0.15, 0.15);
  for (int i = 0; i < 2000; ++i) {
    Eigen::Matrix3d r_n_c;
    Eigen::Vector3d p_n_c;
    random_camera(rng, r_n_c, p_n_c);
    const Eigen::Vector3d pi(u(rng), u(rng), u(rng));
    const Eigen::Vector3d expected = test::reflect_in_n(r_n_c, p_n_c, pi);
    const Eigen::Vector3d got = mirror_image<double>(r_n_c, p_n_c, pi);
    EXPECT_LT((got - expected).norm(), 1e-14);
    // Float agrees to its own precision (relative to the ~metre scale of the scene).
    const Eigen::Vector3f got_f =
        mirror_image<float>(r_n_c.cast<float>(), p_n_c.cast<float>(), pi.cast<float>());
    EXPECT_LT((got_f.cast<double>() - expected).norm(), 2e-6);
  }
}

// Ray trace: back-project the pixel of the predicted image into a ray from the camera centre,
// intersect it with the mirror, reflect it, and check it hits the marker; the unfolded length of
// the path is the distance to the virtual point.
TEST(MirrorImage, RayTraceThroughPixelHitsMarker) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-0.15, 0.15);
  const test::Rig rig;
  const Pinhole<double> k{rig.fu, rig.fv, rig.cu, rig.cv, rig.skew};
  const Eigen::Matrix3d k_inv = rig.k_matrix().inverse();
  int traced = 0, behind_centre = 0;
  for (int i = 0; i < 5000; ++i) {
    Eigen::Matrix3d r_n_c;
    Eigen::Vector3d p_n_c;
    random_camera(rng, r_n_c, p_n_c);
    const Eigen::Vector3d pi_c(u(rng), u(rng), u(rng));
    const Eigen::Vector3d pi_n = r_n_c * pi_c + p_n_c;
    if (pi_n.z() <= 0.0) continue;  // marker behind the mirror: no reflection
    const Eigen::Vector3d img = mirror_image<double>(r_n_c, p_n_c, pi_c);
    Eigen::Vector2d uv;
    if (!project<double>(k, img, uv)) continue;
    ++traced;
    if (pi_c.z() < 0.0) ++behind_centre;

    const Eigen::Vector3d d_c = k_inv * Eigen::Vector3d(uv.x(), uv.y(), 1.0);
    const Eigen::Vector3d d = (r_n_c * d_c).normalized();
    ASSERT_LT(d.z(), 0.0) << "a visible reflection must come from a ray towards the mirror";
    const double t_hit = -p_n_c.z() / d.z();
    const Eigen::Vector3d hit = p_n_c + t_hit * d;
    EXPECT_NEAR(hit.z(), 0.0, 1e-12);
    const Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d r = d - 2.0 * d.dot(n) * n;
    const Eigen::Vector3d to_marker = pi_n - hit;
    const double s = to_marker.dot(r);
    EXPECT_GT(s, 0.0);
    EXPECT_LT((to_marker - s * r).norm(), 1e-9) << "reflected ray misses the marker";
    EXPECT_NEAR(t_hit + s, img.norm(), 1e-9) << "unfolded path length";
  }
  EXPECT_GT(traced, 2000);
  EXPECT_GT(behind_centre, 500) << "markers behind the optical centre must be covered";
}

TEST(MirrorImage, PaperRigMarkersBehindCameraAreVisible) {
  // The paper's markers 1 and 2 are 3 cm behind the optical centre; their reflections lie about
  // twice the camera-mirror distance in front.
  const test::Rig rig;
  Eigen::Matrix3d r_n_c;
  r_n_c << 1, 0, 0, 0, -1, 0, 0, 0, -1;  // looking straight at the mirror
  const Eigen::Vector3d p_n_c(0.1, 0.2, 0.7);
  for (const auto& pi : rig.markers) {
    const Eigen::Vector3d img = mirror_image<double>(r_n_c, p_n_c, pi);
    // Depth 2h - z (h the camera's height): a marker behind the camera is reflected deeper.
    EXPECT_NEAR(img.z(), 2.0 * 0.7 - pi.z(), 1e-15);
    EXPECT_NEAR(img.x(), pi.x(), 1e-15);
    EXPECT_NEAR(img.y(), pi.y(), 1e-15);
  }
}

TEST(Projection, MatchesKMatrix) {
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_real_distribution<double> depth(0.002, 5.0);
  const test::Rig rig;
  const Pinhole<double> k{rig.fu, rig.fv, rig.cu, rig.cv, rig.skew};
  const Eigen::Matrix3d km = rig.k_matrix();
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector3d p(u(rng), u(rng), depth(rng));
    Eigen::Vector2d uv;
    ASSERT_TRUE(project<double>(k, p, uv));
    const Eigen::Vector3d h = km * p;
    const Eigen::Vector2d expected = h.head<2>() / h.z();
    EXPECT_LT((uv - expected).norm(), 1e-12 * std::max(1.0, expected.norm()));
    Eigen::Vector2f uv_f;
    ASSERT_TRUE(project<float>(
        Pinhole<float>{float(rig.fu), float(rig.fv), float(rig.cu), float(rig.cv), float(rig.skew)},
        p.cast<float>(), uv_f));
    EXPECT_LT((uv_f.cast<double>() - expected).norm(), 1e-6 * std::max(1.0, expected.norm()));
  }
  // The principal point is the image of the optical axis; skew shears u by y/z.
  Eigen::Vector2d uv;
  ASSERT_TRUE(project<double>(k, Eigen::Vector3d(0, 0, 2), uv));
  EXPECT_NEAR(uv.x(), rig.cu, 1e-12);
  EXPECT_NEAR(uv.y(), rig.cv, 1e-12);
  ASSERT_TRUE(project<double>(k, Eigen::Vector3d(0, 1, 1), uv));
  EXPECT_NEAR(uv.x(), rig.cu + rig.skew, 1e-12);
  EXPECT_NEAR(uv.y(), rig.cv + rig.fv, 1e-12);
}

TEST(Projection, RejectsPointsNotInFront) {
  const Pinhole<double> k{833.33, 833.33, 2.0, 8.0, 3.0};
  Eigen::Vector2d uv(123.0, 456.0);
  for (double z : {0.0, -0.0, -1e-9, -0.5, -10.0}) {
    EXPECT_FALSE(project<double>(k, Eigen::Vector3d(0.1, -0.2, z), uv)) << z;
  }
  EXPECT_FALSE(project<double>(k, Eigen::Vector3d(0.1, 0.2, std::nan("")), uv));
  EXPECT_EQ(uv, Eigen::Vector2d(123.0, 456.0)) << "output untouched on rejection";
  Eigen::Vector2f uv_f;
  EXPECT_FALSE(project<float>(Pinhole<float>{833.33f, 833.33f, 2.0f, 8.0f, 3.0f},
                              Eigen::Vector3f(0.0f, 0.0f, -1.0f), uv_f));
}

// Closed forms of the lenses (OpenCV's own projections are compared in lens_vs_opencv.py).
TEST(Lens, EquidistantWithoutCoefficientsMapsTheRayAngleToTheRadius) {
  Pinhole<double> k{800.0, 800.0, 320.0, 240.0, 0.0, Distortion::kEquidistant, {0, 0, 0, 0}};
  for (const double angle : {0.0, 1e-12, 0.1, 0.5, 1.0, 1.4}) {  // from the optical axis (rad)
    const double azimuth = 0.7;
    const Eigen::Vector3d p(std::sin(angle) * std::cos(azimuth),
                            std::sin(angle) * std::sin(azimuth), std::cos(angle));
    Eigen::Vector2d uv;
    ASSERT_TRUE(project<double>(k, p, uv));
    const Eigen::Vector2d d = (uv - Eigen::Vector2d(320.0, 240.0)) / 800.0;
    EXPECT_NEAR(d.norm(), angle, 1e-12) << angle;  // r_d = theta
    if (angle > 1e-6) {  // nearer the axis the pixel's rounding hides the direction
      EXPECT_NEAR(std::atan2(d.y(), d.x()), azimuth, 1e-9) << angle;
    }
  }
}

TEST(Lens, RadtanOnTheAxesIsTheOddPolynomialPlusTheTangentialTerms) {
  const double k1 = -0.28, k2 = 0.07, p1 = 0.002, p2 = -0.001;
  Pinhole<double> k{1.0, 1.0, 0.0, 0.0, 0.0, Distortion::kRadtan, {k1, k2, p1, p2}};
  for (const double x : {-0.6, -0.1, 0.0, 0.3, 0.8}) {
    Eigen::Vector2d uv;
    ASSERT_TRUE(project<double>(k, Eigen::Vector3d(x, 0.0, 1.0), uv));
    // y = 0: x_d = x (1 + k1 x^2 + k2 x^4) + 3 p2 x^2, y_d = p1 x^2.
    EXPECT_NEAR(uv.x(), x * (1 + k1 * x * x + k2 * x * x * x * x) + 3 * p2 * x * x, 1e-15);
    EXPECT_NEAR(uv.y(), p1 * x * x, 1e-15);
  }
  // Without a lens the model is the pinhole's.
  const Pinhole<double> plain{800.0, 790.0, 320.0, 240.0, 2.0};
  Eigen::Vector2d uv;
  ASSERT_TRUE(project<double>(plain, Eigen::Vector3d(0.2, -0.1, 2.0), uv));
  EXPECT_NEAR(uv.x(), 800.0 * 0.1 + 2.0 * -0.05 + 320.0, 1e-12);
  EXPECT_NEAR(uv.y(), 790.0 * -0.05 + 240.0, 1e-12);
}

// Beyond about 60 deg off the axis (r^2 = 3) the radtan polynomial describes no lens: the model
// holds its radial factor there, so that a point far outside the field projects along its ray
// scaled by the factor at the field's edge (EuRoC's lens: r = 3 at 3 * 0.82, not at 13.6), and
// the projection stays continuous across the edge.
TEST(Lens, RadtanHoldsItsRadialFactorBeyondSixtyDegrees) {
  const double k1 = -0.28340811, k2 = 0.07395907;
  const Pinhole<double> k{1.0, 1.0, 0.0, 0.0, 0.0, Distortion::kRadtan, {k1, k2, 0.0, 0.0}};
  const double edge = std::sqrt(3.0), factor = 1.0 + 3.0 * (k1 + 3.0 * k2);
  for (const double r : {edge * 1.000001, 2.0, 3.0, 10.0}) {
    Eigen::Vector2d uv;
    ASSERT_TRUE(project<double>(k, Eigen::Vector3d(0.6 * r, 0.8 * r, 1.0), uv));
    EXPECT_NEAR(uv.norm(), r * factor, 1e-12 * r) << r;
    EXPECT_NEAR(std::atan2(uv.y(), uv.x()), std::atan2(0.8, 0.6), 1e-12) << r;
  }
  // Continuous at the edge: just inside, the polynomial itself.
  const double r = edge * 0.999999, r2 = r * r;
  Eigen::Vector2d uv;
  ASSERT_TRUE(project<double>(k, Eigen::Vector3d(r, 0.0, 1.0), uv));
  EXPECT_NEAR(uv.x(), r * (1.0 + r2 * (k1 + r2 * k2)), 1e-15);
  EXPECT_NEAR(uv.x(), edge * factor, 1e-5);
}

// ---------------------------------------------------------------------------------------------
// MirrorState manifold

template <typename S, int M, int NK>
MirrorState<S, M, NK> random_state(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  MirrorState<S, M, NK> x;
  auto vec = [&](auto& v) {
    for (int i = 0; i < v.size(); ++i) v(i) = S(n(rng));
  };
  vec(x.v);
  vec(x.b_a);
  vec(x.b_g);
  vec(x.p);
  vec(x.p_b_c);
  vec(x.markers);
  vec(x.intrinsics);
  x.q_n_b = random_rotation(rng).cast<S>();
  x.q_b_c = random_rotation(rng).cast<S>();
  return x;
}

template <typename S, int L>
Eigen::Matrix<S, L, 1> random_tangent(std::mt19937_64& rng, double scale) {
  std::normal_distribution<double> n(0.0, scale);
  Eigen::Matrix<S, L, 1> d;
  for (int i = 0; i < L; ++i) d(i) = S(n(rng));
  return d;
}

template <typename S, int M, int NK>
void check_state_round_trip(double tol) {
  using State = MirrorState<S, M, NK>;
  std::mt19937_64 rng(20 + NK);
  for (int i = 0; i < 200; ++i) {
    const State x = random_state<S, M, NK>(rng);
    const double scale = i < 100 ? 0.5 : 1e-6;  // rotations well below pi, and tiny steps
    {
      const auto d = random_tangent<S, State::kDim>(rng, scale);
      State y = x;
      y.template boxplus_block<0, State::kDim>(d);
      const auto back = y.template boxminus_block<0, State::kDim>(x);
      EXPECT_LT((back - d).norm(), tol * (1.0 + d.norm()));
      // Each component moved by its own slot of d only.
      EXPECT_LT(double((y.p - x.p - d.template segment<3>(State::kP)).norm()), tol);
      EXPECT_LT(double((y.markers - x.markers - d.template segment<3 * M>(State::kPi)).norm()),
                tol);
    }
    {  // The dynamic block leaves the calibration alone, and vice versa.
      const auto d = random_tangent<S, State::kDynamicDim>(rng, scale);
      State y = x;
      y.template boxplus_block<State::kDynamicBegin, State::kDynamicDim>(d);
      EXPECT_EQ(y.p_b_c, x.p_b_c);
      EXPECT_EQ(y.q_b_c.coeffs(), x.q_b_c.coeffs());
      EXPECT_EQ(y.markers, x.markers);
      const auto back = y.template boxminus_block<State::kDynamicBegin, State::kDynamicDim>(x);
      EXPECT_LT((back - d).norm(), tol * (1.0 + d.norm()));
    }
    {
      const auto d = random_tangent<S, State::kMeasuredDim>(rng, scale);
      State y = x;
      y.template boxplus_block<State::kMeasuredBegin, State::kMeasuredDim>(d);
      EXPECT_EQ(y.v, x.v);
      EXPECT_EQ(y.b_a, x.b_a);
      EXPECT_EQ(y.b_g, x.b_g);
      const auto back = y.template boxminus_block<State::kMeasuredBegin, State::kMeasuredDim>(x);
      EXPECT_LT((back - d).norm(), tol * (1.0 + d.norm()));
      // The attitude slot is a right perturbation of R_n_b.
      const Eigen::Quaterniond expected =
          x.q_n_b.template cast<double>() *
          test::rotvec(
              d.template segment<3>(State::kTheta - State::kMeasuredBegin).template cast<double>());
      EXPECT_LT(angle_between(y.q_n_b.template cast<double>(), expected), 10 * tol);
    }
  }
}

// The calibration layout of MirrorState<M, NK> against the one calibration_layout gives from the
// counts, and against the state itself: moving one group's values moves exactly that group's
// indices of the calibration block's error vector.
template <int M, int NK>
void check_calibration_layout() {
  using State = MirrorState<double, M, NK>;
  constexpr CalibrationLayout layout = State::kCalibration;
  const CalibrationLayout counted = calibration_layout(M, NK);
  for (int g = 0; g < kCalibrationGroups; ++g) {
    const auto group = static_cast<CalibrationGroup>(g);
    EXPECT_EQ(layout[group].begin, counted[group].begin) << "M " << M << " NK " << NK << " g " << g;
    EXPECT_EQ(layout[group].size, counted[group].size) << "M " << M << " NK " << NK << " g " << g;
  }
  EXPECT_EQ(layout.size(), State::kCalibrationDim);
  EXPECT_EQ(State::kCalibrationBegin + State::kCalibrationDim, State::kDim);

  constexpr int B = State::kCalibrationBegin, L = State::kCalibrationDim;
  std::mt19937_64 rng(40 + 10 * M + NK);
  const State x = random_state<double, M, NK>(rng);
  const auto moved_indices = [&](CalibrationGroup group, const State& y) {
    const Eigen::Matrix<double, L, 1> d = y.template boxminus_block<B, L>(x);
    // Moved: by far more than rounding (a rotation unmoved comes back as 1e-17 where the
    // arithmetic contracts to fused multiply-adds, as on aarch64).
    for (int j = 0; j < L; ++j) {
      const bool moved = std::abs(d(j)) > 1e-9;
      EXPECT_EQ(moved, layout[group].contains(j))
          << "M " << M << " NK " << NK << " group " << int(group) << " index " << j;
      if (moved) {
        EXPECT_EQ(layout.group_of(j), group);
      }
    }
  };
  State y = x;
  y.p_b_c += Eigen::Vector3d(0.1, 0.2, 0.3);
  moved_indices(CalibrationGroup::kCameraPosition, y);
  y = x;
  y.q_b_c = x.q_b_c * test::rotvec(Eigen::Vector3d(0.1, 0.2, 0.3));
  moved_indices(CalibrationGroup::kCameraRotation, y);
  y = x;
  y.markers.array() += 0.1;
  moved_indices(CalibrationGroup::kMarkers, y);
  y = x;
  y.t_d += 0.01;
  moved_indices(CalibrationGroup::kTimeOffset, y);
  y = x;
  y.intrinsics.head(NK - State::kLensCoeffs).array() += 1.0;
  moved_indices(CalibrationGroup::kIntrinsics, y);
  y = x;
  y.intrinsics.tail(State::kLensCoeffs).array() += 0.01;
  moved_indices(CalibrationGroup::kLens, y);
}

TEST(MirrorState, CalibrationLayoutMatchesTheState) {
  check_calibration_layout<1, 0>();
  check_calibration_layout<1, 4>();
  check_calibration_layout<3, 0>();
  check_calibration_layout<3, 5>();
  check_calibration_layout<3, 8>();
  check_calibration_layout<5, 8>();
}

TEST(MirrorState, CalibrationLayoutWithoutTimeOffset) {
  // Results written before the time offset was estimated: the intrinsics follow the markers.
  for (const int markers : {1, 3, 4})
    for (const int intrinsics : {0, 4, 5, 8}) {
      const CalibrationLayout with = calibration_layout(markers, intrinsics);
      const CalibrationLayout without = calibration_layout(markers, intrinsics, false);
      EXPECT_EQ(without[CalibrationGroup::kTimeOffset].size, 0);
      EXPECT_EQ(without[CalibrationGroup::kIntrinsics].begin,
                without[CalibrationGroup::kMarkers].end());
      EXPECT_EQ(without.size() + 1, with.size());
      for (int j = 0; j < without.size(); ++j) {
        const int same = j < with[CalibrationGroup::kTimeOffset].begin ? j : j + 1;
        EXPECT_EQ(without.group_of(j), with.group_of(same));
      }
    }
}

// Stage 2 with the lens estimated (NK = 8: fu fv cu cv and the four coefficients, skew held)
// predicts exactly what the fixed-lens model predicts when its coefficients are the configured
// ones, and follows its own coefficients when they differ (they are not ignored).
void expect_lens_state_matches_fixed_lens(Distortion model, const std::array<double, 4>& coeffs) {
  const test::SineTrajectory traj = test::wall_mirror_trajectory();
  const test::Rig rig;
  Pinhole<double> fixed{833.33, 833.33, 322.0, 248.0, 3.0};
  fixed.distortion = model;
  fixed.coeffs = coeffs;
  int compared = 0;
  for (const double t : {0.0, 0.7, 1.9, 3.1}) {
    const MirrorState<double, 3, 0> x0 = test::truth_state<double, 3, 0>(traj, rig, t);
    MirrorState<double, 3, 8> x8;
    x8.v = x0.v;
    x8.p = x0.p;
    x8.q_n_b = x0.q_n_b;
    x8.p_b_c = x0.p_b_c;
    x8.q_b_c = x0.q_b_c;
    x8.markers = x0.markers;
    x8.intrinsics << fixed.fu, fixed.fv, fixed.cu, fixed.cv, coeffs[0], coeffs[1], coeffs[2],
        coeffs[3];
    // The state's camera parameters go where the fixed ones were: give the fixed camera others,
    // all but the skew, which NK = 8 holds.
    Pinhole<double> other = fixed;
    other.fu += 40.0;
    other.cv -= 7.0;
    other.coeffs = {0.1, -0.2, 0.01, -0.01};
    const Exposure<double> e;
    const std::array<double, 3> readout{};
    Eigen::Matrix<double, 6, 1> z0 = Eigen::Matrix<double, 6, 1>::Zero(), z8 = z0;
    std::array<bool, 3> ok0{true, true, true}, ok8 = ok0;
    predict_markers(x0, fixed, e, readout, z0, ok0);
    predict_markers(x8, other, e, readout, z8, ok8);
    for (int i = 0; i < 3; ++i) {
      ASSERT_EQ(ok0[i], ok8[i]) << i;
      if (!ok0[i]) continue;
      ++compared;
      EXPECT_EQ(z0(2 * i), z8(2 * i)) << "t " << t << " marker " << i;  // bit for bit
      EXPECT_EQ(z0(2 * i + 1), z8(2 * i + 1)) << "t " << t << " marker " << i;
    }
    // Each coefficient moves the prediction: the state's coefficients are the ones used.
    for (int j = 0; j < 4; ++j) {
      MirrorState<double, 3, 8> moved = x8;
      moved.intrinsics(4 + j) += 0.05;
      Eigen::Matrix<double, 6, 1> zm = z8;
      std::array<bool, 3> okm{true, true, true};
      predict_markers(moved, other, e, readout, zm, okm);
      Pinhole<double> shifted = fixed;
      shifted.coeffs[static_cast<std::size_t>(j)] += 0.05;
      Eigen::Matrix<double, 6, 1> zs = z0;
      std::array<bool, 3> oks{true, true, true};
      predict_markers(x0, shifted, e, readout, zs, oks);
      bool moved_any = false;
      for (int i = 0; i < 3; ++i) {
        if (!okm[i] || !oks[i]) continue;
        EXPECT_EQ(zm.segment<2>(2 * i), zs.segment<2>(2 * i)) << "coefficient " << j;
        moved_any = moved_any || (zm.segment<2>(2 * i) - z8.segment<2>(2 * i)).norm() > 1e-9;
      }
      EXPECT_TRUE(moved_any) << "coefficient " << j;
    }
  }
  EXPECT_GE(compared, 6);  // the markers were in view: the comparison was made
}

TEST(LensState, EstimatedRadtanCoefficientsPredictAsTheFixedLens) {
  expect_lens_state_matches_fixed_lens(Distortion::kRadtan,
                                       {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05});
}

TEST(LensState, EstimatedEquidistantCoefficientsPredictAsTheFixedLens) {
  expect_lens_state_matches_fixed_lens(Distortion::kEquidistant,
                                       {0.00348238, 0.000715034, -0.00205323, 0.000202936});
}

TEST(MirrorState, BoxplusBoxminusRoundTrip) {
  check_state_round_trip<double, 3, 0>(1e-13);
  check_state_round_trip<double, 3, 5>(1e-13);
  check_state_round_trip<double, 3, 8>(1e-13);
  check_state_round_trip<double, 1, 4>(1e-13);
  check_state_round_trip<float, 3, 0>(2e-6);
}

}  // namespace
}  // namespace mirrorcal
