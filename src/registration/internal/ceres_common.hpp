#pragma once
// Ceres settings shared by the matchers' optimizer-based solvers: small dense problems (3
// parameters), one thread, silent.

#include <ceres/ceres.h>

#include <cmath>
#include <limits>

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

// cos and sin of theta, remembered for the last angle asked: Ceres evaluates every residual block
// at the same pose one after another, so one evaluation pass computes them once instead of once
// per block (they were a tenth of a point-to-point Ceres match). One
// cache per thread, shared by the matchers' cost functions.
inline void cachedCosSin(double theta, double& c, double& s) {
  thread_local double last = std::numeric_limits<double>::quiet_NaN(), last_c = 1.0, last_s = 0.0;
  if (!(theta == last)) {
    last = theta;
    last_c = std::cos(theta);
    last_s = std::sin(theta);
  }
  c = last_c;
  s = last_s;
}

}  // namespace lidar2d::registration::internal
