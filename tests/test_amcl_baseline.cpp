// The AMCL-style particle filter of the dataset benchmark (bench/dataset/amcl_baseline.hpp), the
// baseline `lidar2d track` is compared with. Simulated office: the map from the noise-free run, a
// noisy-odometry run filtered from a uniform start (no initial pose): the cloud converges near the
// truth and then follows it; the same seed gives the same answers; bad options and a map without
// free space are refused.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include "bench/dataset/amcl_baseline.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/office_run.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

using bench::AmclFilter;
using bench::AmclOptions;
using bench::AmclResult;
constexpr double kDeg = std::numbers::pi / 180.0;

using Office = test::OfficeRun;
const Office& office() { return test::officeMapAndRun(); }

AmclOptions smallOptions() {
  AmclOptions o;
  o.global_particles = 5000;
  o.tracking_particles = 1000;
  return o;
}

double errorM(const Frame& f, const AmclResult& r) {
  return (f.T_world_robot->inverse() * r.T_world_robot).translation().norm();
}
double errorDeg(const Frame& f, const AmclResult& r) {
  return std::abs((f.T_world_robot->inverse() * r.T_world_robot).theta()) / kDeg;
}

TEST(AmclBaseline, ConvergesFromAUniformStartAndFollowsTheTruth) {
  const Office& o = office();
  AmclFilter filter(o.map, smallOptions());
  EXPECT_EQ(filter.numParticles(), 5000u);
  std::vector<AmclResult> res;
  for (const Frame& f : o.frames) res.push_back(filter.add(f));
  // The uniform start is not converged: the cloud covers the whole office.
  EXPECT_FALSE(res.front().converged);
  EXPECT_GT(res.front().std_m + (1.0 - res.front().cluster_weight), 0.5);
  std::size_t first = res.size();
  for (std::size_t i = 0; i < res.size(); ++i)
    if (res[i].converged) {
      first = i;
      break;
    }
  ASSERT_LT(first, 80u) << "the cloud never converged within 80 scans";
  EXPECT_LT(errorM(o.frames[first], res[first]), 0.5) << "converged at scan " << first << " far from the truth";
  // Once converged, it follows the truth: 90% of the later scans within 0.2 m and 3 degrees, and
  // with the cloud shrunk to the tracking particles.
  std::size_t near = 0, after = 0;
  for (std::size_t i = first + 10; i < res.size(); ++i) {
    ++after;
    near += errorM(o.frames[i], res[i]) <= 0.2 && errorDeg(o.frames[i], res[i]) <= 3.0;
  }
  ASSERT_GT(after, 100u);
  EXPECT_GE(static_cast<double>(near), 0.9 * static_cast<double>(after)) << near << " of " << after;
  EXPECT_EQ(res.back().particles, 1000u);
}

TEST(AmclBaseline, SameSeedSameAnswers) {
  const Office& o = office();
  AmclOptions opt = smallOptions();
  opt.global_particles = 2000;
  AmclFilter a(o.map, opt), b(o.map, opt);
  for (std::size_t i = 0; i < 40; ++i) {
    const AmclResult ra = a.add(o.frames[i]), rb = b.add(o.frames[i]);
    ASSERT_EQ(ra.T_world_robot.x(), rb.T_world_robot.x()) << "scan " << i;
    ASSERT_EQ(ra.T_world_robot.theta(), rb.T_world_robot.theta()) << "scan " << i;
  }
}

TEST(AmclBaseline, BadOptionsAndAMapWithoutFreeSpaceAreRefused) {
  const Office& o = office();
  auto refused = [&](auto&& edit, const char* field) {
    AmclOptions opt = smallOptions();
    edit(opt);
    try {
      AmclFilter f(o.map, opt);
      ADD_FAILURE() << field << " accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  refused([](AmclOptions& p) { p.global_particles = 0; }, "global_particles");
  refused([](AmclOptions& p) { p.sigma_hit_m = 0.0; }, "sigma_hit_m");
  refused([](AmclOptions& p) { p.alpha3 = -1.0; }, "alpha3");
  refused([](AmclOptions& p) { p.z_rand = 1.5; }, "z_rand");
  refused([](AmclOptions& p) { p.resample_interval = 0; }, "resample_interval");
  const OccupancyImage walls = OccupancyImage::filled(20, 20, 0.05, SE2(), OccupancyImage::kOccupied);
  try {
    AmclFilter f(walls, smallOptions());
    ADD_FAILURE() << "a map without free cells accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_NE(std::string(e.what()).find("free"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace lidar2d
