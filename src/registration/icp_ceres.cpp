#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <vector>

#include "src/registration/internal/ceres_common.hpp"
#include "src/registration/internal/icp_problem.hpp"

namespace lidar2d::registration::internal {

namespace {

// All residuals of a correspondence search as one Ceres residual block, with analytic Jacobians
// over the pose (x, y, theta) of T_target_source. Point-to-line: one residual per line term
// (Censi's r = n^T (R p + t - m)); point-to-point: two per pair (R p + t - m). The robust loss
// (a Ceres LossFunction) is applied per line term or per pair inside the block
// (robustScaling), so the block's squared norm is the sum of rho over them: the same objective as
// one residual block per pair with the loss attached, without Ceres's per-block bookkeeping
// (evaluation dispatch, validity checks, the loss's Jacobian correction), which would take most of
// the time with one block per pair.
class PairResiduals final : public ceres::CostFunction {
 public:
  PairResiduals(const Icp& icp, bool p2l, const ceres::LossFunction* loss)
      : terms_(p2l ? icp.lines() : pairs_), loss_(loss), p2l_(p2l) {
    if (!p2l) {
      const Points2& tp = icp.target().points;
      for (const Pair& pr : icp.pairs()) {
        const Eigen::Vector2d& p = icp.source()[pr.src];
        const Eigen::Vector2d& m = tp[pr.tgt];
        pairs_.push_back({p.x(), p.y(), m.x(), m.y(), 0.0, 0.0});
      }
    }
    set_num_residuals(static_cast<int>(p2l ? terms_.size() : 2 * terms_.size()));
    mutable_parameter_block_sizes()->push_back(3);
  }
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const double* x = parameters[0];
    const double c = std::cos(x[2]), s = std::sin(x[2]);
    double* J = jacobians != nullptr ? jacobians[0] : nullptr;  // row-major, 3 columns
    for (std::size_t k = 0; k < terms_.size(); ++k) {
      const Icp::LineTerm& t = terms_[k];
      // d(T p)/d(x, y, theta) = [1 0 jx; 0 1 jy] (SE2::pointJacobian)
      const double jx = -s * t.px - c * t.py, jy = c * t.px - s * t.py;
      const double qx = c * t.px - s * t.py + x[0] - t.mx, qy = s * t.px + c * t.py + x[1] - t.my;
      double f, g;
      if (p2l_) {
        const double r = t.nx * qx + t.ny * qy;
        robustScaling(loss_, r * r, f, g);
        residuals[k] = f * r;
        if (J != nullptr) {
          const double d = f + g * r * r;
          double* row = J + 3 * k;
          row[0] = d * t.nx;
          row[1] = d * t.ny;
          row[2] = d * (t.nx * jx + t.ny * jy);
        }
      } else {
        robustScaling(loss_, qx * qx + qy * qy, f, g);
        residuals[2 * k] = f * qx;
        residuals[2 * k + 1] = f * qy;
        if (J != nullptr) {
          // f J + g r (r^T J), J = [1 0 jx; 0 1 jy]
          const double rj0 = qx, rj1 = qy, rj2 = qx * jx + qy * jy;
          double* row = J + 6 * k;
          row[0] = f + g * qx * rj0;
          row[1] = g * qx * rj1;
          row[2] = f * jx + g * qx * rj2;
          row[3] = g * qy * rj0;
          row[4] = f + g * qy * rj1;
          row[5] = f * jy + g * qy * rj2;
        }
      }
    }
    return true;
  }

 private:
  std::vector<Icp::LineTerm> pairs_;         // point-to-point: (px, py, mx, my), the normal unused
  const std::vector<Icp::LineTerm>& terms_;  // point-to-line: the search's own line terms
  const ceres::LossFunction* loss_;
  bool p2l_;
};

std::unique_ptr<ceres::LossFunction> makeLoss(const RobustLoss& loss) {
  switch (loss.kind) {
    case RobustLoss::Kind::kNone:
      return nullptr;
    case RobustLoss::Kind::kHuber:
      return std::make_unique<ceres::HuberLoss>(loss.scale_m);
    case RobustLoss::Kind::kCauchy:
      return std::make_unique<ceres::CauchyLoss>(loss.scale_m);
  }
  return nullptr;
}

}  // namespace

// Outer loop of correspondence searches; for each set of pairs Ceres minimises the robust cost
// (a few Levenberg-Marquardt iterations), then the pairs are searched again at the new pose.
Result runCeres(Icp& icp, const SE2& init, const IcpOptions& o) {
  const std::unique_ptr<ceres::LossFunction> loss = makeLoss(o.loss);
  const ceres::Solver::Options so = poseSolverOptions(o.ceres_max_inner_iterations, 1e-12, 1e-10);
  double x[3] = {init.x(), init.y(), init.theta()};
  const ceres::Problem::Options po = singleBlockProblemOptions();
  int it = 0;
  bool converged = false;
  PairSetHistory history;
  while (it < o.max_iterations) {
    ++it;
    const SE2 T(x[0], x[1], x[2]);
    icp.findPairs(T);
    if (icp.pairs().size() < o.min_inliers) return tooFewInliers(init, it, icp.pairs().size(), o);
    const bool repeated = history.seenBefore(icp.setHash());
    PairResiduals residuals(icp, o.metric == IcpMetric::kPointToLine, loss.get());
    ceres::Problem problem(po);
    problem.AddResidualBlock(&residuals, nullptr, x);
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    if (!summary.IsSolutionUsable() || !std::isfinite(x[0]) || !std::isfinite(x[1]) || !std::isfinite(x[2]))
      return failure(init, Status::kSolverFailure, fmt::format("Ceres: {}", summary.message));
    x[2] = wrapAngle(x[2]);
    const Eigen::Vector3d dx(x[0] - T.x(), x[1] - T.y(), angleDiff(x[2], T.theta()));
    if (smallStep(dx, o) || repeated) {
      converged = true;
      break;
    }
  }
  return finalResult(icp, SE2(x[0], x[1], x[2]), it, converged, o);
}

}  // namespace lidar2d::registration::internal
