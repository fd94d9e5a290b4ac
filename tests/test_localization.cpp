// Global localization: line extraction, rotation invariance of the descriptor, the database file
// (round trip, another map, another version, corruption), simulated worlds (office localizes,
// symmetric declines or lists every symmetric pose) and bad input.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/localization_db.hpp"
#include "lidar2d/localization/lines.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/localization/mirror_check.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

using localization::Database;
using localization::DatabaseOptions;
using localization::Localizer;
using localization::LocalizerOptions;
constexpr double kDeg = std::numbers::pi / 180.0;

bool near(const SE2& a, const SE2& b, double m = 0.3, double deg = 5.0) {
  const SE2 e = a.inverse() * b;
  return e.translation().norm() <= m && std::abs(e.theta()) <= deg * kDeg;
}

// Points along a polyline, one every `step` metres (scan order).
Points2 polyline(const std::vector<Eigen::Vector2d>& corners, double step) {
  Points2 pts;
  for (std::size_t k = 0; k + 1 < corners.size(); ++k) {
    const Eigen::Vector2d d = corners[k + 1] - corners[k];
    const int n = static_cast<int>(d.norm() / step);
    for (int i = 0; i < n; ++i) pts.push_back(corners[k] + d * (static_cast<double>(i) / n));
  }
  pts.push_back(corners.back());
  return pts;
}

TEST(LocalizationLines, LCornerGivesTwoLinesWithTheirHessianParameters) {
  // Wall x = 3 (normal 0 rad, d = 3) and wall y = 2 (normal pi/2, d = 2).
  const Points2 pts = polyline({{3.0, -2.0}, {3.0, 2.0}, {-1.0, 2.0}}, 0.05);
  const auto lines = localization::extractLines(pts);
  ASSERT_EQ(lines.size(), 2u);
  bool seen_x = false, seen_y = false;
  for (const auto& l : lines) {
    if (std::abs(angleDiff(l.normal_angle, 0.0)) < 0.01) {
      seen_x = true;
      EXPECT_NEAR(l.distance, 3.0, 1e-3);
      EXPECT_NEAR(l.length, 4.0, 0.1);
      EXPECT_TRUE(l.foot().isApprox(Eigen::Vector2d(3.0, 0.0), 1e-3));
    } else if (std::abs(angleDiff(l.normal_angle, std::numbers::pi / 2)) < 0.01) {
      seen_y = true;
      EXPECT_NEAR(l.distance, 2.0, 1e-3);
    }
  }
  EXPECT_TRUE(seen_x && seen_y);
}

TEST(LocalizationLines, DegenerateInputGivesNoLinesAndBadOptionsThrow) {
  EXPECT_TRUE(localization::extractLines({}).empty());
  EXPECT_TRUE(localization::extractLines(Points2(50, Eigen::Vector2d(1.0, 1.0))).empty());
  EXPECT_TRUE(localization::extractLines(Points2(20, Eigen::Vector2d(NAN, 1.0))).empty());
  localization::LineExtractionOptions bad;
  bad.split_threshold_m = 0.0;
  EXPECT_THROW(localization::extractLines({}, bad), Error);
}

TEST(LocalizationLines, DescriptorIsRotationInvariant) {
  // A room corner with a pillar-like clutter point cloud: rotating the scan frame by alpha adds
  // alpha to every normal angle and keeps every distance and every relative angle (the pair keys).
  const Points2 pts = polyline({{4.0, -3.0}, {4.0, 1.5}, {2.0, 3.0}, {-2.0, 3.0}}, 0.04);
  const auto ref = localization::extractLines(pts);
  ASSERT_GE(ref.size(), 3u);
  for (const double alpha : {0.3, 1.7, -2.5, 3.1}) {
    Points2 rotated;
    const SE2 R(0, 0, alpha);
    for (const auto& p : pts) rotated.push_back(R * p);
    const auto lines = localization::extractLines(rotated);
    ASSERT_EQ(lines.size(), ref.size());
    for (std::size_t i = 0; i < ref.size(); ++i) {
      EXPECT_NEAR(lines[i].distance, ref[i].distance, 1e-6);
      EXPECT_NEAR(angleDiff(lines[i].normal_angle, ref[i].normal_angle + alpha), 0.0, 1e-6);
      for (std::size_t j = 0; j < ref.size(); ++j)
        EXPECT_NEAR(angleDiff(lines[j].normal_angle - lines[i].normal_angle, ref[j].normal_angle - ref[i].normal_angle),
                    0.0, 1e-6);
    }
  }
}

// A world's map built from its route with noise-free scans (as `lidar2d map` would), and noisy
// query scans along the same route.
struct SimMap {
  sim::Scenario scenario;
  std::vector<Frame> frames;
  OccupancyImage map;
};

SimMap simMap(const std::string& world, std::size_t scans) {
  SimMap s;
  s.scenario = sim::builtinScenario(world);
  const auto truth = sim::samplePath(s.scenario.waypoints, {}, scans);
  sim::SimulatorOptions so;
  so.laser.beams = 361;
  const auto clean = sim::simulate(s.scenario.world, truth, so.noiseFree());
  auto m = mapping::makeMap(mapping::MapModel::kLogOdds, {});
  for (const Frame& f : clean) m->insert(f.scan, *f.T_world_robot * f.T_robot_laser);
  s.map = mapping::toOccupancyImage(*m);
  s.frames = sim::simulate(s.scenario.world, truth, so);
  return s;
}

DatabaseOptions fastDb() {
  DatabaseOptions o;
  o.step_m = 0.3;
  o.beams = 360;
  return o;
}

const SimMap& office() {
  static const SimMap s = simMap("office", 120);
  return s;
}

const SimMap& openWorld() {
  static const SimMap s = simMap("open", 120);
  return s;
}

const SimMap& corridorWorld() {
  static const SimMap s = simMap("corridor", 120);
  return s;
}

TEST(Localization, OfficeScansLocalizeCorrectly) {
  const SimMap& s = office();
  const Localizer loc(s.map, {}, fastDb());
  std::size_t answered = 0, correct = 0, n = 0;
  for (std::size_t i = 3; i < s.frames.size(); i += 10) {
    const Frame& f = s.frames[i];
    const auto r = loc.localize(f.scan, f.T_robot_laser);
    ++n;
    if (!r.declined) {
      ++answered;
      correct += near(*f.T_world_robot, r.T_world_robot);
      EXPECT_TRUE(near(*f.T_world_robot, r.T_world_robot))
          << "scan " << i << ": answer " << r.T_world_robot.x() << " " << r.T_world_robot.y() << " "
          << r.T_world_robot.theta() << " truth " << f.T_world_robot->x() << " " << f.T_world_robot->y() << " "
          << f.T_world_robot->theta() << " score " << r.score;
      EXPECT_GE(r.score, loc.options().min_score);
    }
  }
  EXPECT_GE(correct, n * 8 / 10) << "answered " << answered << " of " << n;
}

// A query on two threads (profiles beside the line votes, the first scoring split) answers exactly
// as on one: the same poses, scores and candidates, bit for bit.
TEST(Localization, TwoThreadsAnswerAsOne) {
  const SimMap& s = office();
  // Also with every query searching its candidate regions (no answer is confident enough to skip
  // them): the regions and the refinements run on the query's threads.
  for (const double confident : {LocalizerOptions{}.confident_score, 1.0}) {
    LocalizerOptions one;
    one.threads = 1;
    one.confident_score = confident;
    LocalizerOptions two = one;
    two.threads = 2;
    const Localizer a(s.map, one, fastDb());
    const Localizer b(s.map, two, fastDb());
    std::size_t with_regions = 0;
    for (std::size_t i = 1; i < s.frames.size(); i += 7) {
      const Frame& f = s.frames[i];
      const auto ra = a.localize(f.scan, f.T_robot_laser);
      const auto rb = b.localize(f.scan, f.T_robot_laser);
      EXPECT_EQ(ra.declined, rb.declined) << "scan " << i;
      EXPECT_EQ(ra.reason, rb.reason) << "scan " << i;
      EXPECT_EQ(ra.score, rb.score) << "scan " << i;
      EXPECT_EQ(ra.num_candidates, rb.num_candidates) << "scan " << i;
      EXPECT_EQ(ra.num_profile_candidates, rb.num_profile_candidates) << "scan " << i;
      EXPECT_EQ(ra.num_regions, rb.num_regions) << "scan " << i;
      with_regions += ra.num_regions > 0;
      ASSERT_EQ(ra.candidates.size(), rb.candidates.size()) << "scan " << i;
      for (std::size_t c = 0; c < ra.candidates.size(); ++c) {
        EXPECT_EQ(ra.candidates[c].T_world_robot.x(), rb.candidates[c].T_world_robot.x()) << "scan " << i;
        EXPECT_EQ(ra.candidates[c].T_world_robot.y(), rb.candidates[c].T_world_robot.y()) << "scan " << i;
        EXPECT_EQ(ra.candidates[c].T_world_robot.theta(), rb.candidates[c].T_world_robot.theta()) << "scan " << i;
        EXPECT_EQ(ra.candidates[c].fit, rb.candidates[c].fit) << "scan " << i;
      }
      if (!ra.declined) {
        EXPECT_EQ(ra.T_world_robot.x(), rb.T_world_robot.x()) << "scan " << i;
        EXPECT_EQ(ra.T_world_robot.theta(), rb.T_world_robot.theta()) << "scan " << i;
      }
    }
    if (confident == 1.0) {
      EXPECT_GT(with_regions, 0u);
    }
  }
  LocalizerOptions bad;
  bad.threads = 0;
  EXPECT_TRUE(test::throwsError([&] { Localizer l(s.map, bad, fastDb()); }, ErrorKind::kInvalidArgument, {"threads"}));
}

TEST(Localization, RangeProfilesLocalizeScansWithoutLines) {
  // Scans whose lines give no pair (corridors, curved or cluttered walls) are the range profile's
  // job. Here the query extracts no line at all, so only the profile can find the pose; without it
  // every scan is declined.
  const SimMap& s = office();
  LocalizerOptions profile_only;
  profile_only.lines.min_length_m = 1000.0;  // no line is that long
  profile_only.max_regions = 0;  // the descriptor stages only: no branch and bound
  profile_only.budget_ms = 0;
  LocalizerOptions neither = profile_only;
  neither.profile_candidates = 0;
  const Localizer loc(s.map, profile_only, fastDb());
  const Localizer none(s.map, neither, fastDb());
  std::size_t n = 0, correct = 0;
  for (std::size_t i = 3; i < s.frames.size(); i += 10) {
    const Frame& f = s.frames[i];
    const auto r = loc.localize(f.scan, f.T_robot_laser);
    ++n;
    EXPECT_EQ(r.num_lines, 0u);
    EXPECT_EQ(r.num_profile_candidates, loc.options().profile_candidates);
    if (!r.declined) {
      correct += near(*f.T_world_robot, r.T_world_robot);
      EXPECT_TRUE(near(*f.T_world_robot, r.T_world_robot))
          << "scan " << i << ": answer " << r.T_world_robot.x() << " " << r.T_world_robot.y() << " "
          << r.T_world_robot.theta() << " truth " << f.T_world_robot->x() << " " << f.T_world_robot->y() << " "
          << f.T_world_robot->theta() << " score " << r.score;
    }
    const auto r0 = none.localize(f.scan, f.T_robot_laser);
    EXPECT_TRUE(r0.declined);
    EXPECT_EQ(r0.reason, "no lines");
  }
  EXPECT_GE(correct, n * 8 / 10) << "correct " << correct << " of " << n;
}

TEST(Localization, WholeMapSearchFindsWhatTheDescriptorsMiss) {
  // The cascade's last resort: with neither lines nor range profiles the descriptors propose
  // nothing, and the branch and bound over the whole map (run to its end here, so no timing is
  // involved) finds the pose; without it every scan is declined.
  const SimMap& s = office();
  LocalizerOptions blind;
  blind.lines.min_length_m = 1000.0;
  blind.profile_candidates = 0;
  blind.max_regions = 0;
  blind.budget_ms = 0;
  LocalizerOptions searching = blind;
  searching.fallback_branch_and_bound = true;
  const Localizer none(s.map, blind, fastDb());
  const Localizer loc(s.map, searching, fastDb());
  std::size_t n = 0, correct = 0;
  for (std::size_t i = 3; i < s.frames.size(); i += 20) {
    const Frame& f = s.frames[i];
    const auto r = loc.localize(f.scan, f.T_robot_laser);
    ++n;
    EXPECT_TRUE(r.used_fallback);
    EXPECT_TRUE(r.fallback_complete);
    if (!r.declined) {
      correct += near(*f.T_world_robot, r.T_world_robot);
      EXPECT_TRUE(near(*f.T_world_robot, r.T_world_robot)) << "scan " << i << " score " << r.score;
    }
    const auto r0 = none.localize(f.scan, f.T_robot_laser);
    EXPECT_TRUE(r0.declined);
    EXPECT_FALSE(r0.used_fallback);
  }
  EXPECT_GE(correct, n * 8 / 10) << "correct " << correct << " of " << n;
}

TEST(Localization, RegionSearchRecoversScansTheVerifiedCandidatesMiss) {
  // Stage D: the candidates' regions searched over every heading. With only the range profiles'
  // few best positions (their whole-sector turn and grid position off the truth) and no
  // whole-map search, the regions must at least keep what the descriptors alone answer.
  const SimMap& s = office();
  LocalizerOptions base;
  base.lines.min_length_m = 1000.0;
  base.profile_candidates = 4;
  base.budget_ms = 0;
  base.confident_score = 1.0;  // always search the regions
  LocalizerOptions no_regions = base;
  no_regions.max_regions = 0;
  const Localizer with(s.map, base, fastDb());
  const Localizer without(s.map, no_regions, fastDb());
  std::size_t n = 0, correct_with = 0, correct_without = 0;
  for (std::size_t i = 3; i < s.frames.size(); i += 10) {
    const Frame& f = s.frames[i];
    const auto a = with.localize(f.scan, f.T_robot_laser);
    const auto b = without.localize(f.scan, f.T_robot_laser);
    ++n;
    EXPECT_GT(a.num_regions, 0u);
    EXPECT_EQ(b.num_regions, 0u);
    correct_with += !a.declined && near(*f.T_world_robot, a.T_world_robot);
    correct_without += !b.declined && near(*f.T_world_robot, b.T_world_robot);
    if (!a.declined) {
      EXPECT_TRUE(near(*f.T_world_robot, a.T_world_robot)) << "scan " << i << " score " << a.score;
    }
  }
  EXPECT_GE(correct_with, correct_without);
  EXPECT_GE(correct_with, n * 8 / 10) << "correct " << correct_with << " of " << n;
}

TEST(Localization, ScanWithFewerThanTenBeamsIsUnknown) {
  const SimMap& s = office();
  const Localizer loc(s.map, {}, fastDb());
  const Frame& f = s.frames[3];
  Points2 pts = f.scan.toPoints(f.T_robot_laser);
  pts.resize(9);
  const auto r = loc.localize(pts);
  EXPECT_TRUE(r.declined);
  EXPECT_EQ(r.reason, "no points");
}

// The map's mirror image: its rows in reverse order (a map image read with its rows the wrong way up).
OccupancyImage mirroredRows(const OccupancyImage& m) {
  const auto w = static_cast<std::size_t>(m.width()), h = static_cast<std::size_t>(m.height());
  std::vector<std::int8_t> cells(m.cells().size());
  for (std::size_t row = 0; row < h; ++row)
    std::copy_n(m.cells().begin() + static_cast<std::ptrdiff_t>((h - 1 - row) * w), w,
                cells.begin() + static_cast<std::ptrdiff_t>(row * w));
  return OccupancyImage::create(m.width(), m.height(), m.resolution(), m.origin(), std::move(cells));
}

// Scans in the mirror image of their map are not placed, but their mirror images are: the check
// says so. Scans of another building are not placed either way: it does not.
TEST(LocalizationMirror, ScansInTheMirroredMapAreToldFromScansOfAnotherPlace) {
  const SimMap& s = openWorld();
  const Localizer mirrored_map(mirroredRows(s.map), {}, fastDb());
  localization::MirrorCheck in_mirror;
  std::size_t n = 0, placed = 0;
  for (std::size_t i = 3; i < s.frames.size(); i += 6, ++n) {
    const Frame& f = s.frames[i];
    if (mirrored_map.localize(f.scan, f.T_robot_laser).declined)
      in_mirror.add(f.scan, f.T_robot_laser);
    else
      ++placed;
  }
  EXPECT_LE(placed, n / 5) << "of " << n << " scans in the mirrored map";
  const localization::MirrorCheckResult r = in_mirror.run(mirrored_map);
  EXPECT_EQ(r.tried, 12u);
  EXPECT_TRUE(r.mirrored()) << r.placed << " of " << r.tried << " mirror images placed";
  // The check runs on a log of which fewer than a fifth of the scans were placed, and only then.
  const auto few_placed = in_mirror.runIfFewPlaced(mirrored_map, n);
  ASSERT_TRUE(few_placed.has_value());
  EXPECT_EQ(few_placed->placed, r.placed);
  EXPECT_FALSE(in_mirror.runIfFewPlaced(mirrored_map, 5 * in_mirror.added()).has_value()) << "80% placed";

  // The corridor world's scans in the open world's map (upright): few mirror images placed.
  const SimMap& other = corridorWorld();
  const Localizer upright_map(s.map, {}, fastDb());
  localization::MirrorCheck elsewhere;
  for (std::size_t i = 3; i < other.frames.size(); i += 6) {
    const Frame& f = other.frames[i];
    if (upright_map.localize(f.scan, f.T_robot_laser).declined) elsewhere.add(f.scan, f.T_robot_laser);
  }
  const localization::MirrorCheckResult e = elsewhere.run(upright_map);
  EXPECT_GE(e.tried, localization::MirrorCheckResult::kMinTried);
  EXPECT_FALSE(e.mirrored()) << e.placed << " of " << e.tried << " mirror images placed";
}

// The sample spans the whole log, whatever its length: half the scans from the mirrored map, then
// half from elsewhere, give about half the sample placed mirrored; and at most twice the sample
// size is kept.
TEST(LocalizationMirror, TheSampleSpansTheWholeLog) {
  const SimMap& s = openWorld();
  const SimMap& other = corridorWorld();
  const Localizer mirrored_map(mirroredRows(s.map), {}, fastDb());
  localization::MirrorCheck check(8);
  for (std::size_t i = 0; i < 100; ++i) check.add(s.frames[i].scan, s.frames[i].T_robot_laser);
  for (std::size_t i = 0; i < 100; ++i) check.add(other.frames[i].scan, other.frames[i].T_robot_laser);
  EXPECT_EQ(check.added(), 200u);
  const localization::MirrorCheckResult r = check.run(mirrored_map);
  EXPECT_EQ(r.tried, 8u);
  EXPECT_GE(r.placed, 2u);
  EXPECT_LE(r.placed, 6u);
  EXPECT_THROW(localization::MirrorCheck(0), Error);
}

TEST(LocalizationDatabase, CoverageIsTheShareOfFreeSpaceIndexed) {
  // A 3 m square room: positions everywhere but near its walls. The same room with a 0.3 m wide
  // free strip 10 m long (narrower than twice the clearance, so never indexed) covers less.
  auto room = OccupancyImage::filled(80, 80, 0.05, SE2(), OccupancyImage::kOccupied);
  for (int y = 10; y < 70; ++y)
    for (int x = 10; x < 70; ++x) room.set(x, y, OccupancyImage::kFree);
  auto with_strip = OccupancyImage::filled(80, 260, 0.05, SE2(), OccupancyImage::kOccupied);
  for (int y = 10; y < 70; ++y)
    for (int x = 10; x < 70; ++x) with_strip.set(x, y, OccupancyImage::kFree);
  for (int y = 70; y < 250; ++y)
    for (int x = 37; x < 43; ++x) with_strip.set(x, y, OccupancyImage::kFree);
  const Database a = Database::build(room, fastDb());
  const Database b = Database::build(with_strip, fastDb());
  EXPECT_GT(a.coverage(), 0.5);
  EXPECT_LE(a.coverage(), 1.0);
  EXPECT_LT(b.coverage(), a.coverage() * 0.8);
  EXPECT_TRUE(std::isnan(Database::fromParts(fastDb(), 0, {}, {}).coverage()));
}

TEST(LocalizationDatabase, MapCoarserThanTwentyCentimetresIsRefused) {
  const auto coarse = OccupancyImage::filled(40, 40, 0.25, SE2(), OccupancyImage::kFree);
  EXPECT_TRUE(test::throwsError([&] { (void)Database::build(coarse, fastDb()); }, ErrorKind::kBadInput,
                                {"0.25 m", "coarser than 0.2 m"}));
  const auto fine_enough = OccupancyImage::filled(40, 40, 0.2, SE2(), OccupancyImage::kFree);
  EXPECT_NO_THROW((void)Database::build(fine_enough, fastDb()));
}

TEST(LocalizationDatabase, ProfilesOfTheWrongSizeAreRefused) {
  DatabaseOptions o;
  o.profile_bins = 8;
  std::vector<Database::Position> pos(2);
  const std::vector<float> seven(7, 1.0f), sixteen(16, 1.0f);
  EXPECT_NO_THROW((void)Database::fromParts(o, 0, pos, {}, sixteen));
  EXPECT_NO_THROW((void)Database::fromParts(o, 0, pos, {}, {}));  // no profiles at all
  for (const auto& bad : {seven, std::vector<float>(16, -1.0f), std::vector<float>(16, NAN)}) {
    try {
      (void)Database::fromParts(o, 0, pos, {}, bad);
      FAIL() << "no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
      EXPECT_EQ(e.where().field, "profiles");
    }
  }
  o.profile_bins = 5;
  EXPECT_THROW(o.validate(), Error);
}

TEST(Localization, SymmetricWorldDeclinesOrListsEverySymmetricPose) {
  const SimMap s = simMap("symmetric", 400);
  const Localizer loc(s.map, {}, fastDb());
  std::size_t declined = 0, n = 0;
  for (std::size_t i = 5; i < s.frames.size(); i += 50) {
    const Frame& f = s.frames[i];
    const auto r = loc.localize(f.scan, f.T_robot_laser);
    ++n;
    declined += r.declined;
    std::vector<SE2> listed{r.T_world_robot};
    for (const auto& a : r.alternatives) listed.push_back(a.T_world_robot);
    int found = 0;
    for (int q = 0; q < 4; ++q) {
      const SE2 sym = SE2(0, 0, q * std::numbers::pi / 2) * *f.T_world_robot;
      found += std::any_of(listed.begin(), listed.end(), [&](const SE2& p) { return near(sym, p); });
    }
    // Never a confident answer naming one room: either "unknown", or every symmetric pose listed.
    EXPECT_TRUE(r.declined || found == 4)
        << "scan " << i << " answered with " << found << " of 4 symmetric poses; score " << r.score << " alternative "
        << (r.alternatives.empty() ? 0.0 : r.alternatives[0].score);
    if (r.declined && r.reason == std::string("ambiguous")) {
      EXPECT_GE(found, 2) << "scan " << i;
    }
  }
  EXPECT_GE(declined, n * 3 / 4);
}

// The free-space check skips the samples of a beam that the map's clearance shows to lie in open
// space: the count of beams through walls must be the one of reading every sample. Random thin
// walls (one cell, with gaps) across unknown space, at three resolutions (the 2 cm map samples
// every 2.5 cells); points on the walls (each explained: +1, and -1 when its beam crossed another
// wall first) and in unknown space away from them (0, or -1 through a wall). The expected score
// walks every sample of every beam.
TEST(Localization, TheFreeSpaceCheckSeesEveryWallABeamCrosses) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (const double res : {0.02, 0.05, 0.1}) {
    const int n = static_cast<int>(std::lround(16.0 / res));
    auto map = OccupancyImage::filled(n, n, res, SE2(), OccupancyImage::kUnknown);
    auto cellOf = [&](const Eigen::Vector2d& p) {
      return Eigen::Vector2i(static_cast<int>(std::floor(p.x() / res)), static_cast<int>(std::floor(p.y() / res)));
    };
    // A free 3 m room in a corner, so that the database has positions.
    for (int r = 0; r < n; ++r)
      for (int c = 0; c < n; ++c) {
        const Eigen::Vector2d q((c + 0.5) * res, (r + 0.5) * res);
        if (q.x() < 3.0 && q.y() < 3.0)
          map.set(c, r, q.x() < 0.1 || q.y() < 0.1 || q.x() > 2.9 || q.y() > 2.9 ? 100 : 0);
      }
    std::vector<Eigen::Vector2d> on_walls;
    for (int w = 0; w < 40; ++w) {
      const Eigen::Vector2d a(4.0 + 11.0 * u(rng), 4.0 + 11.0 * u(rng)),
          b = a + Eigen::Vector2d(4.0 * u(rng) - 2.0, 4.0 * u(rng) - 2.0);
      const int steps = static_cast<int>((b - a).norm() / (0.25 * res));
      for (int k = 0; k <= steps; ++k) {
        const double f = static_cast<double>(k) / std::max(1, steps);
        if (std::fmod(f * 10.0, 1.0) > 0.8) continue;  // gaps
        const Eigen::Vector2i c = cellOf(a + f * (b - a));
        if (map.contains(c.x(), c.y())) map.set(c.x(), c.y(), 100);
      }
    }
    for (int r = 0; r < n; ++r)
      for (int c = 0; c < n; ++c)
        if (map.at(c, r) == 100 && (c + 0.5) * res > 3.5) on_walls.push_back({(c + 0.5) * res, (r + 0.5) * res});
    const Localizer loc(map, {}, fastDb());
    auto nearWall = [&](const Eigen::Vector2d& p) {
      const Eigen::Vector2i c = cellOf(p);
      const int k = static_cast<int>(std::ceil(0.5 / res));
      for (int dy = -k; dy <= k; ++dy)
        for (int dx = -k; dx <= k; ++dx)
          if (map.contains(c.x() + dx, c.y() + dy) && map.at(c.x() + dx, c.y() + dy) == 100) return true;
      return false;
    };
    for (int trial = 0; trial < 20; ++trial) {
      const SE2 T_world_robot(3.5 + 12.0 * u(rng), 3.5 + 12.0 * u(rng), 2.0 * std::numbers::pi * u(rng));
      Points2 pts;
      int explained = 0, through = 0;
      for (int i = 0; i < 120; ++i) {
        Eigen::Vector2d w;
        bool on_wall = i % 2 == 0;
        if (on_wall) {
          w = on_walls[rng() % on_walls.size()];
        } else {
          do w = Eigen::Vector2d(3.5 + 12.0 * u(rng), 3.5 + 12.0 * u(rng));
          while (nearWall(w));
        }
        pts.push_back(T_world_robot.inverse() * w);
        // The reference: every sample, one cell (or 5 cm) apart, up to 0.3 m before the point.
        const Eigen::Vector2d o = T_world_robot.translation() / res, e = w / res;
        const double len = (e - o).norm() - 0.3 / res;
        const Eigen::Vector2d dir = (e - o).normalized();
        const double step = std::max(1.0, 0.05 / res);
        bool crossed = false;
        for (double t = 0.5; t < len && !crossed; t += step) {
          const Eigen::Vector2i c = cellOf((o + t * dir) * res);
          crossed = map.contains(c.x(), c.y()) && map.at(c.x(), c.y()) >= 65;
        }
        explained += on_wall;
        through += crossed;
      }
      ASSERT_GT(through, 0) << "res " << res << " trial " << trial;  // the walls are in the way
      const double expected = std::clamp(static_cast<double>(explained - through) / 120.0, 0.0, 1.0);
      EXPECT_NEAR(loc.score(pts, T_world_robot), expected, 1e-12) << "res " << res << " trial " << trial;
    }
  }
}

TEST(Localization, PointsInKnownFreeSpaceCountAgainstAPoseAndUnknownSpaceDoesNot) {
  // A 10 m square room walled on its border; its left half seen free, its right half unknown. The
  // robot stands in the left half. Two scans explain the same 50 points on the left wall and leave
  // 10 unexplained: in known free space 1 m in front of the robot (something the map saw through),
  // or in the unknown half (nothing the map contradicts). Only the first costs score and fit.
  auto map = OccupancyImage::filled(200, 200, 0.05, SE2(), OccupancyImage::kUnknown);
  for (int r = 0; r < 200; ++r)
    for (int c = 0; c < 200; ++c) {
      if (r == 0 || c == 0 || r == 199 || c == 199)
        map.set(c, r, OccupancyImage::kOccupied);
      else if (c < 100)
        map.set(c, r, OccupancyImage::kFree);
    }
  const Localizer loc(map, {}, fastDb());
  const SE2 T_world_robot(2.5, 5.0, 0.0);
  Points2 wall;
  for (int i = 0; i < 50; ++i) wall.push_back(T_world_robot.inverse() * Eigen::Vector2d(0.025, 3.0 + 0.08 * i));
  Points2 in_free = wall, in_unknown = wall;
  for (int i = 0; i < 10; ++i) {
    in_free.push_back(T_world_robot.inverse() * Eigen::Vector2d(1.5, 4.6 + 0.08 * i));
    in_unknown.push_back(T_world_robot.inverse() * Eigen::Vector2d(7.5, 4.6 + 0.08 * i));
  }
  const double unknown_score = loc.score(in_unknown, T_world_robot);
  EXPECT_NEAR(unknown_score, 50.0 / 60.0, 1e-9);
  EXPECT_NEAR(loc.score(wall, T_world_robot), 1.0, 1e-9);
  EXPECT_LT(loc.score(in_free, T_world_robot), unknown_score - 0.05);
}

// Ten identical closed square rooms in a row; the first also holds a pillar 0.3 m wide. A 180-beam
// scan from the first room sees the pillar: every look-alike pose (the other rooms, and each room
// turned half a circle about its centre) explains 6% less of it than the true pose (fit 0.92
// against 0.98), so the single-alternative ratio test (0.95) answers, but the 24 of them together
// are more likely than the true pose (odds 24 x exp(-0.12 x 180 x 0.06) = 6): one scan cannot tell
// the rooms apart with confidence. A pillar 0.7 m wide (each look-alike 16% worse) tells them apart.
// Ten identical 4 m rooms in a row, a pillar of `pillar_radius_m` in the first. The map: walls and
// pillar occupied, the rooms' insides free, the rest unknown (5 cm cells); and a noise-free scan of
// 180 beams over 360 degrees from the first room, at `kTenRoomsTruth`.
const SE2 kTenRoomsTruth(1.0 + 1.5, 1.0 + 2.0, 0.3);
std::pair<OccupancyImage, Frame> tenRooms(double pillar_radius_m) {
  constexpr int kRooms = 10;
  constexpr double kSide = 4.0, kPitch = 5.0;
  std::vector<sim::Segment> walls;
  for (int k = 0; k < kRooms; ++k) {
    const double x0 = 1.0 + k * kPitch, y0 = 1.0;
    const Eigen::Vector2d c[4] = {{x0, y0}, {x0 + kSide, y0}, {x0 + kSide, y0 + kSide}, {x0, y0 + kSide}};
    for (int i = 0; i < 4; ++i) walls.push_back({c[i], c[(i + 1) % 4]});
  }
  const Eigen::Vector2d pillar(1.0 + 3.0, 1.0 + 2.0);
  const sim::World world(walls, {sim::Arc::circle(pillar, pillar_radius_m)});
  const double res = 0.05;
  auto map = OccupancyImage::filled(1060, 120, res, SE2(), OccupancyImage::kUnknown);
  for (int r = 0; r < 120; ++r)
    for (int col = 0; col < 1060; ++col) {
      const Eigen::Vector2d p((col + 0.5) * res, (r + 0.5) * res);
      const double u = std::fmod(p.x() - 1.0, kPitch), v = p.y() - 1.0;
      if (p.x() < 1.0 - res || p.x() > 1.0 + (kRooms - 1) * kPitch + kSide + res || v < -res || v > kSide + res ||
          u > kSide + res)
        continue;
      const bool wall = u < res || u > kSide - res || v < res || v > kSide - res;
      const bool in_pillar = (p - pillar).norm() < pillar_radius_m + 0.5 * res;
      map.set(col, r, wall || in_pillar ? OccupancyImage::kOccupied : OccupancyImage::kFree);
    }
  sim::SimulatorOptions so;
  so.laser.beams = 180;
  so.laser.fov_rad = 2.0 * std::numbers::pi;
  auto frames = sim::simulate(world, {{0.0, kTenRoomsTruth}}, so.noiseFree());
  return {std::move(map), std::move(frames[0])};
}

DatabaseOptions tenRoomsDb() {
  DatabaseOptions db = fastDb();
  db.step_m = 0.25;
  return db;
}

TEST(Localization, ManyLookAlikesEachALittleWorseTogetherDecline) {
  auto answer = [](double pillar_radius_m, double nats) {
    const auto [map, frame] = tenRooms(pillar_radius_m);
    LocalizerOptions o;
    o.ambiguity_nats_per_point = nats;
    const Localizer loc(map, o, tenRoomsDb());
    const auto r = loc.localize(frame.scan, frame.T_robot_laser);
    std::size_t near_truth = 0;
    for (const auto& c : r.candidates) near_truth += near(c.T_world_robot, kTenRoomsTruth);
    EXPECT_EQ(near_truth, 1u) << "the first room is a candidate";
    return r;
  };
  const auto ratio_only = answer(0.15, 0.0);
  ASSERT_FALSE(ratio_only.declined) << ratio_only.reason;
  EXPECT_TRUE(near(ratio_only.T_world_robot, SE2(2.5, 3.0, 0.3)));
  ASSERT_GE(ratio_only.alternatives.size(), 5u);
  EXPECT_LT(ratio_only.alternatives.front().fit, 0.95 * ratio_only.candidates.front().fit);
  const auto together = answer(0.15, LocalizerOptions{}.ambiguity_nats_per_point);
  EXPECT_TRUE(together.declined);
  EXPECT_EQ(together.reason, "ambiguous");
  const auto wide = answer(0.35, LocalizerOptions{}.ambiguity_nats_per_point);
  EXPECT_FALSE(wide.declined) << wide.reason;
  EXPECT_TRUE(near(wide.T_world_robot, SE2(2.5, 3.0, 0.3)));
  for (const double bad : {-0.1, std::numeric_limits<double>::infinity()}) {
    LocalizerOptions o;
    o.ambiguity_nats_per_point = bad;
    EXPECT_TRUE(test::throwsError([&] { o.validate(); }, ErrorKind::kInvalidArgument, {"ambiguity_nats_per_point"}));
  }
}

// Rivals scoring under min_score still count against the best: the ten rooms' scan with a share of
// its beams ending 0.6 m away (an object the map lacks, in free space in every room) fits one room
// just over min_score and the others just under it. None of those may be answered (no alternative),
// but together they are as likely as the best: "ambiguous". Without the look-alikes' odds the best
// is answered, and here it is not even the pillar's room (40-44% of the beams cluttered: the
// pillar's few points weigh less than where the clutter falls).
TEST(Localization, RivalsUnderTheMinimumScoreCountAgainstTheBest) {
  const auto [map, frame] = tenRooms(0.15);
  const Localizer loc(map, {}, tenRoomsDb());
  LocalizerOptions ratio_only;
  ratio_only.ambiguity_nats_per_point = 0.0;
  const Localizer loc_ratio_only(map, ratio_only, tenRoomsDb());
  std::size_t cases = 0, declined = 0;
  for (int percent = 10; percent <= 45; ++percent) {
    LaserScanFields fs = frame.scan.fields();
    for (std::size_t i = 0; i < fs.ranges.size() * static_cast<std::size_t>(percent) / 100; ++i) fs.ranges[i] = 0.6;
    const LaserScan cluttered = LaserScan::create(fs);
    const auto r0 = loc_ratio_only.localize(cluttered, frame.T_robot_laser);
    if (r0.declined || r0.candidates.size() < 2) continue;
    bool rivals_under = true;
    for (std::size_t c = 1; c < r0.candidates.size(); ++c) rivals_under = rivals_under && r0.candidates[c].score < 0.5;
    if (!rivals_under) continue;
    ++cases;
    EXPECT_TRUE(r0.alternatives.empty()) << percent << "%";
    const LocalizerOptions o;
    const double nats = r0.score >= o.confident_score ? o.ambiguity_nats_per_point : o.unconfident_nats_per_point;
    double odds = 0.0;
    for (std::size_t c = 1; c < r0.candidates.size(); ++c)
      odds += std::exp(-nats * static_cast<double>(r0.num_points) * (r0.candidates[0].fit - r0.candidates[c].fit));
    const auto r = loc.localize(cluttered, frame.T_robot_laser);
    EXPECT_EQ(r.declined, odds >= 1.0) << percent << "%: odds " << odds;
    if (r.declined) {
      EXPECT_EQ(r.reason, "ambiguous");
      ++declined;
    }
  }
  EXPECT_GE(cases, 1u) << "no share of cluttered beams leaves the best over min_score and every rival under it";
  EXPECT_EQ(declined, cases);
}

// A best pose under confident_score must stand further above its rivals: the ten rooms with a wide
// pillar, and part of the scan cluttered (0.6 m returns the map lacks). Answers scoring under 0.8
// that the confident weight (0.12 nats per point) keeps, the unconfident one (0.08) declines as
// ambiguous; answers scoring 0.8 or more are decided alike by both.
TEST(Localization, AnUnconfidentAnswerMustStandFurtherAboveItsRivals) {
  const auto [map, frame] = tenRooms(0.35);
  const Localizer loc(map, {}, tenRoomsDb());
  LocalizerOptions same;
  same.unconfident_nats_per_point = same.ambiguity_nats_per_point;
  const Localizer loc_same(map, same, tenRoomsDb());
  std::size_t confident = 0, unconfident_declined = 0;
  for (int percent = 0; percent <= 30; percent += 2) {
    LaserScanFields fs = frame.scan.fields();
    for (std::size_t i = 0; i < fs.ranges.size() * static_cast<std::size_t>(percent) / 100; ++i) fs.ranges[i] = 0.6;
    const LaserScan cluttered = LaserScan::create(fs);
    const auto r = loc.localize(cluttered, frame.T_robot_laser);
    const auto r_same = loc_same.localize(cluttered, frame.T_robot_laser);
    if (r_same.declined) continue;
    if (r_same.score >= LocalizerOptions{}.confident_score) {
      ++confident;
      EXPECT_FALSE(r.declined) << percent << "%: " << r.reason;
    } else if (r.declined) {
      EXPECT_EQ(r.reason, "ambiguous") << percent << "%";
      ++unconfident_declined;
    }
  }
  EXPECT_GE(confident, 1u);
  EXPECT_GE(unconfident_declined, 1u);
  LocalizerOptions bad;
  bad.unconfident_nats_per_point = -1.0;
  EXPECT_TRUE(test::throwsError([&] { bad.validate(); }, ErrorKind::kInvalidArgument, {"unconfident_nats_per_point"}));
}

TEST(Localization, ScanWithNoValidBeamsIsUnknown) {
  const SimMap& s = office();
  const Localizer loc(s.map, {}, fastDb());
  LaserScanFields f;
  f.angle_min = -1.5;
  f.angle_increment = 0.01;
  f.range_max = 30.0;
  f.ranges.assign(300, std::numeric_limits<double>::quiet_NaN());
  const auto r = loc.localize(LaserScan::create(f));
  EXPECT_TRUE(r.declined);
  EXPECT_EQ(r.reason, "no points");
  EXPECT_TRUE(r.T_world_robot.isFinite());
  EXPECT_TRUE(loc.localize(Points2{}).declined);
}

TEST(Localization, MapWithoutFreeSpaceIsRefused) {
  const auto all_occupied = OccupancyImage::filled(40, 40, 0.05, SE2(), OccupancyImage::kOccupied);
  const auto all_unknown = OccupancyImage::filled(40, 40, 0.05, SE2(), OccupancyImage::kUnknown);
  for (const auto* m : {&all_occupied, &all_unknown}) {
    try {
      (void)Database::build(*m, fastDb());
      FAIL() << "no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
      EXPECT_EQ(e.where().field, "free space");
    }
  }
}

TEST(Localization, AbsurdGridIsRefusedUpFront) {
  // 100 m cells: a 4 km square, 4 * 10^8 positions at the 0.2 m step (the build used to run out of
  // memory); the error names the step that would do.
  const auto huge = OccupancyImage::filled(40, 40, 100.0, SE2(), OccupancyImage::kFree);
  DatabaseOptions o = fastDb();
  o.step_m = 0.2;
  try {
    (void)Database::build(huge, o);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_EQ(e.where().field, "step");
    EXPECT_NE(std::string(e.what()).find("at least 1.28 m"), std::string::npos) << e.what();
  }
}

TEST(Localization, AbsurdClearanceIsRefused) {
  // 1e9 m overflowed the clearance's cell count (UBSan: negation of INT_MIN; found by fuzzing the
  // options); 30 m is legal but 600 cells of a 5 cm map.
  const auto map = OccupancyImage::filled(40, 40, 0.05, SE2(), OccupancyImage::kFree);
  DatabaseOptions o = fastDb();
  o.clearance_m = 1e9;
  EXPECT_TRUE(test::throwsError([&] { (void)Database::build(map, o); }, ErrorKind::kInvalidArgument, {"clearance_m"}));
  o.clearance_m = 30;
  EXPECT_TRUE(test::throwsError([&] { (void)Database::build(map, o); }, ErrorKind::kBadInput, {"600 cells", "500"}));
}

TEST(LocalizationDatabase, RoundTripKeepsEverythingAndTheAnswers) {
  const SimMap& s = office();
  test::TempDir dir;
  const std::string path = (dir.path() / "office.l2ddb").string();
  Database db = Database::build(s.map, fastDb());
  ASSERT_GT(db.numPairs(), 1000u);
  io::writeLocalizationDatabase(path, db);
  Database back = io::readLocalizationDatabase(path);
  EXPECT_EQ(back.mapChecksum(), localization::mapChecksum(s.map));
  EXPECT_EQ(io::readLocalizationDatabaseMapChecksum(path), back.mapChecksum());
  EXPECT_EQ(back.options().step_m, db.options().step_m);
  EXPECT_EQ(back.options().beams, db.options().beams);
  EXPECT_EQ(back.options().lines.min_points, db.options().lines.min_points);
  ASSERT_EQ(back.positions().size(), db.positions().size());
  ASSERT_EQ(back.lines().size(), db.lines().size());
  EXPECT_EQ(back.numPairs(), db.numPairs());
  for (std::size_t i = 0; i < db.lines().size(); i += 97) {
    EXPECT_EQ(back.lines()[i].normal_angle, db.lines()[i].normal_angle);
    EXPECT_EQ(back.lines()[i].distance, db.lines()[i].distance);
  }
  EXPECT_EQ(back.options().profile_bins, db.options().profile_bins);
  ASSERT_EQ(db.profiles().size(), db.positions().size() * static_cast<std::size_t>(db.options().profile_bins));
  EXPECT_EQ(back.profiles(), db.profiles());
  const Localizer a(s.map, std::move(db));
  const Localizer b(s.map, std::move(back));
  for (std::size_t i = 7; i < s.frames.size(); i += 30) {
    const auto ra = a.localize(s.frames[i].scan, s.frames[i].T_robot_laser);
    const auto rb = b.localize(s.frames[i].scan, s.frames[i].T_robot_laser);
    EXPECT_EQ(ra.declined, rb.declined);
    EXPECT_TRUE(ra.T_world_robot.isApprox(rb.T_world_robot, 1e-9, 1e-9));
    EXPECT_EQ(ra.score, rb.score);
  }
}

TEST(LocalizationDatabase, AnotherMapIsRefused) {
  const SimMap& s = office();
  Database db = Database::build(s.map, fastDb());
  OccupancyImage other = s.map;
  other.set(other.width() / 2, other.height() / 2,
            other.at(other.width() / 2, other.height() / 2) == OccupancyImage::kOccupied
                ? OccupancyImage::kFree
                : OccupancyImage::kOccupied);
  try {
    Localizer loc(other, std::move(db));
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_EQ(e.where().field, "map checksum");
    EXPECT_NE(std::string(e.what()).find("another map"), std::string::npos) << e.what();
  }
}

TEST(LocalizationDatabase, OtherVersionCorruptionAndTruncationAreRefused) {
  const SimMap& s = office();
  test::TempDir dir;
  const std::string path = (dir.path() / "db").string();
  io::writeLocalizationDatabase(path, Database::build(s.map, fastDb()));
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  auto expectError = [&](const std::string& content, ErrorKind kind, const std::string& field) {
    const std::string p = (dir.path() / "bad").string();
    test::writeFile(p, content);
    try {
      (void)io::readLocalizationDatabase(p);
      FAIL() << "no error for field " << field;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), kind) << e.what();
      EXPECT_EQ(e.where().field, field) << e.what();
      EXPECT_EQ(e.where().file, p);
    }
  };
  std::string v1 = bytes;
  v1[8] = 1;  // version (u32 after the 8-byte magic): version 1 had no range profiles
  expectError(v1, ErrorKind::kUnsupported, "version");
  std::string magic = bytes;
  magic[0] = 'X';
  expectError(magic, ErrorKind::kBadInput, "magic");
  std::string flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x40;
  expectError(flipped, ErrorKind::kBadInput, "checksum");
  expectError(bytes.substr(0, bytes.size() - 100), ErrorKind::kBadInput, "positions");
  expectError(bytes.substr(0, 20), ErrorKind::kBadInput, "step_m");
  EXPECT_THROW((void)io::readLocalizationDatabase((dir.path() / "missing").string()), Error);
  // Not files: read whole, /dev/zero used to run out of memory; a directory gave the standard
  // library's message without the path.
  for (const std::string& p : {std::string("/dev/zero"), dir.path().string()}) {
    try {
      (void)io::readLocalizationDatabase(p);
      ADD_FAILURE() << "no error for " << p;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kBadInput) << e.what();
      EXPECT_EQ(e.where().file, p);
      EXPECT_NE(std::string(e.what()).find("not a localization database file"), std::string::npos) << e.what();
    }
  }
}

TEST(LocalizationReal, IntelOddScansInEvenMapSubset) {
  LIDAR2D_REQUIRE_DATA("corrected/intel.log.gz");
  auto src = io::openLog(test::dataFile("corrected/intel.log.gz").string());
  std::vector<Frame> frames;
  while (auto f = src->next()) frames.push_back(std::move(*f));
  auto m = mapping::makeMap(mapping::MapModel::kLogOdds, {});
  for (std::size_t i = 0; i < frames.size(); i += 2)
    m->insert(frames[i].scan, *frames[i].T_world_robot * frames[i].T_robot_laser);
  const OccupancyImage map = mapping::toOccupancyImage(*m);
  DatabaseOptions o;
  o.step_m = 0.25;
  const Localizer loc(map, {}, o);
  std::size_t n = 0, answered = 0, correct = 0;
  for (std::size_t i = 1; i < frames.size(); i += 40) {
    const auto r = loc.localize(frames[i].scan, frames[i].T_robot_laser);
    ++n;
    if (!r.declined) {
      ++answered;
      correct += near(*frames[i].T_world_robot, r.T_world_robot);
    }
  }
  EXPECT_GE(correct, n * 7 / 10) << correct << " correct of " << n;
  EXPECT_GE(correct + 1, answered) << "at most one wrong answer: " << correct << " of " << answered;
}

}  // namespace
}  // namespace lidar2d
