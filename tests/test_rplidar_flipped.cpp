// End to end on a real upside-down laser: ../shared/data/bags/rplidar-flipped (an RPLidar hung
// under a plate; its config.yaml gives the mounting x 0.2 m, 180 degrees about y). `lidar2d slam`
// with `--laser-mount 0.2,0,0,flipped` must build a map of the room that agrees with the course's
// gridmap.png; read as upright, the mirrored scans must not. `lidar2d map` with the SLAM poses must
// agree as well (its walls are where gridmap.png's are). Global localization of its scans in gridmap.png, read with
// its rows up as the course wrote it, places them; read as map_server would, the map is mirrored.
//
// The comparison: the occupied cells of our map (value >= 65, as map_server reads them) and the
// dark pixels of gridmap.png (grey < 89, i.e. map_server's occupied_thresh 0.65) as point sets; the
// first is placed on the second by an exhaustive search over every rotation and translation
// (registration::matchCorrelativeGlobal, branch and bound, no refinement); then the share of each
// set's points within kNearM of the other set's, both ways. The figures are printed.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <numbers>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "lidar2d/core/laser_mount.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/image.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/localization/mirror_check.hpp"
#include "lidar2d/registration/correlative.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

constexpr const char* kBag = "bags/rplidar-flipped/hw2_data.bag";
constexpr const char* kGridmap = "bags/rplidar-flipped/gridmap.png";
constexpr double kGridRes = 0.05;  // gridmap.png [m/px] (config.yaml image_resolution)
constexpr double kNearM = 0.15;    // "agrees": within 3 cells of the other map's wall

// gridmap.png's dark pixels as points [m]. The course's code (filter.py, image_to_world) maps pixel
// (col, row) to x = col * 0.05 - 7.5, y = row * 0.05 - 9.5: the image's row grows with y, so the
// picture as displayed is the room mirrored. Only that orientation matters here (the alignment
// searches every rotation and translation, not mirror images); the offset is theirs.
Points2 gridmapWalls() {
  const io::GreyImage img = io::readGreyImage(test::dataFile(kGridmap).string());
  Points2 pts;
  for (int row = 0; row < img.height; ++row)
    for (int col = 0; col < img.width; ++col)
      if (img.value[static_cast<std::size_t>(row) * static_cast<std::size_t>(img.width) + static_cast<std::size_t>(col)] < 89)
        pts.emplace_back((col + 0.5) * kGridRes - 7.5, (row + 0.5) * kGridRes - 9.5);
  return pts;
}

// Occupied cells of a map_server map as points in its world frame [m].
Points2 mapWalls(const std::string& yaml) {
  const io::MapFile m = io::readMap(yaml);
  Points2 pts;
  for (int row = 0; row < m.map.height(); ++row)
    for (int col = 0; col < m.map.width(); ++col)
      if (m.map.at(col, row) >= 65) pts.push_back(m.map.cellCenter(col, row));
  return pts;
}

// Share of `pts` within kNearM of a point of `ref` (exact distances; `ref` bucketed in cells).
double shareNear(const Points2& pts, const Points2& ref) {
  std::map<std::pair<long, long>, std::vector<Eigen::Vector2d>> cells;
  auto cell = [](double v) { return static_cast<long>(std::floor(v / kGridRes)); };
  for (const auto& p : ref) cells[{cell(p.x()), cell(p.y())}].push_back(p);
  const long reach = static_cast<long>(std::ceil(kNearM / kGridRes));
  std::size_t near = 0;
  for (const auto& p : pts) {
    bool hit = false;
    for (long dx = -reach; dx <= reach && !hit; ++dx)
      for (long dy = -reach; dy <= reach && !hit; ++dy)
        if (const auto it = cells.find({cell(p.x()) + dx, cell(p.y()) + dy}); it != cells.end())
          for (const auto& q : it->second) hit = hit || (q - p).norm() <= kNearM;
    near += hit ? 1 : 0;
  }
  return pts.empty() ? 0.0 : static_cast<double>(near) / static_cast<double>(pts.size());
}

struct Agreement {
  double ours_near_theirs = 0.0;  // share of our wall cells near gridmap.png's walls
  double theirs_near_ours = 0.0;  // and the other way round
  double score = 0.0;             // the alignment's correlation score
};

Agreement compareWithGridmap(const std::string& yaml) {
  const Points2 theirs = gridmapWalls(), ours = mapWalls(yaml);
  EXPECT_GT(theirs.size(), 500u);
  EXPECT_GT(ours.size(), 200u);
  registration::CorrelativeOptions o;
  o.refine = false;
  o.blur_sigma_m = 0.1;
  o.connect_max_gap_m = 0.0;  // a cloud of cells, not a scan in beam order
  o.min_score = 0.0;
  const registration::CorrelativeGrid grid = registration::CorrelativeGrid::fromPoints(theirs, o);
  const auto r = registration::matchCorrelativeGlobal(grid, ours, o);
  Points2 placed;
  for (const auto& p : ours) placed.push_back(r.T_target_source * p);
  return {shareNear(placed, theirs), shareNear(theirs, placed), r.score};
}

TEST(RplidarFlipped, SlamMapAgreesWithTheGridmapOnlyWithTheFlip) {
  LIDAR2D_REQUIRE_DATA(kBag);
  LIDAR2D_REQUIRE_DATA(kGridmap);
  test::TempDir dir;
  const std::string bag = test::dataFile(kBag).string();
  const std::string flipped = (dir / "flipped").string(), upright = (dir / "upright").string();
  // config.yaml's tf_laser2robot: x 0.2 m, 180 degrees about y (the course's filter.py reads a beam
  // (x, y) as (0.2 - x, y) on the robot). Read as upright: the same place, the mirror left out.
  auto r = test::runCli({"slam", bag, "--laser-mount", "0.2,0,0,0,180,0", "-o", flipped});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = test::runCli({"slam", bag, "--laser-mount", "0.2,0,180", "-o", upright});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // The same poses, mapped again: the walls of `lidar2d map` must sit on gridmap.png's too.
  r = test::runCli({"map", bag, "--laser-mount", "0.2,0,0,0,180,0", "--poses", flipped + "/trajectory.txt", "-o",
                    (dir / "remap").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;

  const Agreement with = compareWithGridmap(flipped + "/map.yaml");
  const Agreement without = compareWithGridmap(upright + "/map.yaml");
  const Agreement remap = compareWithGridmap((dir / "remap.yaml").string());
  auto show = [](const char* name, const Agreement& a) {
    std::printf("%-28s ours near gridmap %.3f, gridmap near ours %.3f (alignment score %.3f)\n", name,
                a.ours_near_theirs, a.theirs_near_ours, a.score);
  };
  show("slam, flipped mounting:", with);
  show("slam, read as upright:", without);
  show("map with the slam poses:", remap);

  // With the flip most of our walls lie on the gridmap's and cover most of them; read as upright,
  // the map is the room's mirror image and no rotation puts it on the gridmap.
  EXPECT_GT(with.ours_near_theirs, 0.7);
  EXPECT_GT(with.theirs_near_ours, 0.5);
  EXPECT_GT(remap.ours_near_theirs, 0.7);
  EXPECT_GT(with.ours_near_theirs, without.ours_near_theirs + 0.2);
  EXPECT_GT(with.theirs_near_ours, without.theirs_near_ours + 0.2);
}

// One scan in 25 of the bag, read with the config's mounting, each localized on its own in
// gridmap.png. The course's code reads the image with its row growing with y (gridmapWalls above),
// i.e. its first row is the lowest y: read so (`rows_up`), every scan is placed and consecutive
// answers agree with the odometry; read as map_server reads an image (first row at the top), the map
// is the room's mirror image: none is, and their mirror images are (localization::MirrorCheck).
TEST(RplidarFlipped, GlobalLocalizationInTheGridmapReadWithItsRowsUp) {
  LIDAR2D_REQUIRE_DATA(kBag);
  LIDAR2D_REQUIRE_DATA(kGridmap);
  io::ReaderOptions ro;
  ro.laser_mount = LaserMount::fromRollPitchYaw(0.2, 0.0, 0.0, 0.0, std::numbers::pi, 0.0);
  auto source = io::openLog(test::dataFile(kBag).string(), ro);
  std::vector<Frame> frames;
  while (auto f = source->next())
    if (f->index % 25 == 0) frames.push_back(std::move(*f));
  ASSERT_GE(frames.size(), 20u);
  io::MapYaml y;
  y.resolution = kGridRes;
  y.origin = SE2(-7.5, -9.5, 0.0);
  y.rows_up = true;
  const localization::Localizer rows_up(io::readMapImage(test::dataFile(kGridmap).string(), y).map);
  y.rows_up = false;
  const localization::Localizer as_map_server(io::readMapImage(test::dataFile(kGridmap).string(), y).map);

  std::size_t placed = 0, pairs = 0, consistent = 0, placed_mirrored_map = 0;
  std::optional<std::pair<SE2, SE2>> previous;  // (answer, odometry)
  localization::MirrorCheck mirror;
  for (const Frame& f : frames) {
    const auto r = rows_up.localize(f.scan, f.T_robot_laser);
    if (!r.declined) {
      ++placed;
      if (previous && f.T_odom_robot) {
        const SE2 e =
            (previous->second.inverse() * *f.T_odom_robot).inverse() * (previous->first.inverse() * r.T_world_robot);
        ++pairs;
        consistent += e.translation().norm() <= 0.3 && std::abs(e.theta()) <= 5.0 * std::numbers::pi / 180.0;
      }
      previous = std::make_pair(r.T_world_robot, f.T_odom_robot.value_or(SE2()));
    }
    if (as_map_server.localize(f.scan, f.T_robot_laser).declined)
      mirror.add(f.scan, f.T_robot_laser);
    else
      ++placed_mirrored_map;
  }
  std::printf(
      "rows up: %zu of %zu placed, %zu of %zu consecutive pairs agree with the odometry; as map_server "
      "reads it: %zu placed\n",
      placed, frames.size(), consistent, pairs, placed_mirrored_map);
  EXPECT_GE(placed, frames.size() * 95 / 100);
  EXPECT_GE(consistent, pairs * 95 / 100);
  EXPECT_LE(placed_mirrored_map, frames.size() / 10);
  EXPECT_TRUE(mirror.run(as_map_server).mirrored());
}

}  // namespace
}  // namespace lidar2d
