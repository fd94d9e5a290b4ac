#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <cmath>

#include "src/registration/internal/icp_problem.hpp"

namespace lidar2d::registration::internal {

namespace {

// Solves H dx = -g. Falls back to the pseudo-inverse (eigenvalues below 1e-12 of the largest
// dropped) when H is singular or nearly so (a corridor leaves one direction unconstrained): the
// step then does not move along that direction. Returns false when H carries no information.
bool solveStep(const Eigen::Matrix3d& H, const Eigen::Vector3d& g, Eigen::Vector3d& dx) {
  Eigen::LDLT<Eigen::Matrix3d> ldlt(H);
  if (ldlt.info() == Eigen::Success && ldlt.isPositive() && ldlt.rcond() > 1e-10) {
    dx = -ldlt.solve(g);
    if (dx.allFinite()) return true;
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(H);
  const double lmax = es.eigenvalues()(2);
  if (!(lmax > 0.0) || !std::isfinite(lmax)) return false;
  dx.setZero();
  for (int i = 0; i < 3; ++i) {
    const double l = es.eigenvalues()(i);
    if (l > 1e-12 * lmax) dx -= es.eigenvectors().col(i) * (es.eigenvectors().col(i).dot(g) / l);
  }
  return dx.allFinite();
}

}  // namespace

Result runGaussNewton(Icp& icp, const SE2& init, const IcpOptions& o) {
  Eigen::Vector3d x = init.vector();
  int it = 0;
  bool converged = false;
  PairSetHistory history;
  while (it < o.max_iterations) {
    ++it;
    icp.findPairs(SE2::fromVector(x));
    if (icp.pairs().size() < o.min_inliers) return tooFewInliers(init, it, icp.pairs().size(), o);
    // A few Gauss-Newton steps on this set of pairs (the nearest-neighbour search costs far more
    // than a linearisation), then search again; converged when the whole outer step is small.
    const bool repeated = history.seenBefore(icp.setHash());
    const Eigen::Vector3d x_outer = x;
    for (int inner = 0; inner < o.gn_inner_iterations; ++inner) {
      const Linearisation L = icp.linearise(SE2::fromVector(x), /*with_cost=*/false);
      Eigen::Vector3d dx;
      if (!solveStep(L.H, L.g, dx))
        return failure(init, Status::kDegenerate, "the normal equations carry no information");
      x += dx;
      x.z() = wrapAngle(x.z());
      if (!x.allFinite()) return failure(init, Status::kSolverFailure, "the estimate became non-finite");
      if (smallStep(dx, o)) break;
    }
    const Eigen::Vector3d dx(x.x() - x_outer.x(), x.y() - x_outer.y(), angleDiff(x.z(), x_outer.z()));
    if (smallStep(dx, o) || repeated) {
      converged = true;
      break;
    }
  }
  return finalResult(icp, SE2::fromVector(x), it, converged, o);
}

}  // namespace lidar2d::registration::internal
