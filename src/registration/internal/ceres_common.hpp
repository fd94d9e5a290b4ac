#pragma once
// Ceres settings shared by the matchers' optimizer-based solvers: small dense problems (3
// parameters), one thread, silent.

#include <ceres/ceres.h>

#include <cmath>

namespace lidar2d::registration::internal {

/// Problem options for the matchers' problems of one residual block (see robustScaling) that
/// their solver owns: Ceres neither takes the cost function nor checks the user-built structure.
inline ceres::Problem::Options singleBlockProblemOptions() {
  ceres::Problem::Options po;
  po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  po.enable_fast_removal = false;
  po.disable_all_safety_checks = true;
  return po;
}

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

/// A residual vector r whose squared norm s = |r|^2 is robustified by `loss` (nullptr: none) inside
/// a cost function, so that several of them can share one residual block: the robustified residual
/// f r with f = sqrt(rho(s) / s) has the squared norm rho(s), and its Jacobian is
/// f J + g r (r^T J) with g = 2 df/ds. (Ceres itself applies a loss to a whole residual block; one
/// block per point cost the matchers most of their time in Ceres's per-block bookkeeping.)
inline void robustScaling(const ceres::LossFunction* loss, double s, double& f, double& g) {
  f = 1.0;
  g = 0.0;
  if (loss == nullptr) return;
  double rho[3];
  loss->Evaluate(s, rho);
  if (!(s > 0.0)) {  // the limit at 0: rho(s) ~ rho'(0) s
    f = std::sqrt(rho[1]);
    return;
  }
  f = std::sqrt(rho[0] / s);
  g = f > 0.0 ? (rho[1] * s - rho[0]) / (s * s * f) : 0.0;
}

}  // namespace lidar2d::registration::internal
