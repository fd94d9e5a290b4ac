// Correlative matching with branch and bound: max-grids against a brute-force window max, the
// branch and bound against the exhaustive search of the same window, recovery on noise-free
// simulated scans (search resolution, then exact after refinement), basin, global mode, bad input.

#include "lidar2d/registration/correlative.hpp"

#include <gtest/gtest.h>

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
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

/// Noise-free 360-beam scans (laser at the robot's centre) of the office world.
class Office {
 public:
  Office() : scenario_(sim::builtinScenario("office")) {
    opts_ = sim::SimulatorOptions{}.noiseFree();
    opts_.laser.beams = 360;
    opts_.laser.fov_rad = 2.0 * std::numbers::pi;
    opts_.laser.T_robot_laser = SE2();
    route_ = sim::samplePath(scenario_.waypoints, sim::PathOptions{});
    sim_ = std::make_unique<sim::Simulator>(scenario_.world, std::vector<sim::TimedPose>{{0.0, SE2()}}, opts_);
  }
  LaserScan makeScan(const SE2& T) const { return sim_->exactScan(T); }
  Points2 scanAt(const SE2& T) const { return makeScan(T).toPoints(); }
  const std::vector<sim::TimedPose>& route() const { return route_; }

 private:
  sim::Scenario scenario_;
  sim::SimulatorOptions opts_;
  std::vector<sim::TimedPose> route_;
  std::unique_ptr<sim::Simulator> sim_;
};

const Office& office() {
  static const Office o;
  return o;
}

/// Every max-grid value (every `step`-th cell, one cell beyond each border) against the brute-force
/// max of the score grid over its window.
void expectMaxGridsAreWindowMaxima(const CorrelativeGrid& g, int step) {
  for (int h = 0; h < g.depth(); ++h) {
    const int w = 1 << h;
    for (int j = -w - 1; j < g.height() + 1; j += step)
      for (int i = -w - 1; i < g.width() + 1; i += step) {
        float ref = 0.0f;
        for (int dj = 0; dj < w; ++dj)
          for (int di = 0; di < w; ++di) ref = std::max(ref, g.value(i + di, j + dj));
        ASSERT_EQ(g.maxValue(h, i, j), ref) << "h " << h << " cell " << i << " " << j;
      }
  }
}

Points2 randomPoints(int n, double half_width, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-half_width, half_width);
  Points2 pts;
  for (int i = 0; i < n; ++i) pts.emplace_back(u(rng), u(rng));
  return pts;
}

TEST(CorrelativeGrid, MaxGridsEqualBruteForceWindowMax) {
  CorrelativeOptions o;
  o.depth = 5;
  o.connect_max_gap_m = 0.0;
  const auto g = CorrelativeGrid::fromPoints(randomPoints(60, 2.0, 5), o);
  ASSERT_EQ(g.depth(), 5);
  expectMaxGridsAreWindowMaxima(g, 3);
  // A grid narrower than the coarsest windows (a few cells, windows of 64).
  o.depth = 7;
  const auto narrow = CorrelativeGrid::fromPoints({Eigen::Vector2d(0.3, -0.2)}, o);
  ASSERT_LT(narrow.width(), 32);
  expectMaxGridsAreWindowMaxima(narrow, 1);
}

TEST(CorrelativeGrid, RebuiltInPlaceEqualsAFreshGrid) {
  CorrelativeOptions o;
  o.depth = 6;
  CorrelativeGrid g = CorrelativeGrid::fromPoints(randomPoints(80, 4.0, 1), o);
  // Smaller, then larger, then empty, then again: no value of an earlier build may survive.
  for (const Points2& pts :
       {randomPoints(30, 1.0, 2), randomPoints(200, 6.0, 3), Points2{}, randomPoints(50, 2.0, 4)}) {
    g.rebuild(pts, o);
    const auto fresh = CorrelativeGrid::fromPoints(pts, o);
    ASSERT_EQ(g.empty(), fresh.empty());
    ASSERT_EQ(g.width(), fresh.width());
    ASSERT_EQ(g.height(), fresh.height());
    ASSERT_EQ(g.depth(), fresh.depth());
    EXPECT_EQ(g.origin(), fresh.origin());
    for (int h = 0; h < fresh.depth(); ++h)
      for (int j = -(1 << h) - 1; j < fresh.height() + 1; ++j)
        for (int i = -(1 << h) - 1; i < fresh.width() + 1; ++i)
          ASSERT_EQ(g.maxValue(h, i, j), fresh.maxValue(h, i, j)) << "h " << h << " cell " << i << " " << j;
  }
}

TEST(CorrelativeGrid, SumOfMaxValuesIsTheSumWithOrWithoutTheBoundsTest) {
  // 40 cells: ten rounds of the four running sums, none left over; and 43 below.
  CorrelativeOptions o;
  o.depth = 4;
  const auto g = CorrelativeGrid::fromPoints(randomPoints(60, 2.0, 7), o);
  std::vector<Eigen::Vector2i> cells;
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> u(-6, 6);
  for (int k = 0; k < 40; ++k) cells.emplace_back(u(rng), u(rng));
  Eigen::Vector2i lo = cells[0], hi = cells[0];
  for (const auto& c : cells) {
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  int inside = 0, straddling = 0;
  // Shifts that keep every cell inside the max-grid, that put some outside, and all outside.
  for (int h = 0; h < g.depth(); ++h)
    for (int j = -20; j < g.height() + 20; j += 3)
      for (int i = -20; i < g.width() + 20; i += 3) {
        double ref = 0.0;
        for (const auto& c : cells) ref += g.maxValue(h, c.x() + i, c.y() + j);
        ASSERT_NEAR(g.sumMaxValues(h, cells, i, j, lo, hi), ref, 1e-12 * cells.size())
            << "h " << h << " shift " << i << " " << j;
        const bool in = lo.x() + i >= 0 && lo.y() + j >= 0 && hi.x() + i < g.width() && hi.y() + j < g.height();
        (in ? inside : straddling) += 1;
      }
  EXPECT_GT(inside, 10);
  EXPECT_GT(straddling, 10);
  EXPECT_EQ(g.sumMaxValues(0, {}, 0, 0, lo, hi), 0.0);
  cells.resize(43, cells.front());  // three left over after the rounds of four
  double ref = 0.0;
  for (const auto& c : cells) ref += g.maxValue(0, c.x() + g.width() / 2, c.y() + g.height() / 2);
  EXPECT_NEAR(g.sumMaxValues(0, cells, g.width() / 2, g.height() / 2, lo, hi), ref, 1e-12 * cells.size());
  EXPECT_GT(ref, 0.0);
}

TEST(Correlative, BranchAndBoundEqualsExhaustiveSearch) {
  const auto& sim = office();
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  CorrelativeOptions o;
  o.linear_window_m = 0.3;
  o.angular_window_rad = 6.0 * kDeg;
  o.min_score = 0.0;
  o.refine = false;
  for (int n = 0; n < 6; ++n) {
    const std::size_t k = 50 + static_cast<std::size_t>(n) * sim.route().size() / 7;
    const SE2 A = sim.route()[k].T_world_robot;
    const SE2 delta(0.25 * u(rng), 0.25 * u(rng), 5.0 * kDeg * u(rng));
    Points2 src = sim.scanAt(A * delta);
    Points2 sub;  // every 4th point keeps the exhaustive reference fast
    for (std::size_t i = 0; i < src.size(); i += 4) sub.push_back(src[i]);
    o.depth = 2 + n;  // also a depth deeper than the window
    const auto grid = CorrelativeGrid::fromPoints(sim.scanAt(A), o);
    const SE2 init(0.1 * u(rng), 0.1 * u(rng), 0.02 * u(rng));
    const auto bb = matchCorrelative(grid, sub, init, o);
    const auto ex = matchCorrelativeExhaustive(grid, sub, init, o);
    ASSERT_TRUE(bb.converged);
    ASSERT_TRUE(ex.converged);
    EXPECT_EQ(bb.score, ex.score) << "case " << n;
    EXPECT_LT(bb.candidates_scored, ex.candidates_scored);
  }
}

TEST(Correlative, RecoversWithinTheSearchResolutionThenExactly) {
  const auto& sim = office();
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int n = 0; n < 6; ++n) {
    const std::size_t k = 20 + static_cast<std::size_t>(n) * sim.route().size() / 6;
    const SE2 A = sim.route()[k].T_world_robot;
    // From 0.8 m and 25 degrees away.
    const double a = u(rng) * std::numbers::pi;
    const SE2 delta(0.8 * std::cos(a), 0.8 * std::sin(a), (n % 2 ? 25.0 : -25.0) * kDeg);
    const auto r = matchCorrelative(sim.scanAt(A), sim.scanAt(A * delta), SE2(), CorrelativeOptions{});
    ASSERT_TRUE(r.converged) << toString(r.status) << " " << r.message;
    EXPECT_TRUE(test::IsNearPose(delta, r.T_search, 0.05, 1.0)) << "route index " << k;
    EXPECT_TRUE(r.refined) << r.message;
    EXPECT_TRUE(test::IsNearPose(delta, r.T_target_source, 0.01, 0.2)) << "route index " << k;
    EXPECT_GT(r.score, 0.5);
    EXPECT_EQ(r.final_cost, r.score);
  }
}

TEST(Correlative, GlobalSearchFindsTheScanInAMap) {
  const auto& sim = office();
  mapping::MapOptions mo;
  mo.resolution_m = 0.1;
  auto map = mapping::makeMap(mapping::MapModel::kLogOdds, mo);
  for (std::size_t k = 0; k < sim.route().size(); k += 5) map->insert(sim.makeScan(sim.route()[k].T_world_robot), sim.route()[k].T_world_robot);
  const auto image = mapping::toOccupancyImage(*map);
  CorrelativeOptions o;
  o.resolution_m = 0.1;
  o.blur_sigma_m = 0.1;
  o.refinement.resolution_m = 0.1;
  o.refinement.truncation_m = 0.3;
  const auto grid = CorrelativeGrid::fromMap(image, o);
  const auto field = LikelihoodField::fromMap(image, o.refinement);
  for (std::size_t k : {100u, 900u}) {
    const SE2 truth = sim.route()[k].T_world_robot;
    const auto r = matchCorrelativeGlobal(grid, sim.scanAt(truth), o, &field);
    ASSERT_TRUE(r.converged) << r.message;
    // Within two search cells: the 10 cm map quantises the walls, and refinement against it is not
    // always accepted (then the search pose is returned).
    EXPECT_TRUE(test::IsNearPose(truth, r.T_target_source, 0.2, 1.5)) << "route index " << k << " " << r.message;
  }
}

TEST(Correlative, BadInputGivesAFiniteFailedResult) {
  const auto& sim = office();
  const auto target = sim.scanAt(sim.route()[10].T_world_robot);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  CorrelativeOptions o;
  auto r = matchCorrelative(target, Points2{}, SE2(0.1, 0.2, 0.3), o);
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.status, Status::kTooFewPoints);
  EXPECT_TRUE(r.T_target_source.isApprox(SE2(0.1, 0.2, 0.3)));
  r = matchCorrelative(Points2{}, target, SE2(), o);
  EXPECT_EQ(r.status, Status::kTooFewPoints);
  r = matchCorrelative(target, Points2(40, Eigen::Vector2d(nan, 1.0)), SE2(), o);
  EXPECT_EQ(r.status, Status::kTooFewPoints);
  r = matchCorrelative(target, target, SE2(0, nan, 0), o);
  EXPECT_EQ(r.status, Status::kInvalidInput);
  EXPECT_TRUE(r.T_target_source.isFinite());
  r = matchCorrelative(target, Points2(40, Eigen::Vector2d(300, 300)), SE2(), o);
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.status, Status::kTooFewInliers);
  EXPECT_TRUE(r.T_target_source.isFinite());

  auto expectField = [&](CorrelativeOptions bad, const std::string& field) {
    try {
      (void)matchCorrelative(target, target, SE2(), bad);
      ADD_FAILURE() << "no error for " << field;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
      EXPECT_EQ(e.where().field, field);
    }
  };
  CorrelativeOptions b;
  b.resolution_m = -1;
  expectField(b, "resolution_m");
  b = {};
  b.depth = 0;
  expectField(b, "depth");
  b = {};
  b.angular_window_rad = 4.0;
  expectField(b, "angular_window_rad");
  b = {};
  b.min_score = 2.0;
  expectField(b, "min_score");
  b = {};
  b.refinement.levels = 0;
  expectField(b, "levels");
}

}  // namespace
}  // namespace lidar2d::registration
