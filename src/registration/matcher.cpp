#include "lidar2d/registration/matcher.hpp"

#include <string>
#include <utility>

#include "lidar2d/core/error.hpp"

namespace lidar2d::registration {

const char* toString(Method m) {
  switch (m) {
    case Method::kP2P:
      return "p2p";
    case Method::kP2L:
      return "p2l";
    case Method::kLikelihoodField:
      return "lf";
    case Method::kCorrelative:
      return "corr";
  }
  return "unknown";
}

std::optional<Method> parseMethod(const std::string& name) {
  for (Method m : {Method::kP2P, Method::kP2L, Method::kLikelihoodField, Method::kCorrelative})
    if (name == toString(m)) return m;
  return std::nullopt;
}

std::optional<Solver> parseSolver(const std::string& name) {
  for (Solver s : {Solver::kGaussNewton, Solver::kCeres})
    if (name == toString(s)) return s;
  return std::nullopt;
}

namespace {

IcpOptions icpOptions(const MatcherOptions& o) {
  IcpOptions icp = o.icp;
  icp.metric = o.method == Method::kP2P ? IcpMetric::kPointToPoint : IcpMetric::kPointToLine;
  icp.solver = o.solver;
  return icp;
}

LfSolver lfSolver(Solver s) { return s == Solver::kCeres ? LfSolver::kCeres : LfSolver::kGaussNewton; }

LikelihoodFieldOptions lfOptions(const MatcherOptions& o) {
  LikelihoodFieldOptions lf = o.lf;
  lf.solver = lfSolver(o.solver);
  return lf;
}

CorrelativeOptions corrOptions(const MatcherOptions& o) {
  CorrelativeOptions c = o.corr;
  c.refinement.solver = lfSolver(o.solver);
  return c;
}

Result invalid(const SE2& init, std::string message) {
  Result r;
  r.T_target_source = init.isFinite() ? init : SE2();
  r.status = Status::kInvalidInput;
  r.message = std::move(message);
  return r;
}

}  // namespace

PreparedTarget::PreparedTarget(const Points2& points_target, const MatcherOptions& options)
    : method_(options.method), points_(points_target) {
  switch (options.method) {
    case Method::kP2P:
    case Method::kP2L:
      icp_ = std::make_unique<IcpTarget>(points_, icpOptions(options));
      break;
    case Method::kLikelihoodField:
    case Method::kCorrelative:
      // The field and grid builders throw for out-of-domain options; a PreparedTarget never
      // throws, so the reason is kept and reported by matchScans.
      try {
        if (options.method == Method::kLikelihoodField) {
          field_ = std::make_unique<LikelihoodField>(LikelihoodField::fromPoints(points_, lfOptions(options)));
        } else {
          const CorrelativeOptions corr = corrOptions(options);
          grid_ = std::make_unique<CorrelativeGrid>(CorrelativeGrid::fromPoints(points_, corr));
          if (corr.refine)
            field_ = std::make_unique<LikelihoodField>(LikelihoodField::fromPoints(points_, corr.refinement));
        }
      } catch (const Error& e) {
        error_ = e.what();
      }
      break;
  }
}

PreparedTarget PreparedTarget::fromMap(const OccupancyImage& map, const MatcherOptions& options) {
  PreparedTarget t(options.method);
  t.from_map_ = true;
  const int occupied_min = options.map_occupied_min;
  if (!(occupied_min >= 1 && occupied_min <= 100)) {
    t.error_ = "MatcherOptions.map_occupied_min: must be in 1..100, got " + std::to_string(occupied_min);
    return t;
  }
  switch (options.method) {
    case Method::kP2P:
    case Method::kP2L:
      // See the header: matched against cell centres, ICP is biased by up to half a cell and
      // point-to-line finds no lines along walls drawn several cells thick.
      t.error_ = std::string("an occupancy map is matched with lf or corr, not ") + toString(options.method) +
                 " (ICP matches point sets: build an IcpTarget from points, e.g. the scans of a local map)";
      return t;
    case Method::kLikelihoodField:
    case Method::kCorrelative:
      try {
        if (options.method == Method::kLikelihoodField) {
          LikelihoodFieldOptions lf = lfOptions(options);
          lf.occupied_min = occupied_min;
          t.field_ = std::make_unique<LikelihoodField>(LikelihoodField::fromMap(map, lf));
        } else {
          CorrelativeOptions corr = corrOptions(options);
          corr.occupied_min = occupied_min;
          corr.refinement.occupied_min = occupied_min;
          t.grid_ = std::make_unique<CorrelativeGrid>(CorrelativeGrid::fromMap(map, corr));
          if (corr.refine)
            t.field_ = std::make_unique<LikelihoodField>(LikelihoodField::fromMap(map, corr.refinement));
        }
      } catch (const Error& e) {
        t.error_ = e.what();
      }
      break;
  }
  return t;
}

PreparedTarget::~PreparedTarget() = default;
PreparedTarget::PreparedTarget(PreparedTarget&&) noexcept = default;
PreparedTarget& PreparedTarget::operator=(PreparedTarget&&) noexcept = default;

Result matchScans(const PreparedTarget& target, const Points2& source, const SE2& init_T_target_source,
                  const MatcherOptions& options) {
  if (target.method() != options.method)
    return invalid(init_T_target_source, std::string("target prepared for method ") + toString(target.method()) +
                                             ", matched with " + toString(options.method));
  if (!target.error().empty()) return invalid(init_T_target_source, target.error());
  switch (options.method) {
    case Method::kP2P:
    case Method::kP2L:
      return alignIcp(*target.icp(), source, init_T_target_source, icpOptions(options));
    case Method::kLikelihoodField:
    case Method::kCorrelative:
      try {
        LikelihoodFieldOptions lf = lfOptions(options);
        CorrelativeOptions corr = corrOptions(options);
        if (target.isMap()) lf.line_search = corr.refinement.line_search = true;  // (see fromMap)
        if (options.method == Method::kLikelihoodField)
          return matchLikelihoodField(*target.field(), source, init_T_target_source, lf);
        return matchCorrelative(*target.grid(), source, init_T_target_source, corr, target.field());
      } catch (const Error& e) {
        return invalid(init_T_target_source, e.what());
      }
  }
  return invalid(init_T_target_source, "unknown method");
}

Result matchScans(const Points2& target, const Points2& source, const SE2& init_T_target_source,
                  const MatcherOptions& options) {
  return matchScans(PreparedTarget(target, options), source, init_T_target_source, options);
}

}  // namespace lidar2d::registration
