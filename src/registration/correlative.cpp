#include "lidar2d/registration/correlative.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <variant>

#include "lidar2d/core/error.hpp"
#include "src/registration/internal/lf_raster.hpp"

namespace lidar2d::registration {

namespace {

constexpr double kMaxCells = 2.0e8;

void requireField(bool ok, const char* field, const std::string& what) {
  if (!ok) throw invalidArgument(what, ErrorLocation({}, 0, field));
}

// The source scan rotated by each searched angle and cut into cells of the grid (Hess 2016,
// "discretized scans"): a translation by whole cells then only adds an integer offset.
struct Discretised {
  SE2 centre;                  // pose of offset (0, 0) at angle offset 0
  double step = 0.0;           // rotation step [rad]
  std::vector<double> angles;  // angle offsets from centre.theta() [rad]
  std::vector<std::vector<Eigen::Vector2i>> cells;  // per angle, per point
  std::vector<Eigen::Vector2i> lo, hi;              // per angle, the box of its cells
  int nx = 0, ny = 0;          // translation offsets in [-nx, nx] x [-ny, ny] cells
};

struct Candidate {
  int k = 0, ix = 0, iy = 0;
  double score = 0.0;
};

double scoreAt(const CorrelativeGrid& g, const Discretised& d, int k, int ix, int iy, int h) {
  const auto kk = static_cast<std::size_t>(k);
  const auto& cells = d.cells[kk];
  return g.sumMaxValues(h, cells, ix, iy, d.lo[kk], d.hi[kk]) / static_cast<double>(cells.size());
}

double angularStep(const CorrelativeOptions& o, const Points2& src, double res) {
  if (o.angular_step_rad > 0.0) return o.angular_step_rad;
  double d_max = res;
  for (const auto& p : src) d_max = std::max(d_max, p.norm());
  // Hess 2016 eq. 7: the farthest point moves by at most one cell per step.
  return std::acos(1.0 - res * res / (2.0 * d_max * d_max));
}

Discretised discretise(const CorrelativeGrid& g, const Points2& src, const SE2& centre, double step, int n_ang_lo,
                       int n_ang_hi, int nx, int ny) {
  Discretised d;
  d.centre = centre;
  d.step = step;
  d.nx = nx;
  d.ny = ny;
  const double inv = 1.0 / g.resolution();
  for (int k = n_ang_lo; k <= n_ang_hi; ++k) {
    const double a = k * step;
    d.angles.push_back(a);
    const SE2 T(centre.x(), centre.y(), centre.theta() + a);
    std::vector<Eigen::Vector2i> cells;
    cells.reserve(src.size());
    for (const auto& p : src) {
      const Eigen::Vector2d q = T * p;
      cells.emplace_back(static_cast<int>(std::floor((q.x() - g.origin().x()) * inv)),
                         static_cast<int>(std::floor((q.y() - g.origin().y()) * inv)));
    }
    const auto [lo, hi] = CorrelativeGrid::boxOf(cells);
    d.lo.push_back(lo);
    d.hi.push_back(hi);
    d.cells.push_back(std::move(cells));
  }
  return d;
}

SE2 poseOf(const CorrelativeGrid& g, const Discretised& d, const Candidate& c) {
  return SE2(d.centre.x() + c.ix * g.resolution(), d.centre.y() + c.iy * g.resolution(),
             d.centre.theta() + d.angles[static_cast<std::size_t>(c.k)]);
}

// Depth-first branch and bound (Hess 2016, algorithm 3): candidates of height h cover the offsets
// [ix, ix + 2^h) x [iy, iy + 2^h); their max-grid score bounds every pose they cover, so a
// candidate whose bound does not beat the best complete score is pruned with all its children.
void branchAndBound(const CorrelativeGrid& g, const Discretised& d, std::vector<Candidate>& cands, int h,
                    Candidate& best, std::size_t& scored) {
  std::sort(cands.begin(), cands.end(), [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  for (const auto& c : cands) {
    if (c.score <= best.score) break;  // sorted: nothing later can win either
    if (h == 0) {
      best = c;
      continue;  // the rest score no higher
    }
    const int s = 1 << (h - 1);
    std::vector<Candidate> children;
    children.reserve(4);
    for (int dx : {0, s}) {
      if (c.ix + dx > d.nx) continue;
      for (int dy : {0, s}) {
        if (c.iy + dy > d.ny) continue;
        Candidate ch{c.k, c.ix + dx, c.iy + dy, 0.0};
        ch.score = scoreAt(g, d, ch.k, ch.ix, ch.iy, h - 1);
        ++scored;
        children.push_back(ch);
      }
    }
    branchAndBound(g, d, children, h - 1, best, scored);
  }
}

CorrelativeResult failure(const SE2& pose, Status status, std::string message) {
  CorrelativeResult r;
  r.T_target_source = pose;
  r.T_search = pose;
  r.status = status;
  r.message = std::move(message);
  return r;
}

// Checks of the inputs shared by all searches; returns the finite source points, or sets `fail`.
Points2 validSource(const Points2& source, const CorrelativeOptions& o, const CorrelativeGrid& g, const SE2& pose,
                    std::optional<CorrelativeResult>& fail) {
  Points2 src;
  src.reserve(source.size());
  for (const auto& p : source)
    if (p.allFinite()) src.push_back(p);
  if (src.size() < o.min_points)
    fail = failure(pose, Status::kTooFewPoints,
                   fmt::format("the source has {} valid points, fewer than min_points = {}", src.size(), o.min_points));
  else if (g.empty())
    fail = failure(pose, Status::kTooFewPoints, "the target has no valid points");
  return src;
}

CorrelativeResult finish(const CorrelativeGrid& g, const Discretised& d, const Candidate& best, const Points2& src,
                         const CorrelativeOptions& o, const LikelihoodField* field, const SE2& fail_pose,
                         std::size_t scored) {
  if (best.score < o.min_score || best.score <= 0.0) {
    auto r = failure(fail_pose, Status::kTooFewInliers,
                     fmt::format("no pose in the window scores above min_score = {}", o.min_score));
    r.candidates_scored = scored;
    return r;
  }
  CorrelativeResult r;
  r.T_search = poseOf(g, d, best);
  r.T_target_source = r.T_search;
  r.score = best.score;
  r.final_cost = best.score;
  r.candidates_scored = scored;
  r.converged = true;
  r.status = Status::kConverged;
  r.num_inliers = src.size();
  if (field != nullptr && o.refine) {
    const Result lf = matchLikelihoodField(*field, src, r.T_search, o.refinement);
    // Refinement only polishes the search's answer: a result that wandered farther than a few search
    // steps is a different local minimum, and the search's (globally best) pose is kept.
    const bool near = (lf.T_target_source.translation() - r.T_search.translation()).norm() <= 3.0 * g.resolution() &&
                      std::abs(angleDiff(lf.T_target_source.theta(), r.T_search.theta())) <= 3.0 * d.step + 1e-3;
    // kMaxIterations still holds a valid estimate: against a map's unsigned field Gauss-Newton can
    // end oscillating by sub-millimetre steps.
    const bool usable = lf.converged || lf.status == Status::kMaxIterations;
    if (usable && near) {
      r.T_target_source = lf.T_target_source;
      r.iterations = lf.iterations;
      r.num_inliers = lf.num_inliers;
      r.information = lf.information;
      r.covariance = lf.covariance;
      r.refined = true;
    } else {
      r.message = fmt::format("refinement not used ({}); the search pose is returned",
                              usable ? "it moved too far" : toString(lf.status));
    }
  }
  return r;
}

}  // namespace

struct CorrelativeGridBuilder {
  /// Builds `g` in place (its vectors keep their capacity); `g` is empty when there are no points.
  static void build(const internal::Polyline& poly, const Points2& all, const CorrelativeOptions& o,
                    CorrelativeGrid& g) {
    Eigen::Vector2d lo = Eigen::Vector2d::Zero(), hi = Eigen::Vector2d::Zero();
    if (!internal::boundingBox(all, lo, hi)) {
      g = CorrelativeGrid();
      return;
    }
    const double res = o.resolution_m, radius = 3.0 * o.blur_sigma_m;
    const double pad = radius + 2.0 * res;
    const Eigen::Vector2d origin = ((lo.array() - pad) / res).floor() * res;
    const double w = std::ceil((hi.x() + pad - origin.x()) / res), h = std::ceil((hi.y() + pad - origin.y()) / res);
    if (w * h > kMaxCells)
      throw invalidArgument(fmt::format("the grid would need {:.0f} x {:.0f} cells; use a coarser resolution", w, h),
                            ErrorLocation({}, 0, "resolution_m"));
    g.resolution_ = res;
    g.origin_ = origin;
    g.width_ = static_cast<int>(w);
    g.height_ = static_cast<int>(h);
    if (g.max_grids_.empty()) g.max_grids_.emplace_back();
    CorrelativeGrid::MaxGrid& m0 = g.max_grids_[0];
    m0.offset = 0;
    m0.width = g.width_;
    m0.height = g.height_;
    m0.values.assign(static_cast<std::size_t>(g.width_) * static_cast<std::size_t>(g.height_), 0.0f);
    std::vector<float>& base = m0.values;
    // Cell centres are the nodes of a grid shifted by half a cell.
    const internal::NodeGrid ng{g.origin_.array() + 0.5 * res, res, g.width_, g.height_};
    const double k = -0.5 / (o.blur_sigma_m * o.blur_sigma_m);
    auto put = [&](int i, int j, double dist) {
      float& v = base[static_cast<std::size_t>(j) * static_cast<std::size_t>(g.width_) + static_cast<std::size_t>(i)];
      v = std::max(v, static_cast<float>(std::exp(k * dist * dist)));
    };
    for (const auto& s : poly.segments) {
      const Eigen::Vector2d lo_s = s.a.cwiseMin(s.b).array() - radius, hi_s = s.a.cwiseMax(s.b).array() + radius;
      internal::forEachNodeInBox(ng, lo_s, hi_s,
                                 [&](int i, int j, const Eigen::Vector2d& q) { put(i, j, internal::segmentDistance(s, q)); });
    }
    for (const auto& p : poly.isolated)
      internal::forEachNodeInBox(ng, p.array() - radius, p.array() + radius,
                                 [&](int i, int j, const Eigen::Vector2d& q) { put(i, j, (q - p).norm()); });
    g.buildMaxGrids(o.depth);
  }
};

namespace {

// out[x] = max(in[x - s], in[x]) for x in [0, n_in + s), where in[] is 0 outside [0, n_in): the
// 1-D step of a max-grid level, as plain loops the compiler vectorises (no bounds check per cell).
void shiftedMax(const float* in, int n_in, int s, float* out) {
  const int n_out = n_in + s;
  for (int x = 0; x < std::min(s, n_in); ++x) out[x] = in[x];
  for (int x = n_in; x < s; ++x) out[x] = 0.0f;  // rows narrower than s
  for (int x = s; x < n_in; ++x) out[x] = std::max(in[x - s], in[x]);
  for (int x = std::max(n_in, s); x < n_out; ++x) out[x] = in[x - s];
}

}  // namespace

void CorrelativeGrid::buildMaxGrids(int depth) {
  max_grids_.resize(static_cast<std::size_t>(std::max(depth, 1)));
  std::vector<float> rows;  // the row pass of one level
  for (int h = 1; h < depth; ++h) {
    // M_h(i, j) = max of M_{h-1} at (i, j), (i + s, j), (i, j + s), (i + s, j + s), s = 2^(h-1):
    // the window [i, i + 2^h) is the union of the two windows of half the size. Defined for
    // i in [-(2^h - 1), width) so that every window touching the grid has a value. Separable: a
    // max along x with shift s, then along y. Level h's offset 2^h - 1 is level h-1's plus s, so
    // index x of level h holds M_{h-1}'s indices x - s and x.
    const int s = 1 << (h - 1);
    const MaxGrid& p = max_grids_[static_cast<std::size_t>(h - 1)];
    MaxGrid& m = max_grids_[static_cast<std::size_t>(h)];
    m.offset = (1 << h) - 1;
    m.width = width_ + m.offset;
    m.height = height_ + m.offset;
    rows.resize(static_cast<std::size_t>(m.width) * static_cast<std::size_t>(p.height));
    for (int y = 0; y < p.height; ++y)
      shiftedMax(p.values.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(p.width), p.width, s,
                 rows.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(m.width));
    m.values.resize(static_cast<std::size_t>(m.width) * static_cast<std::size_t>(m.height));
    // Along y, row by row (the inner loop runs along x, contiguous in memory).
    const auto row = [&](std::vector<float>& v, int y, int width) {
      return v.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(width);
    };
    for (int y = 0; y < m.height; ++y) {
      float* out = row(m.values, y, m.width);
      const bool lo_in = y - s >= 0 && y - s < p.height, hi_in = y < p.height;
      const float* a = lo_in ? row(rows, y - s, m.width) : nullptr;
      const float* b = hi_in ? row(rows, y, m.width) : nullptr;
      if (a && b)
        for (int x = 0; x < m.width; ++x) out[x] = std::max(a[x], b[x]);
      else if (a || b)
        std::copy_n(a ? a : b, m.width, out);
      else
        std::fill_n(out, m.width, 0.0f);
    }
  }
}

void CorrelativeOptions::validate() const {
  requireField(std::isfinite(resolution_m) && resolution_m > 0.0, "resolution_m", "must be finite and > 0");
  requireField(std::isfinite(blur_sigma_m) && blur_sigma_m > 0.0, "blur_sigma_m", "must be finite and > 0");
  requireField(std::isfinite(connect_max_gap_m) && connect_max_gap_m >= 0.0, "connect_max_gap_m", "must be finite and >= 0");
  requireField(occupied_min >= 1 && occupied_min <= 100, "occupied_min", "must be in 1..100");
  requireField(depth >= 1 && depth <= 16, "depth", "must be in 1..16");
  requireField(std::isfinite(linear_window_m) && linear_window_m >= 0.0 && linear_window_m / resolution_m < 1e6,
               "linear_window_m", "must be finite, >= 0 and below 10^6 cells");
  requireField(std::isfinite(angular_window_rad) && angular_window_rad >= 0.0 && angular_window_rad <= std::numbers::pi,
               "angular_window_rad", "must be in [0, pi]");
  requireField(std::isfinite(angular_step_rad) && angular_step_rad >= 0.0 && (angular_step_rad == 0.0 || angular_step_rad >= 1e-6),
               "angular_step_rad", "must be 0 (automatic) or in [1e-6, inf)");
  requireField(std::isfinite(min_score) && min_score >= 0.0 && min_score <= 1.0, "min_score", "must be in [0, 1]");
  requireField(min_points >= 1, "min_points", "must be >= 1");
  if (refine) refinement.validate();
}

CorrelativeGrid CorrelativeGrid::fromPoints(const Points2& target, const CorrelativeOptions& options) {
  CorrelativeGrid g;
  g.rebuild(target, options);
  return g;
}

void CorrelativeGrid::rebuild(const Points2& target, const CorrelativeOptions& options) {
  options.validate();
  CorrelativeGridBuilder::build(internal::makePolyline(target, options.connect_max_gap_m), target, options, *this);
}

CorrelativeGrid CorrelativeGrid::fromMap(const OccupancyImage& map, const CorrelativeOptions& options) {
  options.validate();
  internal::Polyline poly;
  for (int row = 0; row < map.height(); ++row)
    for (int col = 0; col < map.width(); ++col)
      if (map.at(col, row) >= options.occupied_min) poly.isolated.push_back(map.cellCenter(col, row));
  CorrelativeGrid g;
  CorrelativeGridBuilder::build(poly, poly.isolated, options, g);
  return g;
}

namespace {

// Branch and bound over a discretised window (Hess et al. 2016, algorithm 3): the coarsest-level
// candidates over translations [-nx, nx] x [-ny, ny] cells and every discretised angle, then the
// depth-first search, then the result (with refinement). Shared by the local and global searches.
CorrelativeResult searchDiscretised(const CorrelativeGrid& grid, const Discretised& d, int nx, int ny,
                                    const Points2& src, const CorrelativeOptions& options,
                                    const LikelihoodField* refine_field, const SE2& init) {
  const int H = grid.depth() - 1;
  std::vector<Candidate> top;
  std::size_t scored = 0;
  for (int k = 0; k < static_cast<int>(d.angles.size()); ++k)
    for (int ix = -nx; ix <= nx; ix += 1 << H)
      for (int iy = -ny; iy <= ny; iy += 1 << H) {
        top.push_back({k, ix, iy, scoreAt(grid, d, k, ix, iy, H)});
        ++scored;
      }
  // Starting from min_score prunes every branch that cannot reach it (the answer is the same: a
  // best below it fails anyway), which is most of a search in ground the target does not hold.
  Candidate best{0, 0, 0, std::max(-1.0, options.min_score - 1e-12)};
  branchAndBound(grid, d, top, H, best, scored);
  return finish(grid, d, best, src, options, refine_field, init, scored);
}

}  // namespace

namespace {

// The search window around `init` shared by the branch-and-bound and the exhaustive search: the
// valid source points, and the angles and translations of +-angular_window x +-linear_window
// discretised (`nl` cells each way). Returns the failure result instead when the input is unusable.
struct LocalWindow {
  Points2 src;
  int nl = 0;
  Discretised d;
};
std::variant<LocalWindow, CorrelativeResult> localWindow(const CorrelativeGrid& grid, const Points2& source,
                                                         const SE2& init, const CorrelativeOptions& options) {
  options.validate();
  if (!init.isFinite()) return failure(SE2(), Status::kInvalidInput, "the initial guess is not finite");
  std::optional<CorrelativeResult> fail;
  LocalWindow w;
  w.src = validSource(source, options, grid, init, fail);
  if (fail) return *fail;
  const double step = angularStep(options, w.src, grid.resolution());
  const int na = static_cast<int>(std::ceil(options.angular_window_rad / step - 1e-9));
  w.nl = static_cast<int>(std::ceil(options.linear_window_m / grid.resolution() - 1e-9));
  w.d = discretise(grid, w.src, init, step, -na, na, w.nl, w.nl);
  return w;
}

}  // namespace

CorrelativeResult matchCorrelative(const CorrelativeGrid& grid, const Points2& source, const SE2& init,
                                   const CorrelativeOptions& options, const LikelihoodField* refine_field) {
  auto window = localWindow(grid, source, init, options);
  if (auto* fail = std::get_if<CorrelativeResult>(&window)) return *fail;
  const LocalWindow& w = std::get<LocalWindow>(window);
  return searchDiscretised(grid, w.d, w.nl, w.nl, w.src, options, refine_field, init);
}

CorrelativeResult matchCorrelativeGlobal(const CorrelativeGrid& grid, const Points2& source,
                                         const CorrelativeOptions& options, const LikelihoodField* refine_field) {
  options.validate();
  std::optional<CorrelativeResult> fail;
  const Points2 src = validSource(source, options, grid, SE2(), fail);
  if (fail) return *fail;
  const double res = grid.resolution();
  const SE2 centre(grid.origin().x() + 0.5 * grid.width() * res, grid.origin().y() + 0.5 * grid.height() * res, 0.0);
  const double step = angularStep(options, src, res);
  const int na = static_cast<int>(std::ceil(std::numbers::pi / step));
  const int nx = grid.width() / 2 + 1, ny = grid.height() / 2 + 1;
  const auto d = discretise(grid, src, centre, step, -na, na - 1, nx, ny);
  return searchDiscretised(grid, d, nx, ny, src, options, refine_field, SE2());
}

CorrelativeResult matchCorrelative(const Points2& target, const Points2& source, const SE2& init,
                                   const CorrelativeOptions& options) {
  const auto grid = CorrelativeGrid::fromPoints(target, options);
  if (!options.refine) return matchCorrelative(grid, source, init, options, nullptr);
  const auto field = LikelihoodField::fromPoints(target, options.refinement);
  return matchCorrelative(grid, source, init, options, &field);
}

CorrelativeResult matchCorrelativeExhaustive(const CorrelativeGrid& grid, const Points2& source, const SE2& init,
                                             const CorrelativeOptions& options) {
  auto window = localWindow(grid, source, init, options);
  if (auto* fail = std::get_if<CorrelativeResult>(&window)) return *fail;
  const auto& [src, nl, d] = std::get<LocalWindow>(window);
  Candidate best{0, 0, 0, -1.0};
  std::size_t scored = 0;
  for (int k = 0; k < static_cast<int>(d.angles.size()); ++k)
    for (int ix = -nl; ix <= nl; ++ix)
      for (int iy = -nl; iy <= nl; ++iy) {
        const double s = scoreAt(grid, d, k, ix, iy, 0);
        ++scored;
        if (s > best.score) best = {k, ix, iy, s};
      }
  CorrelativeOptions no_refine = options;
  no_refine.refine = false;
  return finish(grid, d, best, src, no_refine, nullptr, init, scored);
}

}  // namespace lidar2d::registration
