#include "lidar2d/registration/result.hpp"

namespace lidar2d::registration {

const char* toString(Status s) {
  switch (s) {
    case Status::kConverged:
      return "converged";
    case Status::kMaxIterations:
      return "max_iterations";
    case Status::kTooFewPoints:
      return "too_few_points";
    case Status::kTooFewInliers:
      return "too_few_inliers";
    case Status::kDegenerate:
      return "degenerate";
    case Status::kInvalidInput:
      return "invalid_input";
    case Status::kSolverFailure:
      return "solver_failure";
  }
  return "unknown";
}

}  // namespace lidar2d::registration
