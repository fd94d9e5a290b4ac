#pragma once
/// @file
/// What every scan matcher returns. Matchers estimate `T_target_source`: the pose of the source
/// scan's frame in the target's frame, so that `p_target = T_target_source * p_source`.

#include <Eigen/Core>
#include <cstddef>
#include <limits>
#include <string>

#include "lidar2d/core/se2.hpp"

namespace lidar2d::registration {

/// Why a matcher stopped.
enum class Status {
  kConverged,      ///< the increment fell below the thresholds (ICP: or the correspondences repeated)
  kMaxIterations,  ///< ran out of iterations (the pose is the last estimate; the likelihood field's: the
                   ///< lowest-cost of its last iterates, or of a cycle too wide to call converged)
  kTooFewPoints,   ///< source or target has fewer valid points than the method needs
  kTooFewInliers,  ///< too few correspondences survived the rejection
  kDegenerate,     ///< the normal equations were singular (e.g. all points identical)
  kInvalidInput,   ///< a non-finite initial guess or option
  kSolverFailure,  ///< the optimiser reported a failure
};
const char* toString(Status s);

/// The rich result of one registration. `pose` is always finite: when the match fails it is the
/// initial guess (and `converged` is false).
struct Result {
  SE2 T_target_source;                 ///< estimate
  bool converged = false;              ///< status == kConverged
  Status status = Status::kInvalidInput;
  int iterations = 0;                  ///< outer iterations performed
  std::size_t num_inliers = 0;         ///< correspondences used in the last iteration
  double final_cost = 0.0;             ///< cost of the last linearisation (method-specific units)
  /// Information matrix H = J^T J (Gauss-Newton approximation of the Hessian) of the last
  /// linearisation, in the parameters (x, y, theta) of T_target_source, unscaled (sum over
  /// residuals with unit weights times robust weights). Degeneracy analysis reads its eigenvalues.
  /// Point-to-line leaves out its two-point lines (IcpOptions::two_point_lines), whose normals are
  /// partly noise: the matrix counts only what the fitted lines (and point pairs) pin.
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();
  /// Covariance estimate of (x, y, theta) [m^2, rad^2]: sigma^2 * H^-1 with sigma^2 the residual
  /// variance, or +inf on the diagonal when H is singular.
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity() * std::numeric_limits<double>::infinity();
  std::string message;                 ///< human-readable detail for failures
};

}  // namespace lidar2d::registration
