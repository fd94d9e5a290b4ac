#pragma once
// Ceres settings shared by the matchers' optimizer-based solvers: small dense problems (3
// parameters), one thread, silent.

#include <ceres/ceres.h>

namespace lidar2d::registration::internal {

/// Solver options for a 3-parameter pose problem: dense QR, one thread, no logging.
inline ceres::Solver::Options poseSolverOptions(int max_iterations, double function_tolerance,
                                                double parameter_tolerance) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = max_iterations;
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  so.function_tolerance = function_tolerance;
  so.gradient_tolerance = 1e-14;
  so.parameter_tolerance = parameter_tolerance;
  return so;
}

}  // namespace lidar2d::registration::internal
