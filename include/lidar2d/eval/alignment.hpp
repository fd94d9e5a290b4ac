#pragma once
/// @file
/// Least-squares rigid alignment of two planar point sets (no scale), in closed form.

#include <vector>

#include <Eigen/Core>

#include "lidar2d/core/se2.hpp"

namespace lidar2d::eval {

/// The rigid transform `T_ref_est` minimising `sum_i |p_ref[i] - T_ref_est * p_est[i]|^2`.
///
/// This is Horn (1987) / Umeyama (1991) without scale, specialised to 2D where the SVD reduces to
/// one atan2: with centred points a_i = p_est[i] - mean(p_est), b_i = p_ref[i] - mean(p_ref),
///   theta = atan2(sum_i (a_i x b_i), sum_i (a_i . b_i)),   t = mean(p_ref) - R(theta) mean(p_est),
/// where x is the 2D cross product. This is the global minimum (the cost is
/// const - 2 (C cos(theta) + S sin(theta)) in theta), so no reflection case arises as in 3D.
/// When the rotation is not determined (a single point, or all points equal) theta is 0 and only
/// the centroids are matched.
/// Throws `lidar2d::Error` (kInvalidArgument) when the sets are empty or of different sizes.
SE2 alignPoints(const std::vector<Eigen::Vector2d>& p_est, const std::vector<Eigen::Vector2d>& p_ref);

}  // namespace lidar2d::eval
