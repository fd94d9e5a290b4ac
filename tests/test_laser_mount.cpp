// ReaderOptions::laser_mount / --laser-mount: the laser's mounting pose replaces the log's on every
// frame and nothing else changes; malformed values are usage errors.

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <limits>
#include <numbers>
#include <random>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/laser_mount.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

/// A scan with seeded random ranges (some invalid) and intensities, beams counter-clockwise or
/// clockwise.
LaserScan randomScan(std::mt19937& rng, bool clockwise = false) {
  std::uniform_real_distribution<double> range(0.2, 9.0), angle(-kPi, kPi), u(0.0, 1.0);
  LaserScanFields f;
  f.time = 3.0;
  const std::size_t n = 5 + rng() % 60;
  f.angle_min = angle(rng);
  f.angle_increment = (clockwise ? -1.0 : 1.0) * 2.0 * kPi / static_cast<double>(n) * (0.3 + 0.7 * u(rng));
  f.range_min = 0.1;
  f.range_max = 10.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double v = u(rng);
    f.ranges.push_back(v < 0.1 ? std::numeric_limits<double>::quiet_NaN() : v < 0.15 ? 10.0 : range(rng));
    f.intensities.push_back(static_cast<double>(i));
  }
  return LaserScan::create(f);
}

/// The reference: each valid beam's endpoint taken through the full 3D mounting, then dropped onto
/// the robot's plane (z ignored), in raw beam order.
Points2 pointsIn3D(const LaserScan& raw, const LaserMount& m) {
  Points2 pts;
  for (std::size_t i : raw.validIndices()) {
    const double a = raw.angle(i), r = raw.ranges()[i];
    const Eigen::Vector3d p = m.rotation3() * Eigen::Vector3d(r * std::cos(a), r * std::sin(a), 0.0) + m.translation3();
    pts.emplace_back(p.x(), p.y());
  }
  return pts;
}

// The mirror is exact: a laser with roll or pitch of 180 degrees (any yaw) gives, through
// project() and the planar T_robot_laser, the robot-frame points of the 3D mounting, with the beams
// reversed so that they keep their turning direction.
TEST(LaserMount, UpsideDownProjectionMatchesThe3DMountingOnRandomScans) {
  std::mt19937 rng(33);
  std::uniform_real_distribution<double> angle(-kPi, kPi), offset(-0.5, 0.5);
  for (int trial = 0; trial < 200; ++trial) {
    SCOPED_TRACE(trial);
    const bool roll = trial % 2 == 0;
    const LaserMount m = LaserMount::fromRollPitchYaw(offset(rng), offset(rng), offset(rng), roll ? kPi : 0.0,
                                                      roll ? 0.0 : kPi, angle(rng));
    ASSERT_TRUE(m.upsideDown());
    ASSERT_NEAR(m.tilt(), 0.0, 1e-9);
    const LaserScan raw = randomScan(rng, trial % 3 == 0);
    const LaserScan up = m.project(raw);
    const Points2 ref = pointsIn3D(raw, m);
    const Points2 got = up.toPoints(m.T_robot_laser());
    ASSERT_EQ(got.size(), ref.size());
    for (std::size_t k = 0; k < ref.size(); ++k) ASSERT_LT((got[k] - ref[ref.size() - 1 - k]).norm(), 1e-9) << k;
    EXPECT_EQ(up.size(), raw.size());
    EXPECT_EQ(up.angleIncrement(), raw.angleIncrement());
    EXPECT_EQ(up.intensities().front(), raw.intensities().back());
    // Mirroring twice gives the raw scan back.
    const LaserScan twice = LaserMount::planar(SE2(), true).project(up);
    EXPECT_EQ(twice.ranges().size(), raw.ranges().size());
    for (std::size_t i = 0; i < raw.size(); ++i)
      if (raw.isValid(i)) {
        EXPECT_EQ(twice.ranges()[i], raw.ranges()[i]);
      }
    EXPECT_NEAR(twice.angleMin(), raw.angleMin(), 1e-12);
  }
}

// The rule, on one beam: roll pi sends laser angle a to -a, pitch pi to pi - a.
TEST(LaserMount, RollAndPitchOfPiMirrorABeam) {
  LaserScanFields f;
  f.angle_min = 0.3;
  f.angle_increment = 0.1;
  f.range_max = 10.0;
  f.ranges = {2.0};
  const LaserScan raw = LaserScan::create(f);
  const auto roll = LaserMount::fromRollPitchYaw(0, 0, 0, kPi, 0, 0);
  const auto pitch = LaserMount::fromRollPitchYaw(0, 0, 0, 0, kPi, 0);
  const Eigen::Vector2d p_roll = roll.project(raw).toPoints(roll.T_robot_laser())[0];
  const Eigen::Vector2d p_pitch = pitch.project(raw).toPoints(pitch.T_robot_laser())[0];
  EXPECT_LT((p_roll - 2.0 * Eigen::Vector2d(std::cos(-0.3), std::sin(-0.3))).norm(), 1e-12);
  EXPECT_LT((p_pitch - 2.0 * Eigen::Vector2d(std::cos(kPi - 0.3), std::sin(kPi - 0.3))).norm(), 1e-12);
  // A roll of pi is the planar mounting (0, 0, 0) flipped; a pitch of pi is (0, 0, 180 deg) flipped.
  EXPECT_TRUE(test::IsNearPose(SE2(), roll.T_robot_laser(), 1e-12, 1e-9));
  EXPECT_TRUE(test::IsNearPose(SE2(0, 0, kPi), pitch.T_robot_laser(), 1e-12, 1e-9));
  // The rplidar-flipped config.yaml's 4x4 matrix: rotation diag(-1, 1, -1) (180 deg about y), x 0.2.
  Eigen::Matrix3d R;
  R << -1, 0, 0, 0, 1, 0, 0, 0, -1;
  const auto cfg = LaserMount::fromTransform(Eigen::Vector3d(0.2, 0, 0), Eigen::Quaterniond(R));
  EXPECT_TRUE(cfg.upsideDown());
  EXPECT_TRUE(test::IsNearPose(SE2(0.2, 0, kPi), cfg.T_robot_laser(), 1e-12, 1e-9));
  EXPECT_FALSE(LaserMount::fromRollPitchYaw(0, 0, 0, kPi, kPi, 0).upsideDown());  // two flips: upright
}

// A tilted laser: each range becomes the horizontal distance of its endpoint from the laser (exact),
// and the bearings stay uniform, off the true ones by at most about tilt^2 / 4 (documented).
TEST(LaserMount, TiltedProjectionShortensRangesToTheirHorizontalPart) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> angle(-kPi, kPi), tilt(2.0 * kDeg, 20.0 * kDeg);
  for (int trial = 0; trial < 100; ++trial) {
    SCOPED_TRACE(trial);
    const double phi = tilt(rng), axis = angle(rng);
    const bool flipped = trial % 2 == 1;
    // Tilted by phi about a horizontal axis at `axis`, on top of an upright or flipped laser.
    const Eigen::Quaterniond q = Eigen::AngleAxisd(phi, Eigen::Vector3d(std::cos(axis), std::sin(axis), 0.0)) *
                                 Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitZ()) *
                                 Eigen::AngleAxisd(flipped ? kPi : 0.0, Eigen::Vector3d::UnitX());
    const LaserMount m = LaserMount::fromTransform(Eigen::Vector3d(0.1, -0.2, 0.3), q);
    ASSERT_NEAR(m.tilt(), phi, 1e-9);
    ASSERT_EQ(m.upsideDown(), flipped);
    const LaserScan raw = randomScan(rng);
    const Points2 ref = pointsIn3D(raw, m);
    const Points2 got = m.project(raw).toPoints(m.T_robot_laser());
    ASSERT_EQ(got.size(), ref.size());  // range_min 0.1 < 0.2 * cos(20 deg): no beam is lost
    const Eigen::Vector2d origin = m.T_robot_laser().translation();
    for (std::size_t k = 0; k < ref.size(); ++k) {
      const Eigen::Vector2d& r = ref[flipped ? ref.size() - 1 - k : k];
      EXPECT_NEAR((got[k] - origin).norm(), (r - origin).norm(), 1e-9) << k;
      const double bearing_error = std::abs(angleDiff(std::atan2((got[k] - origin).y(), (got[k] - origin).x()),
                                                      std::atan2((r - origin).y(), (r - origin).x())));
      EXPECT_LE(bearing_error, 1.1 * phi * phi / 4 + 1e-9) << k;
    }
  }
  // Levelled, the same mounting has no tilt and leaves the ranges alone.
  const auto m = LaserMount::fromRollPitchYaw(0, 0, 0, 1.0 * kDeg, 0, 0.5);
  const LaserScan raw = randomScan(rng);
  const LaserScan level = m.levelled().project(raw), tilted = m.project(raw);
  for (std::size_t i : raw.validIndices()) {
    EXPECT_EQ(level.ranges()[i], raw.ranges()[i]) << i;
    EXPECT_LT(tilted.ranges()[i], raw.ranges()[i]) << i;
  }
}

TEST(LaserMount, InvalidMountingsAreInvalidArguments) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(test::throwsError([&] { (void)LaserMount::planar(SE2(nan, 0.0, 0.0)); }, ErrorKind::kInvalidArgument,
                                {"laser_mount", "finite"}));
  EXPECT_TRUE(test::throwsError([&] { (void)LaserMount::fromRollPitchYaw(0, 0, 0, nan, 0, 0); },
                                ErrorKind::kInvalidArgument, {"laser_mount", "finite"}));
  EXPECT_TRUE(test::throwsError(
      [&] { (void)LaserMount::fromTransform(Eigen::Vector3d::Zero(), Eigen::Quaterniond(0, 0, 0, 0)); },
      ErrorKind::kInvalidArgument, {"laser_mount", "unit length"}));
  EXPECT_NO_THROW((void)LaserMount::fromTransform(Eigen::Vector3d::Zero(), Eigen::Quaterniond(1.004, 0, 0, 0)));
  std::mt19937 rng(1);
  const LaserScan raw = randomScan(rng);
  EXPECT_TRUE(test::throwsError([&] { (void)LaserMount::fromRollPitchYaw(0, 0, 0, 0, 50 * kDeg, 0).project(raw); },
                                ErrorKind::kInvalidArgument, {"tilted by 50.0 deg"}));
}

std::vector<Frame> readAll(const std::string& log, const io::ReaderOptions& o = {}) {
  std::vector<Frame> frames;
  auto src = io::openLog(log, o);
  while (auto f = src->next()) frames.push_back(std::move(*f));
  return frames;
}

TEST(LaserMount, ReplacesTheLogsMountingOnEveryFrameAndNothingElse) {
  test::TempDir dir;
  const std::string log = (dir / "office.log").string();
  ASSERT_EQ(test::runCli({"simulate", "--world", "office", "--scans", "30", "-o", log}).exit_code, 0);
  const auto plain = readAll(log);
  io::ReaderOptions o;
  o.laser_mount = LaserMount::planar(SE2(-0.04, 0.02, 0.1));
  const auto mounted = readAll(log, o);
  ASSERT_EQ(plain.size(), 30u);
  ASSERT_EQ(mounted.size(), plain.size());
  ASSERT_FALSE(test::IsNearPose(o.laser_mount->T_robot_laser(), plain[0].T_robot_laser, 1e-3, 0.1));  // a real change
  for (std::size_t i = 0; i < plain.size(); ++i) {
    EXPECT_TRUE(test::IsNearPose(o.laser_mount->T_robot_laser(), mounted[i].T_robot_laser, 0.0, 0.0)) << i;
    EXPECT_FALSE(mounted[i].laser_upside_down);
    EXPECT_EQ(mounted[i].time, plain[i].time);
    EXPECT_EQ(mounted[i].scan.ranges(), plain[i].scan.ranges());
    EXPECT_TRUE(test::IsNearPose(*plain[i].T_world_robot, *mounted[i].T_world_robot, 0.0, 0.0));
    EXPECT_TRUE(test::IsNearPose(*plain[i].T_odom_robot, *mounted[i].T_odom_robot, 0.0, 0.0));
  }
  auto src = io::openLog(log, o);
  while (src->next()) {
  }
  EXPECT_NE(src->notes().scan_source.find("given by the options"), std::string::npos) << src->notes().scan_source;
}

TEST(LaserMount, AbsurdOffsetOrTiltToleranceIsAnInvalidArgument) {
  test::TempDir dir;
  const std::string log = (dir / "office.log").string();
  ASSERT_EQ(test::runCli({"simulate", "--world", "office", "--scans", "3", "-o", log}).exit_code, 0);
  io::ReaderOptions o;
  // Finite but absurd (a mistyped unit): 1e308 m made `lidar2d slam` fail deep inside with the
  // standard library's "cannot create std::vector larger than max_size()".
  o.laser_mount = LaserMount::planar(SE2(0.0, -1e3, 0.0));
  EXPECT_TRUE(test::throwsError([&] { io::openLog(log, o); }, ErrorKind::kInvalidArgument, {"laser_mount", "100 m"}));
  o.laser_mount = LaserMount::fromRollPitchYaw(0.0, 0.0, 1e3, 0.0, 0.0, 0.0);
  EXPECT_TRUE(test::throwsError([&] { io::openLog(log, o); }, ErrorKind::kInvalidArgument, {"laser_mount", "100 m"}));
  o.laser_mount = LaserMount::planar(SE2(99.0, -99.0, 3.0));
  EXPECT_NO_THROW(io::openLog(log, o));
  for (const double tol : {-1.0, 46.0, std::numeric_limits<double>::quiet_NaN()}) {
    o.max_laser_tilt_deg = tol;
    EXPECT_TRUE(test::throwsError([&] { io::openLog(log, o); }, ErrorKind::kInvalidArgument, {"max_laser_tilt_deg"}));
  }
}

// CARMEN logs cannot say that a laser is upside down: the options do, and the frames' robot-frame
// points are then the raw beams mirrored (a -> -a) at the mounting, computed here from the raw log.
TEST(LaserMount, CarmenLogWithAFlippedMountFromTheOptions) {
  test::TempDir dir;
  const std::string log = (dir / "office.log").string();
  ASSERT_EQ(test::runCli({"simulate", "--world", "office", "--scans", "10", "-o", log}).exit_code, 0);
  const auto raw = readAll(log);
  io::ReaderOptions o;
  o.laser_mount = LaserMount::planar(SE2(0.2, 0.0, 0.0), true);
  const auto flipped = readAll(log, o);
  ASSERT_EQ(flipped.size(), raw.size());
  for (std::size_t k = 0; k < raw.size(); ++k) {
    SCOPED_TRACE(k);
    EXPECT_TRUE(flipped[k].laser_upside_down);
    const Points2 got = flipped[k].scan.toPoints(flipped[k].T_robot_laser);
    const std::vector<std::size_t> valid = raw[k].scan.validIndices();
    ASSERT_EQ(got.size(), valid.size());
    for (std::size_t j = 0; j < valid.size(); ++j) {
      const std::size_t i = valid[valid.size() - 1 - j];  // beam order reversed
      const double a = raw[k].scan.angle(i), r = raw[k].scan.ranges()[i];
      EXPECT_LT((got[j] - Eigen::Vector2d(0.2 + r * std::cos(-a), r * std::sin(-a))).norm(), 1e-9) << j;
    }
  }
  // The same through the command line, and info says so.
  const auto r = test::runCli({"info", log, "--json", "--laser-mount=0.2,0,0,flipped"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_TRUE(j["laser_upside_down"].get<bool>());
  const auto t = test::runCli({"info", log, "--laser-mount=0.2,0,0,flipped"});
  EXPECT_NE(t.out.find("upside down"), std::string::npos) << t.out;
  const auto plain = test::runCli({"info", log});
  EXPECT_EQ(plain.out.find("upside down"), std::string::npos) << plain.out;
}

TEST(LaserMount, CommandLine) {
  test::TempDir dir;
  const std::string log = (dir / "office.log").string();
  ASSERT_EQ(test::runCli({"simulate", "--world", "office", "--scans", "3", "-o", log}).exit_code, 0);
  const auto r = test::runCli({"info", log, "--json", "--laser-mount=0.1,-0.2,30"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_NEAR(j["laser_mount"][0].get<double>(), 0.1, 1e-12);
  EXPECT_NEAR(j["laser_mount"][1].get<double>(), -0.2, 1e-12);
  EXPECT_NEAR(j["laser_mount"][2].get<double>(), std::numbers::pi / 6, 1e-12);
  EXPECT_FALSE(j["laser_upside_down"].get<bool>());
  // Roll, pitch and yaw: 180 degrees about y (the rplidar-flipped config.yaml's matrix) is the
  // planar mounting (x, y, 180 deg), upside down.
  for (const std::string good : {"0.2,0,0,0,180,0", "0.2,0,180,flipped"}) {
    const auto g = test::runCli({"info", log, "--json", "--laser-mount=" + good});
    ASSERT_EQ(g.exit_code, 0) << good << ": " << g.err;
    const auto jg = nlohmann::json::parse(g.out);
    EXPECT_TRUE(jg["laser_upside_down"].get<bool>()) << good;
    EXPECT_NEAR(std::abs(jg["laser_mount"][2].get<double>()), std::numbers::pi, 1e-9) << good;
  }
  for (const std::string bad : {"0.1,0.2", "0.1,0.2,3,4", "a,0,0", "nan,0,0", "0,inf,0", "0,,0", "1e999,0,0", "",
                                 "1e308,0,0", "0,-101,0", "0,0,0,upsidedown", "0,0,0,0,0,flipped", "0,0,0,0,0",
                                 "0,0,200,0,0,0", "0,0,0,0,nan,0"}) {
    const auto b = test::runCli({"info", log, "--laser-mount=" + bad});
    EXPECT_EQ(b.exit_code, 2) << "'" << bad << "': " << b.err;
    EXPECT_NE(b.err.find("--laser-mount"), std::string::npos) << b.err;
  }
  // A tilted mounting from the options: refused by the commands, warned about by info, projected
  // with --allow-tilted.
  const auto refused = test::runCli({"map", log, "-o", (dir / "m").string(), "--laser-mount=0,0,0,10,0,0"});
  EXPECT_EQ(refused.exit_code, 1) << refused.err;
  EXPECT_NE(refused.err.find("tilted by 10.0 deg"), std::string::npos) << refused.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "m.pgm"));
  const auto warned = test::runCli({"info", log, "--json", "--laser-mount=0,0,0,10,0,0"});
  ASSERT_EQ(warned.exit_code, 0) << warned.err;
  const auto jw = nlohmann::json::parse(warned.out);
  EXPECT_NEAR(jw["laser_tilt_deg"].get<double>(), 10.0, 1e-9);
  EXPECT_NE(jw["warnings"].dump().find("unless --allow-tilted"), std::string::npos) << jw["warnings"].dump();
  EXPECT_EQ(test::runCli({"info", log, "--laser-mount=0,0,0,10,0,0", "--max-tilt", "11"}).exit_code, 0);
  const auto allowed =
      test::runCli({"map", log, "-o", (dir / "m").string(), "--laser-mount=0,0,0,10,0,0", "--allow-tilted"});
  EXPECT_EQ(allowed.exit_code, 0) << allowed.err;
  EXPECT_EQ(test::runCli({"info", log, "--max-tilt", "50"}).exit_code, 2);
}

}  // namespace
}  // namespace lidar2d
