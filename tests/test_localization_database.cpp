// The localization database's compact index against brute-force references: the implicit k-d tree
// over quantized pair keys finds exactly the keys a linear scan finds; the line-pair lookup hits
// what an exhaustive comparison of unquantized keys hits (up to keys within the quantization step
// of the search radius); the range profiles of a build (leaping ray casts) equal per-cell ray casts
// from the same positions; a position with more lines than the index addresses is refused.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/geometry/ray_cast.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "src/localization/internal/database_index.hpp"
#include "src/localization/internal/pair_tree.hpp"

namespace lidar2d::localization {
namespace {

using internal::ImplicitPairTree;
using internal::Pair;
using internal::PairKeyScale;

TEST(ImplicitPairTree, RadiusSearchFindsWhatALinearScanFinds) {
  std::mt19937_64 rng(17);
  for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{16}, std::size_t{17}, std::size_t{33},
                              std::size_t{1000}, std::size_t{20000}}) {
    PairKeyScale scale;
    scale.unit[0] = scale.unit[1] = 30.0f / 65535.0f;
    scale.unit[2] = 12.0f / 65535.0f;
    std::vector<Pair> pairs(n);
    std::uniform_int_distribution<int> key(0, 65535), cluster(30000, 30400);
    for (std::size_t i = 0; i < n; ++i) {
      // Half spread over the key space, half in a tight cluster (many equal split values).
      for (int d = 0; d < 3; ++d) pairs[i].key[d] = static_cast<std::uint16_t>(i % 2 ? key(rng) : cluster(rng));
      pairs[i].ref = static_cast<std::uint32_t>(i);
    }
    ImplicitPairTree tree;
    tree.build(pairs, scale);
    std::vector<std::uint32_t> refs;
    for (const auto& p : pairs) refs.push_back(p.ref);
    std::sort(refs.begin(), refs.end());
    for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(refs[i], i);  // a permutation of the pairs
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (int q = 0; q < 200; ++q) {
      const float c = q % 2 ? 0.0f : 30200.0f;
      const float pt[3] = {q % 2 ? u(rng) * 30.0f : (c + 400.0f * u(rng)) * scale.unit[0],
                           q % 2 ? u(rng) * 30.0f : (c + 400.0f * u(rng)) * scale.unit[1],
                           q % 2 ? u(rng) * 12.0f : (c + 400.0f * u(rng)) * scale.unit[2]};
      const float r = q % 3 == 0 ? 0.3f : 2.0f * u(rng);
      std::vector<std::size_t> found, expected;
      tree.radiusSearch(pairs, scale, pt, r * r, [&](std::size_t i) { found.push_back(i); });
      for (std::size_t i = 0; i < n; ++i) {
        float d2 = 0.0f;
        for (int d = 0; d < 3; ++d) {
          const float e = static_cast<float>(pairs[i].key[d]) * scale.unit[d] - pt[d];
          d2 += e * e;
        }
        if (d2 < r * r) expected.push_back(i);
      }
      std::sort(found.begin(), found.end());
      ASSERT_EQ(found, expected) << "n " << n << " query " << q;
    }
  }
}

struct Office {
  std::vector<Frame> frames;
  OccupancyImage map;
};

const Office& office() {
  static const Office o = [] {
    Office s;
    const sim::Scenario sc = sim::builtinScenario("office");
    const auto truth = sim::samplePath(sc.waypoints, {}, 60);
    sim::SimulatorOptions so;
    so.laser.beams = 361;
    const auto clean = sim::simulate(sc.world, truth, so.noiseFree());
    auto m = mapping::makeMap(mapping::MapModel::kLogOdds, {});
    for (const Frame& f : clean) m->insert(f.scan, *f.T_world_robot * f.T_robot_laser);
    s.map = mapping::toOccupancyImage(*m);
    s.frames = sim::simulate(sc.world, truth, so);
    return s;
  }();
  return o;
}

DatabaseOptions smallDb() {
  DatabaseOptions o;
  o.step_m = 0.3;
  o.beams = 360;
  return o;
}

// voteLinePairs' hit count against every (position, line a < line b) pair of the database compared
// with every ordered pair of the scan's lines, keys in floating point (no quantization, no tree).
TEST(LocalizationDatabase, LookupHitsWhatAnExhaustiveComparisonHits) {
  const Office& s = office();
  const Database db = Database::build(s.map, smallDb());
  ASSERT_GT(db.numPairs(), 1000u);
  const LocalizerOptions lo;
  const DatabaseOptions& o = db.options();
  const double k = o.key_angle_scale_m_per_rad;
  const double min_sin_db = std::sin(o.min_pair_angle_rad);
  const double min_sin_q = std::sin(std::max(0.0, o.min_pair_angle_rad - lo.key_radius_m / k));
  auto wrap2pi = [](double a) { return internal::wrapTwoPi(a); };
  std::size_t checked = 0;
  for (std::size_t f = 3; f < s.frames.size(); f += 7) {
    auto lines = extractLines(s.frames[f].scan.toPoints(s.frames[f].T_robot_laser), lo.lines);
    if (lines.size() > lo.max_query_lines) lines.resize(lo.max_query_lines);
    std::size_t hits = 0;
    (void)voteLinePairs(db, lines, lo, 10, &hits);
    std::size_t expected = 0, borderline = 0;
    for (std::size_t i = 0; i < lines.size(); ++i)
      for (std::size_t j = 0; j < lines.size(); ++j) {
        if (i == j) continue;
        const double rel = wrap2pi(lines[j].normal_angle - lines[i].normal_angle);
        if (std::abs(std::sin(rel)) < min_sin_q) continue;
        for (const double shift : {0.0, -2 * std::numbers::pi, 2 * std::numbers::pi}) {
          const double ka = k * (rel + shift);
          if (shift != 0.0 && (ka < -lo.key_radius_m || ka > k * 2 * std::numbers::pi + lo.key_radius_m)) continue;
          for (const auto& p : db.positions())
            for (std::uint32_t a = 0; a < p.num_lines; ++a)
              for (std::uint32_t b = a + 1; b < p.num_lines; ++b) {
                const auto& la = db.lines()[p.first_line + a];
                const auto& lb = db.lines()[p.first_line + b];
                const double drel = wrap2pi(static_cast<double>(lb.normal_angle) - la.normal_angle);
                if (std::abs(std::sin(drel)) < min_sin_db) continue;
                const double e0 = la.distance - lines[i].distance, e1 = lb.distance - lines[j].distance,
                             e2 = k * drel - ka;
                const double d = std::sqrt(e0 * e0 + e1 * e1 + e2 * e2);
                expected += d < lo.key_radius_m;
                borderline += std::abs(d - lo.key_radius_m) < 2e-3;  // within the quantization
              }
        }
      }
    EXPECT_LE(std::abs(static_cast<double>(hits) - static_cast<double>(expected)), static_cast<double>(borderline))
        << "frame " << f;
    EXPECT_GT(expected, 0u);
    ++checked;
  }
  EXPECT_GE(checked, 5u);
}

// The build's range profiles against per-cell ray casts (geometry::castRay) from the stored
// positions: the leaping ray cast answers alike.
TEST(LocalizationDatabase, ProfilesEqualPerCellRayCasts) {
  const Office& s = office();
  const Database db = Database::build(s.map, smallDb());
  const DatabaseOptions& o = db.options();
  const auto B = static_cast<std::size_t>(o.profile_bins);
  ASSERT_EQ(db.profiles().size(), db.positions().size() * B);
  const double res = s.map.resolution();
  std::vector<std::uint8_t> obstacle(static_cast<std::size_t>(s.map.width()) * s.map.height());
  for (std::size_t i = 0; i < obstacle.size(); ++i) obstacle[i] = s.map.cells()[i] >= o.occupied_min;
  // The build's grid of positions (map frame), stepped as the build steps it: a stored position is
  // a float, and a ray from a cell corner goes down one column or the other by a rounding error.
  std::vector<Eigen::Vector2d> grid;
  for (double y = 0.5 * o.step_m; y < s.map.height() * res; y += o.step_m)
    for (double x = 0.5 * o.step_m; x < s.map.width() * res; x += o.step_m) grid.emplace_back(x, y);
  std::size_t compared = 0;
  for (std::size_t p = 0; p < db.positions().size(); p += 23) {
    const Eigen::Vector2d stored = s.map.origin().inverse() * Eigen::Vector2d(db.positions()[p].x, db.positions()[p].y);
    const auto it = std::min_element(grid.begin(), grid.end(), [&](const auto& a, const auto& b) {
      return (a - stored).squaredNorm() < (b - stored).squaredNorm();
    });
    ASSERT_LT((*it - stored).norm(), 1e-4);
    const Eigen::Vector2d start = *it / res;
    std::vector<double> profile(B, o.max_range_m);
    for (int b = 0; b < o.beams; ++b) {
      const double inc = 2.0 * std::numbers::pi / o.beams;  // as the build computes the beam angles
      const double a = -std::numbers::pi + b * inc;
      const double am = a - s.map.origin().theta();
      const double t = geometry::castRay(start, Eigen::Vector2d(std::cos(am), std::sin(am)), o.max_range_m / res,
                                         s.map.width(), s.map.height(), [&](std::int32_t x, std::int32_t y) {
                                           return obstacle[static_cast<std::size_t>(y) * s.map.width() + x] != 0;
                                         });
      if (!std::isfinite(t)) continue;
      double& v = profile[internal::sectorOf(a, B)];
      v = std::min(v, (t + 0.5) * res);
    }
    for (std::size_t k = 0; k < B; ++k) {
      // Stored in whole centimetres.
      ASSERT_NEAR(db.profiles()[p * B + k], profile[k], 0.005 + 1e-6) << "position " << p << " sector " << k;
      ++compared;
    }
  }
  EXPECT_GT(compared, 1000u);
}

TEST(LocalizationDatabase, PositionWithMoreLinesThanTheIndexAddressesIsRefused) {
  std::vector<Database::LineFeature> lines(65536, Database::LineFeature{0.5f, 1.0f, 1.0f});
  Database::Position p;
  p.num_lines = 65536;
  try {
    (void)Database::fromParts(DatabaseOptions{}, 0, {p}, lines);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_EQ(e.where().field, "positions");
    EXPECT_NE(std::string(e.what()).find("65535"), std::string::npos) << e.what();
  }
  p.num_lines = 3;
  EXPECT_NO_THROW((void)Database::fromParts(DatabaseOptions{}, 0, {p}, lines));
}

}  // namespace
}  // namespace lidar2d::localization
