#pragma once
// Point sets of the SLAM pipeline: a scan's points in the robot frame, the voxel filter, and how
// much of a scan a target explains.

#include <cstddef>
#include <optional>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/registration/icp.hpp"

namespace lidar2d::slam::internal {

/// The valid returns of `f` under `max_range_m`, in the robot frame (laser mounting applied), in
/// scan order; with `beams`, the beam index of each.
Points2 scanPoints(const Frame& f, double max_range_m, std::vector<std::size_t>* beams = nullptr);

/// Centroid of the points in each `cell_m` square, in order of first appearance.
Points2 voxelFilter(const Points2& pts, double cell_m);

/// The share of `pts` that lie within `inlier_m` of a point of `target` once moved by T; 0 for no
/// points.
double explainedFraction(const registration::IcpTarget& target, const Points2& pts, const SE2& T, double inlier_m);

/// The direction a target cannot pin `pts` along once moved by T (a corridor's axis, target
/// frame), or nullopt when it pins every direction: the weakest eigen-direction of the
/// translational information per matched point (the mean of n n^T over the points within
/// `inlier_m` of a target point with a line, n its normal), when its eigenvalue is below
/// `threshold` (degeneracy::weakestDirection); nullopt also when no point matches a line (nothing
/// shows a direction to be weak).
std::optional<Eigen::Vector2d> weakDirection(const registration::IcpTarget& target, const Points2& pts, const SE2& T,
                                             double inlier_m, double threshold);

/// How much of a scan a target explains where they overlap.
struct Overlap {
  double explained = 0.0;  ///< share of the points within `inlier_m` of the target (explainedFraction)
  double overlap = 0.0;    ///< share of the points within `overlap_m` of the target (the rest see new ground)
  double explained_in_overlap = 0.0;  ///< explained / overlap (0 when nothing overlaps)
};
/// The Overlap of `pts` moved by T with `target`.
Overlap overlapWith(const registration::IcpTarget& target, const Points2& pts, const SE2& T, double inlier_m,
                    double overlap_m);

}  // namespace lidar2d::slam::internal
