#include "lidar2d/sim/world.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <numbers>

#include "lidar2d/core/error.hpp"

namespace lidar2d::sim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kTwoPi = 2.0 * std::numbers::pi;
// Primitives are registered in every grid cell their bounding box, grown by this margin, touches.
// The margin absorbs the rounding of the grid traversal's cell-boundary parameters, so the cell the
// traversal is in when it reaches a hit point always lists the primitive hit there.
constexpr double kRegisterMargin = 1e-6;  // [m]

double cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }

// True when the direction angle phi (of a point relative to the arc's centre) lies on the arc.
// A tolerance of 1e-12 rad keeps the end points on the arc despite atan2's rounding.
bool onArc(const Arc& a, double phi) {
  if (a.sweep_rad >= kTwoPi) return true;
  double d = std::fmod(phi - a.start_rad, kTwoPi);
  if (d < 0) d += kTwoPi;
  return d <= a.sweep_rad + 1e-12 || d >= kTwoPi - 1e-12;
}

Eigen::Vector2d arcPoint(const Arc& a, double phi) {
  return a.center + a.radius_m * Eigen::Vector2d(std::cos(phi), std::sin(phi));
}

double segmentDistance(const Segment& s, const Eigen::Vector2d& p) {
  const Eigen::Vector2d e = s.b - s.a;
  const double f = std::clamp((p - s.a).dot(e) / e.squaredNorm(), 0.0, 1.0);
  return (s.a + f * e - p).norm();
}

double arcDistance(const Arc& a, const Eigen::Vector2d& p) {
  const Eigen::Vector2d m = p - a.center;
  if (onArc(a, std::atan2(m.y(), m.x()))) return std::abs(m.norm() - a.radius_m);
  return std::min((arcPoint(a, a.start_rad) - p).norm(), (arcPoint(a, a.start_rad + a.sweep_rad) - p).norm());
}

bool finite(const Eigen::Vector2d& v) { return std::isfinite(v.x()) && std::isfinite(v.y()); }

}  // namespace

Arc Arc::circle(const Eigen::Vector2d& center, double radius_m) { return Arc{center, radius_m, 0.0, kTwoPi}; }

double intersectSegment(const Segment& s, const Eigen::Vector2d& origin, const Eigen::Vector2d& dir) {
  // origin + t*dir = a + u*(b - a); Cramer's rule with 2D cross products.
  const Eigen::Vector2d e = s.b - s.a;
  const double denom = cross(dir, e);
  if (denom == 0.0) return kInf;
  const Eigen::Vector2d w = s.a - origin;
  const double t = cross(w, e) / denom;
  const double u = cross(w, dir) / denom;
  if (t >= 0.0 && u >= 0.0 && u <= 1.0) return t;
  return kInf;
}

double intersectArc(const Arc& a, const Eigen::Vector2d& origin, const Eigen::Vector2d& dir) {
  // |m + t*dir|^2 = r^2 with m = origin - centre and |dir| = 1: t^2 + 2bt + c = 0.
  const Eigen::Vector2d m = origin - a.center;
  const double b = dir.dot(m);
  const double c = m.squaredNorm() - a.radius_m * a.radius_m;
  double disc = b * b - c;
  if (disc < 0.0) {
    // A tangent ray can come out slightly negative by rounding; count it as touching.
    if (disc < -1e-12 * (b * b + a.radius_m * a.radius_m)) return kInf;
    disc = 0.0;
  }
  const double sq = std::sqrt(disc);
  for (const double t : {-b - sq, -b + sq}) {
    if (t < 0.0) continue;
    const Eigen::Vector2d p = m + t * dir;
    if (onArc(a, std::atan2(p.y(), p.x()))) return t;
  }
  return kInf;
}

World::World(std::vector<Segment> segments, std::vector<Arc> arcs, std::string name, const WorldOptions& options)
    : segments_(std::move(segments)), arcs_(std::move(arcs)), name_(std::move(name)) {
  const ErrorLocation where({}, 0, "world " + name_);
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    const Segment& s = segments_[i];
    if (!finite(s.a) || !finite(s.b) || (s.b - s.a).norm() <= 0.0)
      throw invalidArgument(fmt::format("segment {} is not finite or has zero length", i), where);
  }
  for (std::size_t i = 0; i < arcs_.size(); ++i) {
    const Arc& a = arcs_[i];
    if (!finite(a.center) || !std::isfinite(a.radius_m) || !(a.radius_m > 0.0) || !std::isfinite(a.start_rad) ||
        !std::isfinite(a.sweep_rad) || !(a.sweep_rad > 0.0))
      throw invalidArgument(fmt::format("arc {} is not finite, or its radius or sweep is not positive", i), where);
  }
  if (!(options.cell_size_m >= 0.0) || !std::isfinite(options.cell_size_m))
    throw invalidArgument("cell_size_m must be >= 0", where);
  const std::size_t n = numPrimitives();
  if (n == 0) return;
  if (n >= std::numeric_limits<std::uint32_t>::max()) throw invalidArgument("too many primitives", where);

  // Bounding boxes (arcs: the whole circle's box, a cheap conservative bound).
  std::vector<Eigen::Vector2d> lo(n), hi(n);
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    lo[i] = segments_[i].a.cwiseMin(segments_[i].b);
    hi[i] = segments_[i].a.cwiseMax(segments_[i].b);
  }
  for (std::size_t i = 0; i < arcs_.size(); ++i) {
    const Eigen::Vector2d r = Eigen::Vector2d::Constant(arcs_[i].radius_m);
    lo[segments_.size() + i] = arcs_[i].center - r;
    hi[segments_.size() + i] = arcs_[i].center + r;
  }
  min_ = lo[0];
  max_ = hi[0];
  for (std::size_t i = 1; i < n; ++i) {
    min_ = min_.cwiseMin(lo[i]);
    max_ = max_.cwiseMax(hi[i]);
  }
  const Eigen::Vector2d grid_min = min_ - Eigen::Vector2d::Constant(2 * kRegisterMargin);
  const Eigen::Vector2d extent = (max_ - min_) + Eigen::Vector2d::Constant(4 * kRegisterMargin);
  double h = options.cell_size_m;
  if (h == 0.0) {
    h = std::clamp(std::sqrt(std::max(extent.x(), 1e-3) * std::max(extent.y(), 1e-3) / static_cast<double>(n)), 0.05,
                   5.0);
  }
  constexpr double kMaxCells = 4e6;
  if ((extent.x() / h + 1) * (extent.y() / h + 1) > kMaxCells) h = std::sqrt(extent.x() * extent.y() / kMaxCells) * 1.01;
  cell_ = h;
  nx_ = std::max(1, static_cast<int>(std::ceil(extent.x() / h)));
  ny_ = std::max(1, static_cast<int>(std::ceil(extent.y() / h)));
  gmin_ = grid_min;
  gmax_ = grid_min + Eigen::Vector2d(nx_ * h, ny_ * h);

  auto cellRange = [&](std::size_t i, int& x0, int& x1, int& y0, int& y1) {
    x0 = std::clamp(static_cast<int>(std::floor((lo[i].x() - kRegisterMargin - gmin_.x()) / h)), 0, nx_ - 1);
    x1 = std::clamp(static_cast<int>(std::floor((hi[i].x() + kRegisterMargin - gmin_.x()) / h)), 0, nx_ - 1);
    y0 = std::clamp(static_cast<int>(std::floor((lo[i].y() - kRegisterMargin - gmin_.y()) / h)), 0, ny_ - 1);
    y1 = std::clamp(static_cast<int>(std::floor((hi[i].y() + kRegisterMargin - gmin_.y()) / h)), 0, ny_ - 1);
  };
  const std::size_t cells = static_cast<std::size_t>(nx_) * static_cast<std::size_t>(ny_);
  cell_start_.assign(cells + 1, 0);
  for (std::size_t i = 0; i < n; ++i) {
    int x0, x1, y0, y1;
    cellRange(i, x0, x1, y0, y1);
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) ++cell_start_[static_cast<std::size_t>(y) * nx_ + x + 1];
  }
  for (std::size_t c = 0; c < cells; ++c) cell_start_[c + 1] += cell_start_[c];
  ids_.resize(cell_start_[cells]);
  std::vector<std::uint32_t> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (std::size_t i = 0; i < n; ++i) {
    int x0, x1, y0, y1;
    cellRange(i, x0, x1, y0, y1);
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) ids_[fill[static_cast<std::size_t>(y) * nx_ + x]++] = static_cast<std::uint32_t>(i);
  }
}

double World::hitPrimitive(std::uint32_t id, const Eigen::Vector2d& origin, const Eigen::Vector2d& dir) const {
  if (id < segments_.size()) return intersectSegment(segments_[id], origin, dir);
  return intersectArc(arcs_[id - segments_.size()], origin, dir);
}

double World::castRay(const Eigen::Vector2d& origin, double angle_rad, double max_range_m) const {
  return castRay(origin, Eigen::Vector2d(std::cos(angle_rad), std::sin(angle_rad)), max_range_m);
}

double World::castRayBruteForce(const Eigen::Vector2d& origin, const Eigen::Vector2d& dir, double max_range_m) const {
  double best = kInf;
  const auto n = static_cast<std::uint32_t>(numPrimitives());
  for (std::uint32_t i = 0; i < n; ++i) {
    const double t = hitPrimitive(i, origin, dir);
    if (t < best && t <= max_range_m) best = t;
  }
  return best;
}

double World::castRay(const Eigen::Vector2d& p, const Eigen::Vector2d& d, double max_range_m) const {
  assert(std::abs(d.norm() - 1.0) < 1e-6);
  if (nx_ == 0 || !(max_range_m >= 0.0)) return kInf;
  // Clip the ray to the grid's box (slab method); every primitive lies inside the box.
  double t0 = 0.0, t1 = max_range_m;
  for (int k = 0; k < 2; ++k) {
    if (d[k] == 0.0) {
      if (p[k] < gmin_[k] || p[k] > gmax_[k]) return kInf;
      continue;
    }
    double ta = (gmin_[k] - p[k]) / d[k], tb = (gmax_[k] - p[k]) / d[k];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (t0 > t1) return kInf;

  // Grid traversal (Amanatides & Woo 1987, "A fast voxel traversal algorithm for ray tracing").
  const double h = cell_;
  const Eigen::Vector2d q = p + t0 * d;
  int ix = std::clamp(static_cast<int>(std::floor((q.x() - gmin_.x()) / h)), 0, nx_ - 1);
  int iy = std::clamp(static_cast<int>(std::floor((q.y() - gmin_.y()) / h)), 0, ny_ - 1);
  const int step_x = d.x() > 0 ? 1 : -1, step_y = d.y() > 0 ? 1 : -1;
  double t_max_x = kInf, t_max_y = kInf, t_delta_x = kInf, t_delta_y = kInf;
  if (d.x() != 0.0) {
    t_max_x = (gmin_.x() + (ix + (d.x() > 0 ? 1 : 0)) * h - p.x()) / d.x();
    t_delta_x = h / std::abs(d.x());
  }
  if (d.y() != 0.0) {
    t_max_y = (gmin_.y() + (iy + (d.y() > 0 ? 1 : 0)) * h - p.y()) / d.y();
    t_delta_y = h / std::abs(d.y());
  }
  double best = kInf;
  for (;;) {
    const std::size_t c = static_cast<std::size_t>(iy) * nx_ + ix;
    for (std::uint32_t k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
      const double t = hitPrimitive(ids_[k], p, d);
      if (t < best && t <= max_range_m) best = t;
    }
    const double t_exit = std::min(t_max_x, t_max_y);
    // A hit inside this cell cannot be beaten by a later cell: stop. Hits beyond this cell are kept
    // as candidates, because a primitive spanning several cells can be met before its nearest point.
    if (best <= t_exit || t_exit > t1) break;
    if (t_max_x < t_max_y) {
      ix += step_x;
      t_max_x += t_delta_x;
      if (ix < 0 || ix >= nx_) break;
    } else {
      iy += step_y;
      t_max_y += t_delta_y;
      if (iy < 0 || iy >= ny_) break;
    }
  }
  return best;
}

double World::distance(const Eigen::Vector2d& p) const {
  double best = kInf;
  for (const Segment& s : segments_) best = std::min(best, segmentDistance(s, p));
  for (const Arc& a : arcs_) best = std::min(best, arcDistance(a, p));
  return best;
}

}  // namespace lidar2d::sim
