// Property tests of the SE(2) pose type on seeded random poses.

#include <gtest/gtest.h>

#include <numbers>
#include <random>

#include "lidar2d/core/se2.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

constexpr double kPi = std::numbers::pi;

class Se2Property : public ::testing::TestWithParam<int> {
 protected:
  SE2 randomPose() {
    return {pos_(rng_), pos_(rng_), ang_(rng_)};
  }
  Eigen::Vector3d randomTangent() { return {pos_(rng_), pos_(rng_), ang_(rng_) * 0.999}; }
  std::mt19937 rng_{static_cast<unsigned>(GetParam())};
  std::uniform_real_distribution<double> pos_{-10.0, 10.0};
  std::uniform_real_distribution<double> ang_{-kPi, kPi};
};

TEST(WrapAngle, MapsIntoHalfOpenInterval) {
  EXPECT_DOUBLE_EQ(wrapAngle(kPi), kPi);
  EXPECT_DOUBLE_EQ(wrapAngle(-kPi), kPi);
  EXPECT_NEAR(wrapAngle(3 * kPi), kPi, 1e-12);
  EXPECT_NEAR(wrapAngle(-3 * kPi + 0.1), -kPi + 0.1, 1e-12);
  EXPECT_NEAR(wrapAngle(2 * kPi + 0.5), 0.5, 1e-12);
  EXPECT_NEAR(wrapAngle(1e6), std::remainder(1e6, 2 * kPi), 1e-9);
  EXPECT_TRUE(std::isnan(wrapAngle(std::nan(""))));
  EXPECT_NEAR(angleDiff(kPi - 0.1, -kPi + 0.1), -0.2, 1e-12);
}

TEST_P(Se2Property, InverseComposesToIdentity) {
  for (int i = 0; i < 100; ++i) {
    const SE2 T = randomPose();
    EXPECT_TRUE(test::IsNearPose(SE2(), T * T.inverse(), 1e-12, 1e-10));
    EXPECT_TRUE(test::IsNearPose(SE2(), T.inverse() * T, 1e-12, 1e-10));
  }
}

TEST_P(Se2Property, CompositionIsAssociativeAndMatchesMatrices) {
  for (int i = 0; i < 100; ++i) {
    const SE2 a = randomPose(), b = randomPose(), c = randomPose();
    EXPECT_TRUE(test::IsNearPose((a * b) * c, a * (b * c), 1e-10, 1e-9));
    const Eigen::Matrix3d m = a.matrix() * b.matrix();
    const SE2 ab = a * b;
    EXPECT_TRUE(ab.matrix().isApprox(m, 1e-12));
    const Eigen::Vector2d p(pos_(rng_), pos_(rng_));
    EXPECT_TRUE(((a * b) * p).isApprox(a * (b * p), 1e-12));
    EXPECT_TRUE((a.inverse() * (a * p)).isApprox(p, 1e-10));
  }
}

TEST_P(Se2Property, ExpLogRoundTrip) {
  for (int i = 0; i < 100; ++i) {
    const SE2 T = randomPose();
    EXPECT_TRUE(test::IsNearPose(T, SE2::exp(T.log()), 1e-10, 1e-10));
    const Eigen::Vector3d xi = randomTangent();
    EXPECT_TRUE(SE2::exp(xi).log().isApprox(xi, 1e-9));
    // Tiny angles use the Taylor branch.
    const Eigen::Vector3d small(xi.x(), xi.y(), 1e-9);
    EXPECT_TRUE(SE2::exp(small).log().isApprox(small, 1e-9));
  }
}

TEST_P(Se2Property, ExpIsConstantTwistIntegration) {
  // exp integrates a constant body twist: compare with many small Euler steps.
  const Eigen::Vector3d xi = randomTangent();
  SE2 T;
  const int n = 20000;
  for (int k = 0; k < n; ++k) T = T * SE2(xi.x() / n, xi.y() / n, xi.z() / n);
  EXPECT_TRUE(test::IsNearPose(SE2::exp(xi), T, 1e-3, 1e-6));
}

TEST_P(Se2Property, AdjointMovesTangentAcrossFrames) {
  for (int i = 0; i < 100; ++i) {
    const SE2 T = randomPose();
    const Eigen::Vector3d xi = randomTangent() * 0.3;
    EXPECT_TRUE(test::IsNearPose(T * SE2::exp(xi) * T.inverse(), SE2::exp(T.adjoint() * xi), 1e-9, 1e-9));
  }
}

Eigen::Vector3d paramsDiff(const SE2& a, const SE2& b) {
  return {a.x() - b.x(), a.y() - b.y(), angleDiff(a.theta(), b.theta())};
}

TEST_P(Se2Property, AnalyticJacobiansMatchNumeric) {
  const double h = 1e-6;
  for (int i = 0; i < 50; ++i) {
    const SE2 a = randomPose(), b = randomPose();
    const Eigen::Vector2d p(pos_(rng_), pos_(rng_));
    const Eigen::Vector3d xi = randomTangent();
    Eigen::Matrix<double, 2, 3> jp;
    Eigen::Matrix3d jl, jr, ji, je;
    for (int k = 0; k < 3; ++k) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      d[k] = h;
      const SE2 ap = SE2::fromVector(a.vector() + d), am = SE2::fromVector(a.vector() - d);
      const SE2 bp = SE2::fromVector(b.vector() + d), bm = SE2::fromVector(b.vector() - d);
      jp.col(k) = (ap * p - am * p) / (2 * h);
      jl.col(k) = paramsDiff(ap * b, am * b) / (2 * h);
      jr.col(k) = paramsDiff(a * bp, a * bm) / (2 * h);
      ji.col(k) = paramsDiff(ap.inverse(), am.inverse()) / (2 * h);
      je.col(k) = paramsDiff(SE2::exp(xi + d), SE2::exp(xi - d)) / (2 * h);
    }
    EXPECT_TRUE(a.pointJacobian(p).isApprox(jp, 1e-6)) << a.pointJacobian(p) << "\nvs\n" << jp;
    EXPECT_TRUE(a.composeJacobianLeft(b).isApprox(jl, 1e-6));
    EXPECT_TRUE(a.composeJacobianRight().isApprox(jr, 1e-6));
    EXPECT_TRUE(a.inverseJacobian().isApprox(ji, 1e-6));
    EXPECT_TRUE(SE2::expJacobian(xi).isApprox(je, 1e-6)) << SE2::expJacobian(xi) << "\nvs\n" << je;
    const Eigen::Vector3d small(xi.x(), xi.y(), 1e-5);
    Eigen::Matrix3d js;
    for (int k = 0; k < 3; ++k) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      d[k] = 1e-7;
      js.col(k) = paramsDiff(SE2::exp(small + d), SE2::exp(small - d)) / 2e-7;
    }
    EXPECT_TRUE(SE2::expJacobian(small).isApprox(js, 1e-5));
  }
}

TEST(Se2, InterpolateTakesShorterArc) {
  const SE2 a(0, 0, kPi - 0.1), b(2, 4, -kPi + 0.1);
  const SE2 m = interpolate(a, b, 0.5);
  EXPECT_TRUE(test::IsNearPose(SE2(1, 2, kPi), m, 1e-12, 1e-9));
}

INSTANTIATE_TEST_SUITE_P(Seeds, Se2Property, ::testing::Values(1, 2, 3));

}  // namespace
}  // namespace lidar2d
