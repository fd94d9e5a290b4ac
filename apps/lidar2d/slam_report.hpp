#pragma once
// The self-contained HTML report of a SLAM run: map with trajectory, loop closures and degenerate
// stretches drawn over it, time per scan, events, and the run's summary. No external resources.

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "lidar2d/io/map_file.hpp"
#include "lidar2d/slam/slam.hpp"

namespace lidar2d::cli {

struct ReportInput {
  const std::string& log;
  const slam::Slam& slam;
  const std::vector<slam::ScanEstimate>& trajectory;
  const OccupancyImage& map;
  const nlohmann::ordered_json& summary;
};

/// The report page (UTF-8 HTML5, images embedded as data: URIs, no scripts needed to display it).
std::string slamReportHtml(const ReportInput& in);

}  // namespace lidar2d::cli
