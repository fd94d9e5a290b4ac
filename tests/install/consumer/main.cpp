// Uses the installed lidar2d through its public headers: scan matching (Ceres, nanoflann), a
// trajectory file round trip (io), an occupancy map (mapping). Prints "consumer: ok" when the
// results are right, else the reason, and exits 1.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <lidar2d/core/se2.hpp>
#include <lidar2d/io/trajectory.hpp>
#include <lidar2d/mapping/export.hpp>
#include <lidar2d/mapping/occupancy_map.hpp>
#include <lidar2d/registration/matcher.hpp>

int main() {
  using namespace lidar2d;
  // An L-corner, and the same seen from a pose shifted by (0.1, -0.05, 2 deg).
  Points2 target;
  for (int i = 0; i < 60; ++i) target.emplace_back(2.0, -1.5 + 0.05 * i);
  for (int i = 0; i < 60; ++i) target.emplace_back(-1.0 + 0.05 * i, 1.5);
  const SE2 T_target_source(0.1, -0.05, 2.0 * 3.14159265358979 / 180.0);
  Points2 source;
  for (const auto& p : target) source.push_back(T_target_source.inverse() * p);
  const auto result = registration::matchScans(target, source, SE2(), {});
  if (!result.converged || !result.T_target_source.isApprox(T_target_source, 1e-3, 1e-3)) {
    std::printf("consumer: matching failed: %s\n", result.message.c_str());
    return 1;
  }
  const std::string path = (std::filesystem::temp_directory_path() / "lidar2d-consumer-traj.txt").string();
  io::writeTrajectory(path, {{1.0, T_target_source}});
  const auto back = io::readTrajectory(path);
  std::filesystem::remove(path);
  if (back.size() != 1 || !back[0].pose.isApprox(T_target_source, 1e-6, 1e-6)) {
    std::printf("consumer: trajectory round trip failed\n");
    return 1;
  }
  auto map = mapping::makeMap(mapping::MapModel::kLogOdds);
  map->insert(LaserScan::create({.time = 0.0, .angle_min = -1.0, .angle_increment = 0.01, .range_min = 0.1,
                                 .range_max = 10.0, .ranges = std::vector<double>(201, 3.0), .intensities = {}}),
              SE2());
  const auto image = mapping::toOccupancyImage(*map);
  if (image.width() < 10) {
    std::printf("consumer: map too small\n");
    return 1;
  }
  std::printf("consumer: ok (map %dx%d)\n", image.width(), image.height());
  return 0;
}
