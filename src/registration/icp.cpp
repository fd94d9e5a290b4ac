// ICP's options and entry points. The target's preparation is in icp_target.cpp, the
// correspondence search and normal equations in icp_problem.cpp, the solvers in
// icp_gauss_newton.cpp and icp_ceres.cpp.

#include "lidar2d/registration/icp.hpp"

#include <fmt/format.h>

#include <cmath>
#include <string>
#include <utility>

#include "src/registration/internal/icp_problem.hpp"
#include "src/registration/internal/icp_target.hpp"

namespace lidar2d::registration {

const char* toString(Solver s) {
  switch (s) {
    case Solver::kGaussNewton:
      return "gn";
    case Solver::kCeres:
      return "ceres";
  }
  return "unknown";
}

const char* toString(NeighborSearch s) {
  switch (s) {
    case NeighborSearch::kBearingWalk:
      return "bearing";
    case NeighborSearch::kKdTree:
      return "kdtree";
  }
  return "unknown";
}

const char* toString(RobustLoss::Kind k) {
  switch (k) {
    case RobustLoss::Kind::kNone:
      return "none";
    case RobustLoss::Kind::kHuber:
      return "huber";
    case RobustLoss::Kind::kCauchy:
      return "cauchy";
  }
  return "unknown";
}

double RobustLoss::weight(double r) const {
  switch (kind) {
    case Kind::kNone:
      return 1.0;
    case Kind::kHuber: {
      const double a = std::abs(r);
      return a <= scale_m ? 1.0 : scale_m / a;
    }
    case Kind::kCauchy:
      return 1.0 / (1.0 + (r * r) / (scale_m * scale_m));
  }
  return 1.0;
}

double RobustLoss::rho(double r) const {
  const double s = r * r;
  switch (kind) {
    case Kind::kNone:
      return s;
    case Kind::kHuber:
      return s <= scale_m * scale_m ? s : 2.0 * scale_m * std::sqrt(s) - scale_m * scale_m;
    case Kind::kCauchy:
      return scale_m * scale_m * std::log1p(s / (scale_m * scale_m));
  }
  return s;
}

std::string IcpOptions::check() const {
  auto finite_pos = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!finite_pos(max_correspondence_dist_m)) return "max_correspondence_dist_m must be finite and > 0";
  if (!(trim_keep_fraction > 0.0 && trim_keep_fraction <= 1.0)) return "trim_keep_fraction must be in (0, 1]";
  if (max_iterations < 1) return "max_iterations must be >= 1";
  if (!(std::isfinite(translationEps()) && translationEps() >= 0.0)) return "translation_eps_m must be finite and >= 0";
  if (!(std::isfinite(rotationEps()) && rotationEps() >= 0.0)) return "rotation_eps_rad must be finite and >= 0";
  if (loss.kind != RobustLoss::Kind::kNone && !finite_pos(loss.scale_m)) return "loss.scale_m must be finite and > 0";
  if (min_points < 3) return "min_points must be >= 3";
  if (min_inliers < 3) return "min_inliers must be >= 3";
  if (normal_neighbors < 2) return "normal_neighbors must be >= 2";
  if (!finite_pos(normal_max_radius_m)) return "normal_max_radius_m must be finite and > 0";
  if (!(max_line_flatness >= 0.0 && max_line_flatness <= 1.0)) return "max_line_flatness must be in [0, 1]";
  if (ceres_max_inner_iterations < 1) return "ceres_max_inner_iterations must be >= 1";
  if (gn_inner_iterations < 1) return "gn_inner_iterations must be >= 1";
  if (!(std::isfinite(point_pair_weight) && point_pair_weight >= 0.0))
    return "point_pair_weight must be finite and >= 0";
  if (!(std::isfinite(min_source_spacing_m) && min_source_spacing_m >= 0.0))
    return "min_source_spacing_m must be finite and >= 0";
  return {};
}

namespace {

// The points in their order (a scan's: by bearing) without those closer than `spacing` to the last
// point kept (IcpOptions::min_source_spacing_m).
Points2 thinned(const Points2& in, double spacing) {
  const double s2 = spacing * spacing;
  Points2 out;
  out.reserve(in.size());
  for (const auto& p : in)
    if (out.empty() || (p - out.back()).squaredNorm() >= s2) out.push_back(p);
  return out;
}

}  // namespace

Result alignIcp(const IcpTarget& target, const Points2& points_source, const SE2& init_T_target_source,
                const IcpOptions& options) {
  if (const std::string bad = options.check(); !bad.empty())
    return internal::failure(init_T_target_source, Status::kInvalidInput, "invalid option: " + bad);
  if (!init_T_target_source.isFinite())
    return internal::failure(init_T_target_source, Status::kInvalidInput, "the initial guess is not finite");
  Points2 source = internal::finitePoints(points_source);
  if (source.size() < options.min_points || target.size() < options.min_points)
    return internal::failure(init_T_target_source, Status::kTooFewPoints,
                             fmt::format("{} finite source and {} finite target points, {} needed", source.size(),
                                         target.size(), options.min_points));
  if (internal::allSame(source) || target.allIdentical())
    return internal::failure(
        init_T_target_source, Status::kDegenerate,
        internal::allSame(source) ? "all source points are identical" : "all target points are identical");
  if (options.min_source_spacing_m > 0.0) {
    Points2 kept = thinned(source, options.min_source_spacing_m);
    if (kept.size() >= options.min_points) source = std::move(kept);  // (thinning never makes a match fail)
  }
  internal::Icp icp(target, source, options);
  return options.solver == Solver::kCeres ? internal::runCeres(icp, init_T_target_source, options)
                                          : internal::runGaussNewton(icp, init_T_target_source, options);
}

Result alignIcp(const Points2& points_target, const Points2& points_source, const SE2& init_T_target_source,
                const IcpOptions& options) {
  if (const std::string bad = options.check(); !bad.empty())
    return internal::failure(init_T_target_source, Status::kInvalidInput, "invalid option: " + bad);
  return alignIcp(IcpTarget(points_target, options), points_source, init_T_target_source, options);
}

}  // namespace lidar2d::registration
