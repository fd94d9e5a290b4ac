#include "src/slam/internal/points.hpp"

#include <cmath>
#include <cstdint>
#include <unordered_map>

#include "lidar2d/degeneracy/degeneracy.hpp"

namespace lidar2d::slam::internal {

Points2 scanPoints(const Frame& f, double max_range_m, std::vector<std::size_t>* beams) {
  Points2 pts;
  const LaserScan& s = f.scan;
  pts.reserve(s.size());
  if (beams) beams->clear();
  for (std::size_t i : s.validIndices()) {
    const double r = s.ranges()[i];
    if (!(r < max_range_m)) continue;
    const double a = s.angle(i);
    pts.push_back(f.T_robot_laser * Eigen::Vector2d(r * std::cos(a), r * std::sin(a)));
    if (beams) beams->push_back(i);
  }
  return pts;
}

/// Stacked scans of the same wall would otherwise give each target point near-duplicate neighbours
/// from other scans, and a line fit over a neighbourhood of duplicates has no direction (no normal):
/// point-to-line ICP then loses its correspondences exactly where the robot stands still or turns
/// on the spot.
Points2 voxelFilter(const Points2& pts, double cell_m) {
  struct Acc {
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    int n = 0;
  };
  std::unordered_map<std::uint64_t, std::size_t> index;
  std::vector<Acc> acc;
  index.reserve(pts.size());
  acc.reserve(pts.size());
  for (const auto& p : pts) {
    const auto ix = static_cast<std::int64_t>(std::floor(p.x() / cell_m));
    const auto iy = static_cast<std::int64_t>(std::floor(p.y() / cell_m));
    const std::uint64_t key = (static_cast<std::uint64_t>(ix) << 32) ^ (static_cast<std::uint64_t>(iy) & 0xffffffffULL);
    auto [it, inserted] = index.try_emplace(key, acc.size());
    if (inserted) acc.emplace_back();
    acc[it->second].sum += p;
    ++acc[it->second].n;
  }
  Points2 out;
  out.reserve(acc.size());
  for (const auto& a : acc) out.push_back(a.sum / a.n);
  return out;
}

double explainedFraction(const registration::IcpTarget& target, const Points2& pts, const SE2& T, double inlier_m) {
  return overlapWith(target, pts, T, inlier_m, inlier_m).explained;
}

}  // namespace lidar2d::slam::internal

namespace lidar2d::slam::internal {

Overlap overlapWith(const registration::IcpTarget& target, const Points2& pts, const SE2& T, double inlier_m,
                    double overlap_m) {
  Overlap o;
  if (pts.empty()) return o;
  std::size_t inliers = 0, overlapping = 0;
  for (const auto& p : pts) {
    double d2 = 0.0;
    if (target.nearest(T * p, &d2) >= target.size()) continue;
    if (d2 <= overlap_m * overlap_m) ++overlapping;
    if (d2 <= inlier_m * inlier_m) ++inliers;
  }
  const auto n = static_cast<double>(pts.size());
  o.explained = static_cast<double>(inliers) / n;
  o.overlap = static_cast<double>(overlapping) / n;
  o.explained_in_overlap = overlapping > 0 ? static_cast<double>(inliers) / static_cast<double>(overlapping) : 0.0;
  return o;
}

std::optional<Eigen::Vector2d> weakDirection(const registration::IcpTarget& target, const Points2& pts, const SE2& T,
                                             double inlier_m, double threshold) {
  const Points2& normals = target.normals();
  Eigen::Matrix2d H = Eigen::Matrix2d::Zero();
  std::size_t matched = 0;
  for (const auto& p : pts) {
    double d2 = 0.0;
    const std::size_t i = target.nearestWithin(T * p, inlier_m * inlier_m, &d2);
    if (i >= target.size() || normals[i].squaredNorm() < 0.5) continue;
    H += normals[i] * normals[i].transpose();
    ++matched;
  }
  if (matched == 0) return std::nullopt;
  return degeneracy::weakestDirection(H / static_cast<double>(matched), threshold);
}

}  // namespace lidar2d::slam::internal
