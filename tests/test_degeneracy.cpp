// Degeneracy detectors on tiny synthetic worlds (single wall, L-corner, corridors, wide hall, clutter,
// circle), the cannot-decide cases, DBSCAN against a brute-force reference, the remapping API and the
// ground-truth labels of the simulated worlds.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <random>

#include "lidar2d/core/error.hpp"
#include "lidar2d/degeneracy/degeneracy.hpp"
#include "lidar2d/degeneracy/ground_truth.hpp"
#include "lidar2d/registration/matcher.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace lidar2d::degeneracy {
namespace {

using V = Eigen::Vector2d;
constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

struct Laser {
  int beams = 360;
  double fov_deg = 270.0;
  double range_max_m = 30.0;
  double noise_m = 0.01;
};

// The points a laser at `T_world_robot` (mounted at the robot's centre) sees in `world`, robot frame.
Points2 scan(const sim::World& world, const SE2& T_world_robot, const Laser& laser = {}, std::uint64_t seed = 1) {
  sim::SimulatorOptions o;
  o.laser.beams = laser.beams;
  o.laser.fov_rad = laser.fov_deg * kDeg;
  o.laser.range_max_m = laser.range_max_m;
  o.laser.range_noise_m = laser.noise_m;
  o.laser.dropout = 0.0;
  o.laser.T_robot_laser = SE2();
  o.seed = seed;
  sim::Simulator s(world, {{0.0, T_world_robot}}, o);
  const Frame f = *s.next();
  return f.scan.toPoints(f.T_robot_laser);
}

sim::World walls(std::vector<sim::Segment> segs, std::vector<sim::Arc> arcs = {}) {
  return sim::World(std::move(segs), std::move(arcs));
}

// Absolute difference of two axes [rad], in [0, pi/2].
double axisDiff(double a, double b) { return std::abs(0.5 * wrapAngle(2.0 * (a - b))); }

void expectDegenerateAlong(const Result& r, double axis_rad) {
  EXPECT_EQ(r.verdict, Verdict::kDegenerate)
      << "geometric " << toString(r.geometric.verdict) << " " << r.geometric.score << " " << r.geometric.reason
      << "; information " << toString(r.information.verdict) << " " << r.information.score;
  EXPECT_EQ(r.geometric.verdict, Verdict::kDegenerate) << r.geometric.score << " " << r.geometric.reason;
  EXPECT_EQ(r.information.verdict, Verdict::kDegenerate) << r.information.score;
  EXPECT_LT(axisDiff(r.direction_rad, axis_rad), 3 * kDeg) << r.direction_rad / kDeg;
  EXPECT_LT(axisDiff(r.geometric.direction_rad, axis_rad), 3 * kDeg) << r.geometric.direction_rad / kDeg;
  EXPECT_GE(r.score, 0.0);
  EXPECT_LT(r.score, 0.01);
}

void expectWellConstrained(const Result& r) {
  EXPECT_EQ(r.verdict, Verdict::kWellConstrained) << "score " << r.score;
  EXPECT_EQ(r.geometric.verdict, Verdict::kWellConstrained) << r.geometric.score << " " << r.geometric.reason;
  EXPECT_EQ(r.information.verdict, Verdict::kWellConstrained) << r.information.score;
  // Clear of the band where one detector confirms the other's "degenerate" (2x the 0.01 threshold).
  EXPECT_GT(r.score, 2 * Options{}.information.threshold);
  EXPECT_LE(r.score, 0.5 + 1e-9);
}

TEST(Degeneracy, SingleWallIsDegenerateAlongIt) {
  const auto w = walls({{V(-40, 2), V(40, 2)}});
  expectDegenerateAlong(analyze(scan(w, SE2())), 0.0);
  // The robot turned by 40 degrees: the wall's axis in the robot frame turns by -40 degrees.
  expectDegenerateAlong(analyze(scan(w, SE2(1, 0, 40 * kDeg))), -40 * kDeg);
}

TEST(Degeneracy, LCornerIsWellConstrained) {
  const auto w = walls({{V(-40, 2), V(3, 2)}, {V(3, 2), V(3, -40)}});
  expectWellConstrained(analyze(scan(w, SE2())));
}

TEST(Degeneracy, ClosedRoomIsWellConstrained) {
  const auto w = walls({{V(-3, -2), V(4, -2)}, {V(4, -2), V(4, 3)}, {V(4, 3), V(-3, 3)}, {V(-3, 3), V(-3, -2)}});
  expectWellConstrained(analyze(scan(w, SE2(0.5, 0.3, 0.2))));
}

TEST(Degeneracy, LongCorridorIsDegenerateAlongItsAxis) {
  for (double axis_deg : {0.0, 30.0, 90.0, -65.0}) {
    const SE2 T(0, 0, axis_deg * kDeg);  // corridor frame in the world
    const auto w = walls({{T * V(-100, -1), T * V(100, -1)}, {T * V(-100, 1), T * V(100, 1)}});
    const Result r = analyze(scan(w, T * SE2(0, 0.2, 5 * kDeg)));
    SCOPED_TRACE(axis_deg);
    expectDegenerateAlong(r, -5 * kDeg);
  }
}

TEST(Degeneracy, CorridorWithRecessedDoorsIsDegenerate) {
  // 2 m corridor; 1 m doors every 4 m on both sides, recessed 0.15 m (closed doors in their frames).
  std::vector<sim::Segment> s;
  for (double x = -60; x < 60; x += 4) {
    for (double side : {-1.0, 1.0}) {
      s.push_back({V(x, side), V(x + 3, side)});                    // wall
      s.push_back({V(x + 3, side), V(x + 3, side * 1.15)});         // jamb
      s.push_back({V(x + 3, side * 1.15), V(x + 4, side * 1.15)});  // door
      s.push_back({V(x + 4, side * 1.15), V(x + 4, side)});         // jamb
    }
  }
  const Result r = analyze(scan(walls(s), SE2(0.3, 0.1, 0)));
  // The jambs are 15 cm pieces seen edge-on: they hardly constrain, and the walls and doors are parallel.
  EXPECT_EQ(r.verdict, Verdict::kDegenerate) << r.geometric.score << " " << r.information.score;
  EXPECT_LT(axisDiff(r.direction_rad, 0.0), 3 * kDeg);
}

TEST(Degeneracy, CorridorOpeningIntoARoomIsWellConstrained) {
  // The corridor ends 6 m ahead in a room whose far wall faces the robot.
  std::vector<sim::Segment> s{{V(-60, -1), V(6, -1)}, {V(-60, 1), V(6, 1)},  {V(6, 1), V(6, 4)},  {V(6, 4), V(12, 4)},
                              {V(12, 4), V(12, -4)},  {V(12, -4), V(6, -4)}, {V(6, -4), V(6, -1)}};
  expectWellConstrained(analyze(scan(walls(s), SE2())));
}

TEST(Degeneracy, WideHallWithOnlyTheSideWallsInRangeIsDegenerate) {
  // A 12 m wide hall, 200 m long; a 10 m laser sees only the side walls.
  const auto w = walls({{V(-100, -6), V(100, -6)}, {V(-100, 6), V(100, 6)}});
  Laser laser;
  laser.range_max_m = 10.0;
  expectDegenerateAlong(analyze(scan(w, SE2(0, 0.5, 0), laser)), 0.0);
}

TEST(Degeneracy, IsolatedClutterPointsDoNotHideACorridor) {
  const auto w = walls({{V(-100, -1), V(100, -1)}, {V(-100, 1), V(100, 1)}});
  Points2 pts = scan(w, SE2());
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(-15, 15), uy(-0.9, 0.9);
  for (int k = 0; k < 15; ++k) pts.push_back(V(ux(rng), uy(rng)));  // stray returns (dust, a person's legs)
  const Result r = analyze(pts);
  expectDegenerateAlong(r, 0.0);
}

TEST(Degeneracy, FurnitureInACorridorConstrainsIt) {
  // Cabinets along one wall: their 0.5 m faces across the corridor constrain the motion along it.
  std::vector<sim::Segment> s{{V(-100, -1), V(100, -1)}, {V(-100, 1), V(100, 1)}};
  for (double x : {-3.0, 2.0}) {
    s.push_back({V(x, 1), V(x, 0.5)});
    s.push_back({V(x, 0.5), V(x + 1, 0.5)});
    s.push_back({V(x + 1, 0.5), V(x + 1, 1)});
  }
  expectWellConstrained(analyze(scan(walls(s), SE2())));
}

TEST(Degeneracy, PillarsInTheOpenConstrainEverything) {
  std::vector<sim::Arc> arcs;
  for (const V& c : {V(3, 1), V(-2, 4), V(1, -3), V(-4, -2), V(6, -5)}) arcs.push_back(sim::Arc::circle(c, 0.3));
  expectWellConstrained(analyze(scan(sim::World({}, arcs), SE2())));
}

TEST(Degeneracy, RoundRoomConstrainsTranslationNotRotation) {
  const sim::World w({}, {sim::Arc::circle(V(0, 0), 4.0)});
  Laser laser;
  laser.fov_deg = 360.0;
  const Result centred = analyze(scan(w, SE2(0, 0, 0), laser));
  expectWellConstrained(centred);
  EXPECT_LT(centred.information.rotation_score, 0.01);  // rotation about the centre changes nothing
  EXPECT_EQ(centred.geometric.lines.size() > 0 || centred.geometric.num_unstructured_points > 0, true);
  // A square room constrains rotation.
  const auto square = walls({{V(-3, -3), V(3, -3)}, {V(3, -3), V(3, 3)}, {V(3, 3), V(-3, 3)}, {V(-3, 3), V(-3, -3)}});
  EXPECT_GT(analyze(scan(square, SE2(0.5, 0, 0), laser)).information.rotation_score, 0.05);
}

TEST(Degeneracy, ScoreDoesNotDependOnTheBeamCount) {
  const auto l_corner = walls({{V(-40, 2), V(40, 2)}, {V(4, 2), V(4, -40)}});
  const auto corridor = walls({{V(-100, -1), V(100, -1)}, {V(-100, 1), V(100, 1)}});
  std::vector<double> scores;
  for (int beams : {180, 360, 1440}) {
    SCOPED_TRACE(beams);
    Laser laser;
    laser.beams = beams;
    const Result l = analyze(scan(l_corner, SE2(), laser));
    EXPECT_EQ(l.verdict, Verdict::kWellConstrained);
    scores.push_back(l.score);
    const Result c = analyze(scan(corridor, SE2(), laser));
    EXPECT_EQ(c.verdict, Verdict::kDegenerate);
    EXPECT_LT(c.score, 0.2 * Options{}.information.threshold);
  }
  // An 8-fold beam count changes the normalised score by less than a factor of 2 (far walls are sampled
  // differently), so one threshold serves every scanner.
  const auto [lo, hi] = std::minmax_element(scores.begin(), scores.end());
  EXPECT_LT(*hi / *lo, 2.0);
}

TEST(Degeneracy, CannotDecideOnTooLittleData) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Points2 few;
  for (int i = 0; i < 10; ++i) few.push_back(V(2, -0.5 + 0.1 * i));
  Points2 one_spot;
  for (int i = 0; i < 200; ++i) one_spot.push_back(V(1.0 + 1e-3 * (i % 7), 2.0 + 1e-3 * (i % 5)));
  Points2 all_nan(300, V(nan, nan));
  Points2 sparse;  // 100 points 2 m apart: no clusters, no normals
  for (int i = 0; i < 100; ++i)
    sparse.push_back(V(std::cos(i * 0.7) * (2 + 0.3 * i), std::sin(i * 0.7) * (2 + 0.3 * i)));
  for (const Points2& input : {few, one_spot, all_nan, sparse, Points2{}}) {
    const Result r = analyze(input);
    EXPECT_EQ(r.verdict, Verdict::kCannotDecide) << input.size();
    EXPECT_FALSE(r.reason.empty());
    EXPECT_TRUE(std::isnan(r.score));
    EXPECT_TRUE(std::isnan(r.direction_rad));
    EXPECT_EQ(analyzeGeometric(input).verdict, Verdict::kCannotDecide);
    EXPECT_EQ(analyzeInformation(input).verdict, Verdict::kCannotDecide);
  }
}

TEST(Degeneracy, NanPointsAmongValidOnesAreIgnored) {
  const auto w = walls({{V(-40, 2), V(40, 2)}, {V(4, 2), V(4, -40)}});
  Points2 pts = scan(w, SE2());
  const Result clean = analyze(pts);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 0; i < pts.size(); i += 3) pts.insert(pts.begin() + static_cast<long>(i), V(nan, 1.0));
  const Result r = analyze(pts);
  EXPECT_EQ(r.verdict, clean.verdict);
  EXPECT_NEAR(r.score, clean.score, 1e-12);
  ASSERT_EQ(r.geometric.cluster_of_point.size(), pts.size());
}

TEST(Degeneracy, BadOptionsThrow) {
  Options o;
  o.geometric.cluster_eps_m = 0.0;
  EXPECT_THROW(analyze({}, o), Error);
  o = {};
  o.information.threshold = 0.7;
  EXPECT_THROW(analyze({}, o), Error);
  GeometricOptions g;
  g.input.min_points = 1;
  EXPECT_THROW(analyzeGeometric({}, g), Error);
  EXPECT_FALSE(Options{}.check().size());
}

// DBSCAN with core_min_points = 1 is the connected components of the eps-graph: compare with a
// brute-force union-find on seeded random points.
TEST(Degeneracy, ClustersMatchABruteForceReference) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-5, 5);
  for (int trial = 0; trial < 5; ++trial) {
    Points2 pts;
    for (int i = 0; i < 300; ++i) pts.push_back(V(u(rng), u(rng)));
    GeometricOptions o;
    o.cluster_eps_m = 0.35;
    o.core_min_points = 1;
    o.min_cluster_points = 2;
    const GeometricResult r = analyzeGeometric(pts, o);
    std::vector<int> parent(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) parent[i] = static_cast<int>(i);
    std::function<int(int)> find = [&](int i) { return parent[i] == i ? i : parent[i] = find(parent[i]); };
    for (std::size_t i = 0; i < pts.size(); ++i)
      for (std::size_t j = i + 1; j < pts.size(); ++j)
        if ((pts[i] - pts[j]).norm() <= o.cluster_eps_m) parent[find(static_cast<int>(i))] = find(static_cast<int>(j));
    std::map<int, int> size;
    for (std::size_t i = 0; i < pts.size(); ++i) ++size[find(static_cast<int>(i))];
    for (std::size_t i = 0; i < pts.size(); ++i)
      for (std::size_t j = i + 1; j < pts.size(); ++j) {
        const bool same_ref =
            find(static_cast<int>(i)) == find(static_cast<int>(j)) && size[find(static_cast<int>(i))] >= 2;
        const bool same = r.cluster_of_point[i] >= 0 && r.cluster_of_point[i] == r.cluster_of_point[j];
        ASSERT_EQ(same, same_ref) << i << " " << j;
      }
    for (std::size_t i = 0; i < pts.size(); ++i)
      EXPECT_EQ(r.cluster_of_point[i] < 0, size[find(static_cast<int>(i))] < 2);
  }
}

TEST(Degeneracy, LinesOfAnLShapedClusterAreSplitAtTheCorner) {
  Points2 pts;
  for (int i = 0; i <= 40; ++i) pts.push_back(V(3.0, -2.0 + 0.05 * i));  // x = 3, y -2..0
  for (int i = 1; i <= 40; ++i) pts.push_back(V(3.0 - 0.05 * i, 0.0));   // y = 0, x 3..1
  const GeometricResult r = analyzeGeometric(pts);
  EXPECT_EQ(r.num_clusters, 1u);
  ASSERT_GE(r.lines.size(), 2u);
  EXPECT_LE(r.lines.size(), 4u);
  double longest[2] = {0, 0};  // longest vertical and horizontal lines
  for (const Line& l : r.lines) {
    const int k = std::abs(l.direction.y()) > std::abs(l.direction.x()) ? 0 : 1;
    longest[k] = std::max(longest[k], l.length());
  }
  EXPECT_GT(longest[0], 1.5);
  EXPECT_GT(longest[1], 1.5);
  EXPECT_EQ(r.verdict, Verdict::kWellConstrained);
}

TEST(DegeneracyRemap, ProjectorKeepsOnlyWellConstrainedDirections) {
  Eigen::Matrix3d H = Eigen::Vector3d(1e-6, 50.0, 20.0).asDiagonal();
  const Eigen::Matrix3d P = wellConstrainedProjector(H, 1e-3);
  EXPECT_TRUE(P.isApprox(Eigen::Vector3d(0, 1, 1).asDiagonal().toDenseMatrix(), 1e-12)) << P;
  // Rotated: the free direction at 30 degrees.
  const double c = std::cos(30 * kDeg), s = std::sin(30 * kDeg);
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  R.topLeftCorner<2, 2>() << c, -s, s, c;
  const Eigen::Matrix3d P2 = wellConstrainedProjector(R * H * R.transpose(), 1e-3);
  EXPECT_NEAR((P2 * Eigen::Vector3d(c, s, 0)).norm(), 0.0, 1e-9);
  EXPECT_NEAR((P2 * Eigen::Vector3d(-s, c, 0.3) - Eigen::Vector3d(-s, c, 0.3)).norm(), 0.0, 1e-9);
  EXPECT_TRUE(P2.isApprox(projectorRemovingDirection(30 * kDeg), 1e-9));
  EXPECT_TRUE(wellConstrainedProjector(Eigen::Matrix3d::Constant(std::nan("")), 0.0).isZero());
}

// Solution remapping with the information matrix a matcher returns: in a corridor along x, the
// projector built from point-to-line ICP's H removes x and keeps y and theta.
TEST(DegeneracyRemap, ProjectorFromAMatchersInformationInACorridor) {
  const auto w = walls({{V(-100, -1), V(100, -1)}, {V(-100, 1), V(100, 1)}});
  const Points2 target = scan(w, SE2(), {}, 1), source = scan(w, SE2(0.1, 0.05, 0.02), {}, 2);
  registration::MatcherOptions mo;
  mo.method = registration::Method::kP2L;
  const registration::Result r = registration::matchScans(target, source, SE2(0.1, 0.05, 0.02), mo);
  ASSERT_GT(r.num_inliers, 100u);
  // The matcher's normals (5 nearest neighbours, 1 cm noise) leave about 0.012 per inlier along the
  // corridor (the detector's own, wider normals: below 0.002): a threshold of 0.05 per inlier.
  const Eigen::Matrix3d P = wellConstrainedProjector(r.information, 0.05 * static_cast<double>(r.num_inliers));
  EXPECT_LT((P * Eigen::Vector3d::UnitX()).norm(), 0.05) << P;
  EXPECT_NEAR((P * Eigen::Vector3d::UnitY() - Eigen::Vector3d::UnitY()).norm(), 0.0, 0.05) << P;
  EXPECT_NEAR((P * Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitZ()).norm(), 0.0, 0.05) << P;
  // A slid estimate is pulled back to the guess along x only.
  const SE2 remapped = remapPose(SE2(0.1, 0.05, 0.02), SE2(0.6, 0.06, 0.021), P);
  EXPECT_NEAR(remapped.x(), 0.1, 0.03);
  EXPECT_NEAR(remapped.y(), 0.06, 0.01);
}

// The same corridor's match, its translational information per inlier: weak along the corridor's
// axis (x) below the threshold, nothing weak in a room's match, and always the least constrained
// direction with an infinite threshold.
TEST(DegeneracyRemap, TheWeakestDirectionOfAMatchIsTheCorridorsAxis) {
  const auto corridor = walls({{V(-100, -1), V(100, -1)}, {V(-100, 1), V(100, 1)}});
  const auto room = walls({{V(-3, -2), V(3, -2)}, {V(3, -2), V(3, 2)}, {V(3, 2), V(-3, 2)}, {V(-3, 2), V(-3, -2)}});
  registration::MatcherOptions mo;
  mo.method = registration::Method::kP2L;
  auto perInlier = [&](const auto& w) {
    const Points2 target = scan(w, SE2(), {}, 1), source = scan(w, SE2(0.1, 0.05, 0.02), {}, 2);
    const registration::Result r = registration::matchScans(target, source, SE2(0.1, 0.05, 0.02), mo);
    EXPECT_GT(r.num_inliers, 100u);
    return Eigen::Matrix2d(r.information.topLeftCorner<2, 2>() / static_cast<double>(r.num_inliers));
  };
  const Eigen::Matrix2d H_corridor = perInlier(corridor), H_room = perInlier(room);
  const std::optional<Eigen::Vector2d> axis = weakestDirection(H_corridor, 0.05);
  ASSERT_TRUE(axis.has_value()) << H_corridor;
  EXPECT_NEAR(axis->norm(), 1.0, 1e-12);
  EXPECT_GT(std::abs(axis->x()), 0.99) << axis->transpose();
  EXPECT_FALSE(weakestDirection(H_room, 0.05).has_value()) << H_room;
  const std::optional<Eigen::Vector2d> least = weakestDirection(H_room, std::numeric_limits<double>::infinity());
  ASSERT_TRUE(least.has_value());
  // The room is 6 m x 4 m: the walls across x are farther apart, fewer returns pin x.
  EXPECT_GT(std::abs(least->x()), std::abs(least->y())) << least->transpose();
  Eigen::Matrix2d bad = H_corridor;
  bad(0, 1) = bad(1, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(weakestDirection(bad, std::numeric_limits<double>::infinity()).has_value());
}

TEST(DegeneracyRemap, ConstrainMatchKeepsThePriorAlongTheCorridor) {
  Result deg;
  deg.verdict = Verdict::kDegenerate;
  deg.direction_rad = 0.0;                 // the source scan's corridor runs along its x axis
  const SE2 prior(0.10, 0.00, 90 * kDeg);  // the source is turned by 90 degrees: its x is the target's y
  const SE2 match(0.13, 0.40, 91 * kDeg);  // the matcher slid 0.4 m along the corridor
  const SE2 out = constrainMatch(match, prior, deg);
  EXPECT_NEAR(out.x(), 0.13, 1e-12);  // across the corridor: the match
  EXPECT_NEAR(out.y(), 0.00, 1e-12);  // along it: the prior
  EXPECT_NEAR(out.theta(), 91 * kDeg, 1e-12);
  Result fine;
  fine.verdict = Verdict::kWellConstrained;
  EXPECT_TRUE(constrainMatch(match, prior, fine).isApprox(match));
  EXPECT_TRUE(constrainMatch(match, prior, Result{}).isApprox(prior));  // cannot decide
  const SE2 remapped = remapPose(prior, match, Eigen::Matrix3d::Identity());
  EXPECT_TRUE(remapped.isApprox(match, 1e-12, 1e-12));
}

TEST(DegeneracyTruth, SimulatedCorridorIsLabelledDegenerateInItsMiddleOnly) {
  const sim::Scenario sc = sim::builtinScenario("corridor");
  const sim::LaserModel laser;
  const TruthLabel mid = labelFromWorld(sc.world, SE2(20, 0, 0), laser);
  EXPECT_TRUE(mid.degenerate);
  EXPECT_TRUE(mid.enough_hits);
  EXPECT_LT(axisDiff(mid.direction_rad, 0.0), 1e-9);
  EXPECT_FALSE(labelFromWorld(sc.world, SE2(50, 0, 0), laser).degenerate);    // sees the east room's far wall
  EXPECT_FALSE(labelFromWorld(sc.world, SE2(-4, 2.5, 0), laser).degenerate);  // in the west room
  EXPECT_FALSE(labelFromWorld(sim::builtinScenario("office").world, SE2(10, 7.5, 0), laser).degenerate);
}

}  // namespace
}  // namespace lidar2d::degeneracy
