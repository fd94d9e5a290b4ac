// Likelihood-field matching: field interpolation and gradient, exact recovery on noise-free
// simulated scans (Gauss-Newton and Ceres), convergence basin, scan-to-map, degeneracy, bad input.

#include "lidar2d/registration/likelihood_field.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include "lidar2d/core/error.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d::registration {

void PrintTo(LfSolver s, std::ostream* os) { *os << (s == LfSolver::kCeres ? "Ceres" : "GaussNewton"); }

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

/// Noise-free 360-beam scans (laser at the robot's centre) of a built-in world.
class SimScans {
 public:
  explicit SimScans(const std::string& world) : scenario_(sim::builtinScenario(world)) {
    opts_ = sim::SimulatorOptions{}.noiseFree();
    opts_.laser.beams = 360;
    opts_.laser.fov_rad = 2.0 * std::numbers::pi;
    opts_.laser.range_max_m = 30.0;
    opts_.laser.T_robot_laser = SE2();
    route_ = sim::samplePath(scenario_.waypoints, sim::PathOptions{});
    sim_ = std::make_unique<sim::Simulator>(scenario_.world, std::vector<sim::TimedPose>{{0.0, SE2()}}, opts_);
  }
  /// Endpoints of a scan taken at T_world_robot, in the robot frame.
  Points2 scanAt(const SE2& T_world_robot) const { return makeScan(T_world_robot).toPoints(); }
  LaserScan makeScan(const SE2& T_world_robot) const { return sim_->exactScan(T_world_robot); }
  const std::vector<sim::TimedPose>& route() const { return route_; }
  const sim::World& world() const { return scenario_.world; }

 private:
  sim::Scenario scenario_;
  sim::SimulatorOptions opts_;
  std::vector<sim::TimedPose> route_;
  std::unique_ptr<sim::Simulator> sim_;
};

const SimScans& office() {
  static const SimScans s("office");
  return s;
}

// A map built by the mapping module from noise-free scans at every 5th pose of the route.
const OccupancyImage& officeMap() {
  static const OccupancyImage image = [] {
    const auto& sim = office();
    mapping::MapOptions mo;
    mo.resolution_m = 0.05;
    auto map = mapping::makeMap(mapping::MapModel::kLogOdds, mo);
    for (std::size_t k = 0; k < sim.route().size(); k += 5) {
      const SE2 T = sim.route()[k].T_world_robot;
      map->insert(sim.makeScan(T), T);
    }
    return mapping::toOccupancyImage(*map);
  }();
  return image;
}

LikelihoodFieldOptions withSolver(LfSolver solver) {
  LikelihoodFieldOptions o;
  o.solver = solver;
  return o;
}

class LfSolverTest : public ::testing::TestWithParam<LfSolver> {};

TEST_P(LfSolverTest, RecoversKnownTransformsExactly) {
  const auto& sim = office();
  const auto opts = withSolver(GetParam());
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int cases = 0;
  for (std::size_t k = 5; k < sim.route().size(); k += sim.route().size() / 8) {
    const SE2 A = sim.route()[k].T_world_robot;
    const SE2 delta(0.1 * u(rng), 0.1 * u(rng), 3.0 * kDeg * u(rng));
    const auto target = sim.scanAt(A);
    const auto source = sim.scanAt(A * delta);
    const auto r = matchLikelihoodField(target, source, SE2(), opts);
    ASSERT_TRUE(r.converged) << "route index " << k << ": " << toString(r.status) << " " << r.message;
    EXPECT_TRUE(test::IsNearPose(delta, r.T_target_source, 0.01, 0.2)) << "route index " << k;
    EXPECT_GT(r.num_inliers, 100u);
    EXPECT_TRUE(r.covariance.allFinite());
    EXPECT_GT(r.information.determinant(), 0.0);
    ++cases;
  }
  EXPECT_GE(cases, 8);
}

TEST_P(LfSolverTest, ConvergesFrom20cmAnd5Degrees) {
  const auto& sim = office();
  const auto opts = withSolver(GetParam());
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ang(-std::numbers::pi, std::numbers::pi);
  int ok = 0, n = 0;
  for (std::size_t k = 3; k < sim.route().size(); k += sim.route().size() / 12, ++n) {
    const SE2 A = sim.route()[k].T_world_robot;
    const double a = ang(rng);
    const SE2 delta(0.2 * std::cos(a), 0.2 * std::sin(a), (n % 2 ? 5.0 : -5.0) * kDeg);
    const auto r = matchLikelihoodField(sim.scanAt(A), sim.scanAt(A * delta), SE2(), opts);
    if (r.converged && test::IsNearPose(delta, r.T_target_source, 0.01, 0.2)) ++ok;
  }
  EXPECT_GE(n, 12);
  // Measured: Gauss-Newton 13 of 13, Ceres 10 of 13 (its trust region stops in a local minimum of
  // the truncated field more often from this far out).
  EXPECT_GE(ok, GetParam() == LfSolver::kGaussNewton ? n - 1 : n - 4) << ok << " of " << n << " recovered";
}

// Gauss-Newton (IRLS weights) and Ceres (the loss applied per point inside one residual block)
// minimise the same robust cost: with noisy scans and clutter in the source that no wall explains,
// they agree, for each loss; and the loss matters there (without it the clutter pulls the pose).
TEST(LikelihoodField, GaussNewtonAndCeresAgreeWithOutliers) {
  const auto& sim = office();
  std::mt19937 rng(13);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  auto noisy = [&](Points2 pts) {
    for (auto& p : pts) p += Eigen::Vector2d(noise(rng), noise(rng));
    return pts;
  };
  double moved_without_loss = 0.0;
  int cases = 0;
  for (std::size_t k = 9; k < sim.route().size(); k += sim.route().size() / 5) {
    const SE2 A = sim.route()[k].T_world_robot;
    const SE2 delta(0.08 * u(rng), 0.08 * u(rng), 3.0 * kDeg * u(rng));
    const Points2 target = noisy(sim.scanAt(A));
    Points2 source = noisy(sim.scanAt(A * delta));
    // Clutter: a tenth of the points moved 5-15 cm off their walls, all to the same side.
    for (std::size_t i = 0; i < source.size(); i += 10)
      source[i] += Eigen::Vector2d(0.05 + 0.1 * std::abs(u(rng)), 0.0);
    for (LfLoss loss : {LfLoss::kHuber, LfLoss::kCauchy}) {
      LikelihoodFieldOptions o;
      o.loss = loss;
      const auto field = LikelihoodField::fromPoints(target, o);
      const Result gn = matchLikelihoodField(field, source, SE2(), o);
      o.solver = LfSolver::kCeres;
      const Result ceres = matchLikelihoodField(field, source, SE2(), o);
      EXPECT_TRUE(test::IsNearPose(gn.T_target_source, ceres.T_target_source, 0.003, 0.1))
          << "route index " << k << ": " << gn.T_target_source.vector().transpose() << " vs "
          << ceres.T_target_source.vector().transpose();
      // (The clutter, within the field's truncation, still pulls both by about a centimetre.)
      EXPECT_TRUE(test::IsNearPose(delta, gn.T_target_source, 0.02, 0.3)) << "route index " << k;
      o.loss = LfLoss::kNone;
      const Result plain = matchLikelihoodField(field, source, SE2(), o);
      moved_without_loss = std::max(moved_without_loss,
                                    (plain.T_target_source.translation() - ceres.T_target_source.translation()).norm());
      ++cases;
    }
  }
  EXPECT_GE(cases, 8);
  EXPECT_GT(moved_without_loss, 0.005) << moved_without_loss;
}

TEST_P(LfSolverTest, ScanToMapRecoversThePose) {
  const auto& sim = office();
  const auto& image = officeMap();
  auto opts = withSolver(GetParam());
  const auto field = LikelihoodField::fromMap(image, opts);
  ASSERT_FALSE(field.empty());
  int ok = 0, n = 0;
  for (std::size_t k = 7; k < sim.route().size(); k += sim.route().size() / 6, ++n) {
    const SE2 truth = sim.route()[k].T_world_robot;
    const SE2 init = truth * SE2(0.1, -0.08, 3.0 * kDeg);
    const auto r = matchLikelihoodField(field, sim.scanAt(truth), init, opts);
    // Not `converged`: against the unsigned field of a map, Gauss-Newton may keep oscillating by
    // sub-millimetre steps around the kink at the cell centres and report kMaxIterations.
    if (test::IsNearPose(truth, r.T_target_source, 0.03, 0.5)) ++ok;
    EXPECT_TRUE(test::IsNearPose(truth, r.T_target_source, 0.03, 0.5)) << "route index " << k;
  }
  EXPECT_EQ(ok, n);
}

TEST(LikelihoodField, LineSearchStopsAtTheMinimumOfAMap) {
  // Plain Gauss-Newton against a map's unsigned field may step across the minimum until
  // max_iterations (see ScanToMapRecoversThePose); with the line search every match converges, at
  // the same accuracy.
  const auto& sim = office();
  LikelihoodFieldOptions opts;
  opts.line_search = true;
  const auto field = LikelihoodField::fromMap(officeMap(), opts);
  for (std::size_t k = 7; k < sim.route().size(); k += sim.route().size() / 6) {
    const SE2 truth = sim.route()[k].T_world_robot;
    const auto r = matchLikelihoodField(field, sim.scanAt(truth), truth * SE2(0.1, -0.08, 3.0 * kDeg), opts);
    EXPECT_TRUE(r.converged) << "route index " << k << ": " << toString(r.status) << " after " << r.iterations;
    EXPECT_LT(r.iterations, 3 * opts.max_iterations) << "route index " << k;
    EXPECT_TRUE(test::IsNearPose(truth, r.T_target_source, 0.03, 0.5)) << "route index " << k;
  }
}

TEST_P(LfSolverTest, CorridorIsDegenerateAlongItsAxis) {
  const SimScans corridor("corridor");
  const SE2 A(30.0, 0.0, 0.0);  // middle of the 60 m corridor along x
  const auto target = corridor.scanAt(A);
  const auto source = corridor.scanAt(A * SE2(0.0, 0.05, 1.0 * kDeg));
  const auto r = matchLikelihoodField(target, source, SE2(), withSolver(GetParam()));
  ASSERT_GT(r.num_inliers, 0u);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(r.information);
  const Eigen::Vector3d weakest = es.eigenvectors().col(0);
  EXPECT_GT(std::abs(weakest.x()), 0.95) << "weakest direction " << weakest.transpose();
  EXPECT_LT(es.eigenvalues()(0), 1e-3 * es.eigenvalues()(1));
  EXPECT_NEAR(r.T_target_source.y(), 0.05, 0.01);
  EXPECT_NEAR(r.T_target_source.theta(), 1.0 * kDeg, 0.2 * kDeg);
}

TEST_P(LfSolverTest, BadInputGivesAFiniteFailedResult) {
  const auto& sim = office();
  const auto opts = withSolver(GetParam());
  const auto target = sim.scanAt(sim.route()[10].T_world_robot);
  const double nan = std::numeric_limits<double>::quiet_NaN();

  auto r = matchLikelihoodField(target, Points2{}, SE2(0.1, 0.2, 0.3), opts);
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.status, Status::kTooFewPoints);
  EXPECT_TRUE(r.T_target_source.isApprox(SE2(0.1, 0.2, 0.3)));

  r = matchLikelihoodField(target, Points2{{1, 0}, {0, 1}}, SE2(), opts);
  EXPECT_EQ(r.status, Status::kTooFewPoints);

  r = matchLikelihoodField(target, Points2(50, Eigen::Vector2d(nan, nan)), SE2(), opts);
  EXPECT_EQ(r.status, Status::kTooFewPoints);

  r = matchLikelihoodField(Points2{}, target, SE2(), opts);
  EXPECT_EQ(r.status, Status::kTooFewPoints);
  EXPECT_FALSE(r.message.empty());

  r = matchLikelihoodField(target, target, SE2(nan, 0, 0), opts);
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.status, Status::kInvalidInput);
  EXPECT_TRUE(r.T_target_source.isFinite());

  // All source points identical, far from the target: no inliers.
  r = matchLikelihoodField(target, Points2(50, Eigen::Vector2d(500, 500)), SE2(), opts);
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.status, Status::kTooFewInliers);
  EXPECT_TRUE(r.T_target_source.isFinite());

  // All source points identical on a wall: one point constrains at most one direction.
  r = matchLikelihoodField(target, Points2(50, target[0]), SE2(), opts);
  EXPECT_TRUE(r.T_target_source.isFinite());
  EXPECT_TRUE(r.information.allFinite());
}

INSTANTIATE_TEST_SUITE_P(Solvers, LfSolverTest, ::testing::Values(LfSolver::kGaussNewton, LfSolver::kCeres),
                         [](const auto& info) { return info.param == LfSolver::kCeres ? "Ceres" : "GaussNewton"; });

TEST(LikelihoodField, GradientMatchesNumericDifferences) {
  const auto& sim = office();
  const auto target = sim.scanAt(sim.route()[30].T_world_robot);
  const auto field = LikelihoodField::fromPoints(target);
  std::mt19937 rng(3);
  int checked = 0;
  for (int l = 0; l < field.numLevels(); ++l) {
    const auto& lv = field.level(l);
    std::uniform_int_distribution<std::size_t> pick(0, target.size() - 1);
    std::uniform_real_distribution<double> off(-lv.truncation, lv.truncation);
    for (int n = 0; n < 400; ++n) {
      const Eigen::Vector2d p = target[pick(rng)] + Eigen::Vector2d(off(rng), off(rng));
      // Stay inside one cell so that the bilinear interpolant is smooth around p.
      const Eigen::Vector2d u = (p - lv.origin) / lv.resolution;
      const Eigen::Vector2d f = u.array() - u.array().floor();
      if ((f.array() < 0.01).any() || (f.array() > 0.99).any()) continue;
      const auto s = field.sample(p, l);
      if (!s.inlier) continue;
      const double h = 1e-5 * lv.resolution;
      const double gx = (field.sample(p + Eigen::Vector2d(h, 0), l).value - field.sample(p - Eigen::Vector2d(h, 0), l).value) / (2 * h);
      const double gy = (field.sample(p + Eigen::Vector2d(0, h), l).value - field.sample(p - Eigen::Vector2d(0, h), l).value) / (2 * h);
      EXPECT_NEAR(s.gradient.x(), gx, 1e-6);
      EXPECT_NEAR(s.gradient.y(), gy, 1e-6);
      ++checked;
    }
  }
  EXPECT_GT(checked, 300);
}

TEST(LikelihoodField, ValueIsSamplesValueToTheLastBit) {
  const auto& sim = office();
  const auto target = sim.scanAt(sim.route()[30].T_world_robot);
  const auto field = LikelihoodField::fromPoints(target);
  std::mt19937 rng(5);
  for (int l = 0; l < field.numLevels(); ++l) {
    const auto& lv = field.level(l);
    std::uniform_int_distribution<std::size_t> pick(0, target.size() - 1);
    // Also points beyond the grid and beyond the truncation.
    std::uniform_real_distribution<double> off(-40.0 * lv.resolution, 40.0 * lv.resolution);
    for (int n = 0; n < 2000; ++n) {
      const Eigen::Vector2d p = target[pick(rng)] + Eigen::Vector2d(off(rng), off(rng));
      EXPECT_EQ(field.value(p, l), field.sample(p, l).value) << "level " << l << " at " << p.transpose();
    }
    const double nan = std::numeric_limits<double>::quiet_NaN();
    EXPECT_EQ(field.value(Eigen::Vector2d(nan, 0.0), l), lv.truncation);
  }
}

TEST(LikelihoodField, InterpolatesTheNodesAndIsZeroOnAWall) {
  // A straight wall x = 1.013 seen by a sensor at the origin: the signed distance is 1.013 - x,
  // linear, so bilinear interpolation reproduces it exactly between nodes (sub-cell accurate).
  Points2 wall;
  for (double y = -2.0; y <= 2.0; y += 0.02) wall.emplace_back(1.013, y);
  LikelihoodFieldOptions o;
  o.levels = 2;
  const auto field = LikelihoodField::fromPoints(wall, o);
  ASSERT_EQ(field.numLevels(), 2);
  for (double x : {0.9, 0.95, 1.0, 1.013, 1.04, 1.1})
    for (double y : {-0.5, 0.123, 1.01}) {
      const auto s = field.sample({x, y}, 0);
      ASSERT_TRUE(s.inlier) << x << " " << y;
      EXPECT_NEAR(s.value, 1.013 - x, 1e-6);
      EXPECT_NEAR(s.gradient.x(), -1.0, 1e-5);
      EXPECT_NEAR(s.gradient.y(), 0.0, 1e-5);
    }
  // Nodes: the sample at a node equals the stored node value.
  const auto& lv = field.level(1);
  const Eigen::Vector2d q = lv.origin + Eigen::Vector2d(7, 9) * lv.resolution;
  EXPECT_NEAR(field.sample(q, 1).value, lv.at(7, 9), 1e-6);
  // Far away: truncated, not an inlier.
  const auto far = field.sample({5.0, 0.0}, 0);
  EXPECT_FALSE(far.inlier);
  EXPECT_DOUBLE_EQ(far.value, o.truncation_m);
}

// The field of a scan node by node from its definition: the signed distance to the line of each
// wall segment (consecutive points at most connect_max_gap_m apart) over the nodes whose
// projection falls on the segment extended by one node spacing, positive on the sensor's side; the
// distance to each isolated point; the value of smallest magnitude, clamped at the truncation. The
// reference visits each segment's whole bounding box; the field build visits only the band along
// the segment, and must not miss a node of it (segments at every angle: a noisy scan, and walls
// exactly along the axes).
TEST(LikelihoodField, FieldMatchesItsDefinitionNodeByNode) {
  const auto& sim = office();
  Points2 noisy = sim.scanAt(sim.route()[40].T_world_robot);
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 0.01);
  for (auto& p : noisy) p += Eigen::Vector2d(noise(rng), noise(rng));
  Points2 square;  // walls along the axes, a gap, and an isolated point
  for (double t = -1.0; t <= 1.0; t += 0.05) {
    square.emplace_back(2.0, t);
    square.emplace_back(t, -1.5);
  }
  square.emplace_back(-3.0, 3.0);
  for (const Points2& pts : {noisy, sim.scanAt(sim.route()[10].T_world_robot), square}) {
    const LikelihoodFieldOptions o;
    const auto field = LikelihoodField::fromPoints(pts, o);
    std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>> segments;
    std::vector<char> in_segment(pts.size(), 0);
    for (std::size_t i = 0; i + 1 < pts.size(); ++i) {
      const double d = (pts[i + 1] - pts[i]).norm();
      if (d <= o.connect_max_gap_m && d > 1e-9) {
        segments.emplace_back(pts[i], pts[i + 1]);
        in_segment[i] = in_segment[i + 1] = 1;
      }
    }
    for (int l = 0; l < field.numLevels(); ++l) {
      const auto& lv = field.level(l);
      const double r = lv.truncation, ext = lv.resolution;
      std::vector<float> ref(lv.values.size(), static_cast<float>(r));
      auto visitBox = [&](const Eigen::Vector2d& lo, const Eigen::Vector2d& hi, auto&& f) {
        const int i0 = std::max(0, static_cast<int>(std::ceil((lo.x() - lv.origin.x()) / lv.resolution)));
        const int i1 = std::min(lv.width - 1, static_cast<int>(std::floor((hi.x() - lv.origin.x()) / lv.resolution)));
        const int j0 = std::max(0, static_cast<int>(std::ceil((lo.y() - lv.origin.y()) / lv.resolution)));
        const int j1 = std::min(lv.height - 1, static_cast<int>(std::floor((hi.y() - lv.origin.y()) / lv.resolution)));
        for (int j = j0; j <= j1; ++j)
          for (int i = i0; i <= i1; ++i) {
            const Eigen::Vector2d q(lv.origin.x() + i * lv.resolution, lv.origin.y() + j * lv.resolution);
            const double d = f(q);
            float& v =
                ref[static_cast<std::size_t>(j) * static_cast<std::size_t>(lv.width) + static_cast<std::size_t>(i)];
            if (std::abs(d) < std::abs(v)) v = static_cast<float>(d);
          }
      };
      for (const auto& [a, b] : segments) {
        const Eigen::Vector2d u = (b - a) / (b - a).norm();
        const double len = (b - a).norm();
        Eigen::Vector2d n(-u.y(), u.x());
        if (n.dot(-a) < 0.0) n = -n;
        visitBox(a.cwiseMin(b).array() - (r + ext), a.cwiseMax(b).array() + (r + ext), [&](const Eigen::Vector2d& q) {
          const double t = (q - a).dot(u);
          return t < -ext || t > len + ext ? std::numeric_limits<double>::infinity() : (q - a).dot(n);
        });
      }
      for (std::size_t i = 0; i < pts.size(); ++i)
        if (!in_segment[i])
          visitBox(pts[i].array() - r, pts[i].array() + r,
                   [&](const Eigen::Vector2d& q) { return (q - pts[i]).norm(); });
      std::size_t differ = 0, near_wall = 0;
      for (std::size_t k = 0; k < ref.size(); ++k) {
        differ += std::abs(ref[k] - lv.values[k]) > 1e-6f;
        near_wall += std::abs(ref[k]) < static_cast<float>(r);
      }
      EXPECT_EQ(differ, 0u) << "level " << l << " of " << ref.size() << " nodes";
      EXPECT_GT(near_wall, 100u) << "level " << l;
    }
  }
}

TEST(LikelihoodField, OptionsOutOfDomainThrowNamingTheField) {
  const Points2 pts{{1, 0}, {1, 0.1}, {1, 0.2}};
  auto expectField = [&](LikelihoodFieldOptions o, const std::string& field) {
    try {
      (void)matchLikelihoodField(pts, pts, SE2(), o);
      ADD_FAILURE() << "no error for " << field;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
      EXPECT_EQ(e.where().field, field);
    }
  };
  LikelihoodFieldOptions o;
  o.resolution_m = 0;
  expectField(o, "resolution_m");
  o = {};
  o.levels = 0;
  expectField(o, "levels");
  o = {};
  o.truncation_m = 0.01;
  expectField(o, "truncation_m");
  o = {};
  o.max_iterations = 0;
  expectField(o, "max_iterations");
  o = {};
  o.loss_scale_m = std::numeric_limits<double>::quiet_NaN();
  expectField(o, "loss_scale_m");
  o = {};
  o.min_points = 2;
  expectField(o, "min_points");
}

}  // namespace
}  // namespace lidar2d::registration
