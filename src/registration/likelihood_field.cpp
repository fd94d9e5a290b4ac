#include "lidar2d/registration/likelihood_field.hpp"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <string>

#include "lidar2d/core/error.hpp"
#include "lidar2d/registration/icp.hpp"
#include "src/registration/internal/ceres_common.hpp"
#include "src/registration/internal/lf_raster.hpp"

namespace lidar2d::registration {

namespace {

using internal::NodeGrid;

// Gauss-Newton stops at a cycle of the finest level when its poses lie within this many cells of
// each other, and their angles within the arc of that many cells at 1 m from the laser: 5 mm and
// 0.29 deg with 5 cm cells.
constexpr double kCycleSpreadCells = 0.1;

// Gauss-Newton on a coarse level stops when its step is under this many of the level's cells (and
// as many radians per metre of cell): 1 mm and 0.29 deg on the 20 cm level of the default three.
// The seed it hands on is then far inside the next level's basin, so the iterations this saves do
// not change the result; the finest level keeps the step thresholds of the options.
constexpr double kCoarseStepCells = 0.005;

// Largest number of nodes one level may have: a field is a working buffer, not a canvas for
// arbitrary extents (a 500 m x 500 m map at 5 cm is 10^8 nodes).
constexpr double kMaxNodes = 2.0e8;

void requireField(bool ok, const char* field, const std::string& what) {
  if (!ok) throw invalidArgument(what, ErrorLocation({}, 0, field));
}

LikelihoodField::Level makeLevel(const Eigen::Vector2d& lo, const Eigen::Vector2d& hi, double res, double trunc) {
  LikelihoodField::Level lv;
  lv.resolution = res;
  lv.inv_resolution = 1.0 / res;
  lv.truncation = trunc;
  const double pad = trunc + 2.0 * res;
  lv.origin = ((lo.array() - pad) / res).floor() * res;
  const Eigen::Vector2d ext = hi.array() + pad - lv.origin.array();
  const double w = std::ceil(ext.x() / res) + 1.0, h = std::ceil(ext.y() / res) + 1.0;
  if (w * h > kMaxNodes)
    throw invalidArgument(fmt::format("the field would need {:.0f} x {:.0f} nodes; use a coarser resolution", w, h),
                          ErrorLocation({}, 0, "resolution_m"));
  lv.width = static_cast<int>(w);
  lv.height = static_cast<int>(h);
  lv.values.assign(static_cast<std::size_t>(lv.width) * static_cast<std::size_t>(lv.height), static_cast<float>(trunc));
  return lv;
}

float& node(LikelihoodField::Level& lv, int i, int j) {
  return lv.values[static_cast<std::size_t>(j) * static_cast<std::size_t>(lv.width) + static_cast<std::size_t>(i)];
}

// Distance to isolated points minus `radius`, kept where it is the smallest magnitude so far.
void splatPoints(LikelihoodField::Level& lv, const std::vector<Eigen::Vector2d>& pts, double radius = 0.0) {
  const NodeGrid g{lv.origin, lv.resolution, lv.width, lv.height};
  const double r = lv.truncation;
  for (const auto& p : pts) {
    internal::forEachNodeInBox(g, p.array() - r, p.array() + r, [&](int i, int j, const Eigen::Vector2d& q) {
      const double d = (q - p).norm() - radius;
      float& v = node(lv, i, j);
      if (std::abs(d) < std::abs(v)) v = static_cast<float>(d);
    });
  }
}

// Signed distance to the line of each segment, positive on the sensor's side, over the nodes whose
// projection falls on the segment extended by one node spacing at both ends (so consecutive
// segments overlap and a wall's end does not create a sign discontinuity beside it).
void splatSegments(LikelihoodField::Level& lv, const std::vector<internal::Segment>& segs, const Eigen::Vector2d& sensor) {
  const NodeGrid g{lv.origin, lv.resolution, lv.width, lv.height};
  const double r = lv.truncation, ext = lv.resolution;
  for (const auto& s : segs) {
    const Eigen::Vector2d ab = s.b - s.a;
    const double len = ab.norm();
    const Eigen::Vector2d u = ab / len;
    Eigen::Vector2d n(-u.y(), u.x());
    if (n.dot(sensor - s.a) < 0.0) n = -n;
    internal::forEachNodeNearRectangle(g, s.a, u, n, -ext, len + ext, r, [&](int i, int j, const Eigen::Vector2d& q) {
      const Eigen::Vector2d aq = q - s.a;
      const double t = aq.dot(u);
      if (t < -ext || t > len + ext) return;
      const double d = aq.dot(n);
      float& v = node(lv, i, j);
      if (std::abs(d) < std::abs(v)) v = static_cast<float>(d);
    });
  }
}

// Bilinear interpolation of one level at p with its analytic gradient (LikelihoodField::sample; a
// function of its own so that the matchers' loops inline it).
inline LikelihoodField::Sample sampleLevel(const LikelihoodField::Level& lv, const Eigen::Vector2d& p) {
  LikelihoodField::Sample s;
  s.value = lv.truncation;
  const LikelihoodField::Level::Cell c = lv.cellAt(p);
  if (!c.row0) return s;
  const float* row0 = c.row0;
  const float* row1 = row0 + lv.width;
  const double v00 = row0[0], v10 = row0[1], v01 = row1[0], v11 = row1[1];
  const double fx = c.fx, fy = c.fy, inv_res = lv.inv_resolution;
  s.value = lv.interpolate(c);
  s.gradient.x() = ((1 - fy) * (v10 - v00) + fy * (v11 - v01)) * inv_res;
  s.gradient.y() = ((1 - fx) * (v01 - v00) + fx * (v11 - v10)) * inv_res;
  const float t = static_cast<float>(lv.truncation);
  s.inlier = std::abs(row0[0]) < t && std::abs(row0[1]) < t && std::abs(row1[0]) < t && std::abs(row1[1]) < t;
  return s;
}

// d value / d theta at p (source frame) for a pose whose rotation has cosine c and sine sn: the
// field gradient times the theta column of SE2::pointJacobian(p).
inline double thetaDerivative(const Eigen::Vector2d& gradient, const Eigen::Vector2d& p, double c, double sn) {
  return gradient.x() * (-sn * p.x() - c * p.y()) + gradient.y() * (c * p.x() - sn * p.y());
}

double robustWeight(LfLoss loss, double r, double k) {
  const double a = std::abs(r);
  switch (loss) {
    case LfLoss::kNone:
      return 1.0;
    case LfLoss::kHuber:
      return a <= k ? 1.0 : k / a;
    case LfLoss::kCauchy:
      return 1.0 / (1.0 + (r / k) * (r / k));
  }
  return 1.0;
}

// One linearisation of the field cost at T over the inliers of level l.
struct Linearisation {
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  double sq_sum = 0.0;  // sum of squared residuals of the inliers
  std::size_t n = 0;
};

// The cost of every point at T (points outside the field count at the truncation).
double totalCost(const LikelihoodField& field, int l, const Points2& src, const SE2& T, LfLoss loss, double k) {
  RobustLoss rho;  // (ICP's loss: the same definitions as robustWeight's)
  rho.kind = loss == LfLoss::kHuber ? RobustLoss::Kind::kHuber
                                    : (loss == LfLoss::kCauchy ? RobustLoss::Kind::kCauchy : RobustLoss::Kind::kNone);
  rho.scale_m = k;
  double c = 0.0;
  const LikelihoodField::Level& lv = field.level(l);
  for (const auto& p : src) c += rho.rho(sampleLevel(lv, T * p).value);
  return c;
}

Linearisation linearise(const LikelihoodField& field, int l, const Points2& src, const SE2& T, LfLoss loss, double k) {
  Linearisation lin;
  const LikelihoodField::Level& lv = field.level(l);
  const double c = std::cos(T.theta()), sn = std::sin(T.theta());
  for (const auto& p : src) {
    const Eigen::Vector2d q(c * p.x() - sn * p.y() + T.x(), sn * p.x() + c * p.y() + T.y());
    const auto s = sampleLevel(lv, q);
    if (!s.inlier) continue;
    // gradient^T * SE2::pointJacobian(p)
    const Eigen::Vector3d J(s.gradient.x(), s.gradient.y(), thetaDerivative(s.gradient, p, c, sn));
    const double w = robustWeight(loss, s.value, k);
    lin.H.noalias() += w * J * J.transpose();
    lin.g.noalias() += (w * s.value) * J;
    lin.sq_sum += s.value * s.value;
    ++lin.n;
  }
  return lin;
}

// The first of `poses` with the lowest totalCost.
SE2 lowestCost(const LikelihoodField& field, int l, const Points2& src, const std::vector<SE2>& poses, LfLoss loss,
               double k) {
  SE2 best_pose = poses.front();
  double best = std::numeric_limits<double>::infinity();
  for (const SE2& m : poses) {
    const double c = totalCost(field, l, src, m, loss, k);
    if (c < best) {
      best = c;
      best_pose = m;
    }
  }
  return best_pose;
}

// Every source point's field value at T * p as one Ceres residual block of n residuals, with
// analytic Jacobians (chain rule: field gradient times SE2::pointJacobian). Points outside the
// inlier zone give the truncation with a zero Jacobian, the value a truncated field assigns them.
// The robust loss (a Ceres LossFunction) is applied per point inside the block (robustScaling), so
// that the block's squared norm is the sum of rho(v^2) over the points, the same objective as one
// block per point with the loss attached. One block instead of one per point: Ceres's bookkeeping
// per residual block (evaluation dispatch, validity checks, the loss's Jacobian correction) would
// take most of the solve's time.
class FieldResiduals final : public ceres::CostFunction {
 public:
  FieldResiduals(const LikelihoodField::Level& level, const Points2& src, const ceres::LossFunction* loss)
      : level_(level), src_(src), loss_(loss) {
    set_num_residuals(static_cast<int>(src.size()));
    mutable_parameter_block_sizes()->push_back(3);
  }
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const double* x = parameters[0];
    const double c = std::cos(x[2]), sn = std::sin(x[2]);
    double* J = jacobians != nullptr ? jacobians[0] : nullptr;  // row-major n x 3
    for (std::size_t i = 0; i < src_.size(); ++i) {
      const Eigen::Vector2d& p = src_[i];
      const Eigen::Vector2d q(c * p.x() - sn * p.y() + x[0], sn * p.x() + c * p.y() + x[1]);
      const auto s = sampleLevel(level_, q);
      const double v = s.inlier ? s.value : level_.truncation;
      double f, g;
      internal::robustScaling(loss_, v * v, f, g);
      residuals[i] = f * v;
      const double dr_dv = f + g * v * v;
      if (J != nullptr) {
        double* row = J + 3 * i;
        if (s.inlier) {
          row[0] = dr_dv * s.gradient.x();
          row[1] = dr_dv * s.gradient.y();
          row[2] = dr_dv * thetaDerivative(s.gradient, p, c, sn);
        } else {
          row[0] = row[1] = row[2] = 0.0;
        }
      }
    }
    return true;
  }

 private:
  const LikelihoodField::Level& level_;
  const Points2& src_;
  const ceres::LossFunction* loss_;
};

// Ends a Ceres solve at the first accepted step shorter than `max_norm` (the norm over x, y and
// theta: each component is then below it too), the Gauss-Newton solver's test. Ceres's own
// tolerances are relative to the cost and to |x|; on the piecewise-bilinear field the cost keeps
// changing in its last digits while the steps stay at micrometres, so without this most solves
// would run to max_iterations and report no convergence.
class SmallStepStop final : public ceres::IterationCallback {
 public:
  explicit SmallStepStop(double max_norm) : max_norm_(max_norm) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    return s.iteration > 0 && s.step_is_successful && s.step_norm <= max_norm_ ? ceres::SOLVER_TERMINATE_SUCCESSFULLY
                                                                               : ceres::SOLVER_CONTINUE;
  }

 private:
  double max_norm_;
};

Result failure(const SE2& pose, Status status, std::string message) {
  Result r;
  r.T_target_source = pose;
  r.converged = false;
  r.status = status;
  r.message = std::move(message);
  return r;
}

}  // namespace

void LikelihoodFieldOptions::validate() const {
  requireField(std::isfinite(resolution_m) && resolution_m > 0.0, "resolution_m", "must be finite and > 0");
  requireField(levels >= 1 && levels <= 8, "levels", "must be in 1..8");
  requireField(std::isfinite(truncation_m) && truncation_m >= 2.0 * resolution_m, "truncation_m",
               "must be finite and >= 2 * resolution_m");
  requireField(std::isfinite(connect_max_gap_m) && connect_max_gap_m >= 0.0, "connect_max_gap_m", "must be finite and >= 0");
  requireField(occupied_min >= 1 && occupied_min <= 100, "occupied_min", "must be in 1..100");
  requireField(solver == LfSolver::kGaussNewton || solver == LfSolver::kCeres, "solver", "unknown solver");
  requireField(loss == LfLoss::kNone || loss == LfLoss::kHuber || loss == LfLoss::kCauchy, "loss", "unknown loss");
  requireField(std::isfinite(loss_scale_m) && loss_scale_m > 0.0, "loss_scale_m", "must be finite and > 0");
  requireField(max_iterations >= 1, "max_iterations", "must be >= 1");
  requireField(std::isfinite(min_translation_step_m) && min_translation_step_m >= 0.0, "min_translation_step_m",
               "must be finite and >= 0");
  requireField(std::isfinite(min_rotation_step_rad) && min_rotation_step_rad >= 0.0, "min_rotation_step_rad",
               "must be finite and >= 0");
  requireField(min_points >= 3, "min_points", "must be >= 3");
}

LikelihoodField LikelihoodField::fromPoints(const Points2& target, const LikelihoodFieldOptions& options,
                                            const Eigen::Vector2d& sensor_origin) {
  options.validate();
  LikelihoodField f;
  Eigen::Vector2d lo, hi;
  if (!internal::boundingBox(target, lo, hi)) return f;
  const auto poly = internal::makePolyline(target, options.connect_max_gap_m);
  for (int l = 0; l < options.levels; ++l) {
    const double scale = std::ldexp(1.0, l);
    auto lv = makeLevel(lo, hi, options.resolution_m * scale, options.truncation_m * scale);
    splatSegments(lv, poly.segments, sensor_origin);
    splatPoints(lv, poly.isolated);
    f.levels_.push_back(std::move(lv));
  }
  return f;
}

LikelihoodField LikelihoodField::fromMap(const OccupancyImage& map, const LikelihoodFieldOptions& options) {
  options.validate();
  Points2 obstacles;
  for (int row = 0; row < map.height(); ++row)
    for (int col = 0; col < map.width(); ++col)
      if (map.at(col, row) >= options.occupied_min) obstacles.push_back(map.cellCenter(col, row));
  LikelihoodField f;
  Eigen::Vector2d lo, hi;
  if (!internal::boundingBox(obstacles, lo, hi)) return f;
  for (int l = 0; l < options.levels; ++l) {
    const double scale = std::ldexp(1.0, l);
    auto lv = makeLevel(lo, hi, options.resolution_m * scale, options.truncation_m * scale);
    splatPoints(lv, obstacles, 0.5 * map.resolution());
    f.levels_.push_back(std::move(lv));
  }
  return f;
}

LikelihoodField::Sample LikelihoodField::sample(const Eigen::Vector2d& p, int l) const {
  return sampleLevel(levels_[static_cast<std::size_t>(l)], p);
}

Result matchLikelihoodField(const LikelihoodField& field, const Points2& source, const SE2& init,
                            const LikelihoodFieldOptions& options) {
  options.validate();
  if (!init.isFinite()) return failure(SE2(), Status::kInvalidInput, "the initial guess is not finite");
  Points2 src;
  src.reserve(source.size());
  for (const auto& p : source)
    if (p.allFinite()) src.push_back(p);
  if (src.size() < options.min_points)
    return failure(init, Status::kTooFewPoints,
                   fmt::format("the source has {} valid points, fewer than min_points = {}", src.size(), options.min_points));
  if (field.empty()) return failure(init, Status::kTooFewPoints, "the target has no valid points");

  SE2 T = init;
  int iterations = 0;
  bool converged = false;
  std::string wide_cycle;  // why the finest level stopped unconverged at a cycle (Gauss-Newton)
  const int levels = std::min(field.numLevels(), options.levels);
  for (int l = levels - 1; l >= 0; --l) {
    const double scale = std::ldexp(1.0, l);
    const double k = options.loss_scale_m * scale;
    const double max_step = field.level(l).truncation;
    // A coarse level only seeds the next one: it stops at steps under kCoarseStepCells of its cell.
    const double coarse_step = l > 0 ? kCoarseStepCells * field.level(l).resolution : 0.0;
    converged = false;
    if (options.solver == LfSolver::kGaussNewton) {
      // Line search: the cost at T, carried from the step that moved there (NaN: not known yet).
      double cost_at_T = std::numeric_limits<double>::quiet_NaN();
      // The poses the iterations started from, latest last (the cycle test below).
      std::vector<SE2> visited;
      visited.reserve(static_cast<std::size_t>(options.max_iterations));
      const double tol_t = options.min_translation_step_m * scale, tol_r = options.min_rotation_step_rad * scale;
      const double step_t = std::max(options.min_translation_step_m, coarse_step);
      const double step_r = std::max(options.min_rotation_step_rad, coarse_step);
      for (int it = 0; it < options.max_iterations; ++it) {
        visited.push_back(T);
        const auto lin = linearise(field, l, src, T, options.loss, k);
        if (lin.n < options.min_points) {
          if (l > 0) break;  // the coarse level did not see enough; try the finer ones anyway
          return failure(init, Status::kTooFewInliers,
                         fmt::format("{} points lie within the field's truncation, fewer than min_points = {}", lin.n,
                                     options.min_points));
        }
        // A tiny Levenberg term keeps a (nearly) singular H solvable; the degenerate direction
        // then barely moves instead of jumping.
        const Eigen::Matrix3d A = lin.H + 1e-9 * (lin.H.trace() + 1e-12) * Eigen::Matrix3d::Identity();
        Eigen::Vector3d dx = -A.ldlt().solve(lin.g);
        if (!dx.allFinite()) return failure(init, Status::kDegenerate, "the normal equations are singular");
        // Gauss-Newton is only trusted within the field's truncation: clamp the step.
        const double tn = dx.head<2>().norm();
        if (tn > max_step) dx.head<2>() *= max_step / tn;
        dx.z() = std::clamp(dx.z(), -0.3, 0.3);
        SE2 next(T.x() + dx.x(), T.y() + dx.y(), T.theta() + dx.z());
        if (options.line_search && l == 0) {
          // A step that raises the cost is halved, up to kMaxHalvings times; when none lowers it,
          // the estimate is a minimum of this level along the Gauss-Newton direction.
          constexpr int kMaxHalvings = 4;
          const double c0 = std::isnan(cost_at_T) ? totalCost(field, l, src, T, options.loss, k) : cost_at_T;
          int halvings = 0;
          double c = totalCost(field, l, src, next, options.loss, k);
          for (; c > c0 && halvings < kMaxHalvings; ++halvings) {
            dx *= 0.5;
            next = SE2(T.x() + dx.x(), T.y() + dx.y(), T.theta() + dx.z());
            c = totalCost(field, l, src, next, options.loss, k);
          }
          if (c > c0) {
            ++iterations;
            converged = true;
            break;
          }
          cost_at_T = c;  // the cost at `next`, where T moves now
        }
        T = next;
        ++iterations;
        if (dx.head<2>().norm() <= step_t && std::abs(dx.z()) <= step_r) {
          converged = true;
          break;
        }
        // A cycle: the step came back to a pose an earlier iteration started from (the field is
        // piecewise bilinear, and a point crossing a cell edge can flip the linearisation back and
        // forth, so Gauss-Newton may alternate between two to four poses instead of shrinking its
        // step; more iterations would only repeat it). The level stops at the lowest-cost of the
        // members and their centroid (a two-cycle straddles the minimum). On a coarse level, which
        // only seeds the next one, that is its answer; on the finest it counts as converged when
        // the members lie within kCycleSpreadCells of each other, the precision the estimate then
        // has, and otherwise ends the match unconverged (kMaxIterations, saying so).
        const auto back = std::find_if(visited.rbegin() + 1, visited.rend(),
                                       [&](const SE2& V) { return V.isApprox(T, tol_t, tol_r); });
        if (back != visited.rend() && back - visited.rbegin() <= 3) {
          std::vector<SE2> candidates(visited.end() - (back - visited.rbegin()) - 1, visited.end());
          double spread_t = 0.0, spread_r = 0.0;
          Eigen::Vector3d sum = Eigen::Vector3d::Zero();
          for (const SE2& m : candidates) {
            spread_t = std::max(spread_t, (m.translation() - T.translation()).norm());
            spread_r = std::max(spread_r, std::abs(angleDiff(m.theta(), T.theta())));
            sum += Eigen::Vector3d(m.x(), m.y(), T.theta() + angleDiff(m.theta(), T.theta()));
          }
          const std::size_t members = candidates.size();
          sum /= static_cast<double>(members);
          candidates.emplace_back(sum.x(), sum.y(), sum.z());
          T = lowestCost(field, l, src, candidates, options.loss, k);
          const double gate = kCycleSpreadCells * field.level(l).resolution;
          converged = l > 0 || (spread_t <= gate && spread_r <= gate);
          if (!converged)
            wide_cycle = fmt::format(
                "Gauss-Newton alternates between {} poses up to {:.1f} mm and {:.2f} deg apart; stopped at the "
                "lowest-cost one",
                members, 1e3 * spread_t, spread_r * 180.0 / std::numbers::pi);
          break;
        }
      }
      if (l == 0 && !converged && wide_cycle.empty() && !visited.empty()) {
        // Out of iterations without a clean cycle (the steps wander between nearby poses): the
        // estimate is the lowest-cost of the last iterates, not whichever came last.
        std::vector<SE2> last{T};
        for (auto m = visited.rbegin(); m != visited.rend() && last.size() < 5; ++m) last.push_back(*m);
        T = lowestCost(field, l, src, last, options.loss, k);
      }
    } else {
      double x[3] = {T.x(), T.y(), T.theta()};
      std::unique_ptr<ceres::LossFunction> loss;
      if (options.loss == LfLoss::kHuber) loss = std::make_unique<ceres::HuberLoss>(k);
      if (options.loss == LfLoss::kCauchy) loss = std::make_unique<ceres::CauchyLoss>(k);
      FieldResiduals residuals(field.level(l), src, loss.get());
      ceres::Problem problem(internal::singleBlockProblemOptions());
      problem.AddResidualBlock(&residuals, nullptr, x);
      ceres::Solver::Options so = internal::poseSolverOptions(options.max_iterations, 1e-10, 1e-9);
      SmallStepStop stop(
          std::max(std::min(options.min_translation_step_m, options.min_rotation_step_rad), coarse_step));
      so.callbacks.push_back(&stop);
      ceres::Solver::Summary summary;
      ceres::Solve(so, &problem, &summary);
      iterations += static_cast<int>(summary.iterations.size()) - 1;
      if (!std::isfinite(x[0]) || !std::isfinite(x[1]) || !std::isfinite(x[2]))
        return failure(init, Status::kSolverFailure, "Ceres returned a non-finite pose");
      T = SE2(x[0], x[1], x[2]);
      converged = summary.termination_type == ceres::CONVERGENCE || summary.termination_type == ceres::USER_SUCCESS;
      if (summary.termination_type == ceres::FAILURE && l == 0)
        return failure(init, Status::kSolverFailure, summary.message);
    }
  }

  // The final linearisation at the estimate: H, inliers, cost and covariance.
  const auto lin = linearise(field, 0, src, T, options.loss, options.loss_scale_m);
  if (lin.n < options.min_points)
    return failure(init, Status::kTooFewInliers,
                   fmt::format("{} points lie within the field's truncation at the estimate, fewer than min_points = {}",
                               lin.n, options.min_points));
  Result r;
  r.T_target_source = T;
  r.iterations = iterations;
  r.num_inliers = lin.n;
  r.final_cost = lin.sq_sum / static_cast<double>(lin.n);
  r.information = lin.H;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(lin.H);
  const double max_eig = std::max(es.eigenvalues().maxCoeff(), 0.0);
  if (es.eigenvalues().minCoeff() > 1e-12 * max_eig && max_eig > 0.0) {
    const double sigma2 = lin.n > 3 ? lin.sq_sum / static_cast<double>(lin.n - 3) : lin.sq_sum;
    r.covariance = sigma2 * lin.H.inverse();
  }
  r.converged = converged;
  r.status = converged ? Status::kConverged : Status::kMaxIterations;
  if (!converged) r.message = wide_cycle.empty() ? "the last level did not converge within max_iterations" : wide_cycle;
  return r;
}

Result matchLikelihoodField(const Points2& target, const Points2& source, const SE2& init,
                            const LikelihoodFieldOptions& options) {
  const auto field = LikelihoodField::fromPoints(target, options);
  return matchLikelihoodField(field, source, init, options);
}

}  // namespace lidar2d::registration
