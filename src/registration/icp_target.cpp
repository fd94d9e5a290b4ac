// IcpTarget: the finite target points, their nearest-neighbour structure and line fits.

#include "src/registration/internal/icp_target.hpp"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "lidar2d/registration/icp.hpp"

namespace lidar2d::registration {

namespace internal {

Points2 finitePoints(const Points2& in) {
  Points2 out;
  out.reserve(in.size());
  for (const auto& p : in)
    if (std::isfinite(p.x()) && std::isfinite(p.y())) out.push_back(p);
  return out;
}

bool allSame(const Points2& pts) {
  if (pts.empty()) return false;
  Eigen::Vector2d lo = pts.front(), hi = pts.front();
  for (const auto& p : pts) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).maxCoeff() <= 1e-9;
}

}  // namespace internal

IcpTarget::Impl::Impl(Points2 pts, const IcpOptions& o) : points(std::move(pts)), identical(internal::allSame(points)) {
  if (o.neighbor_search == NeighborSearch::kKdTree)
    tree = std::make_unique<geometry::KdTree2>(points);
  else
    bearing = std::make_unique<internal::BearingIndex>(points);
  computeNormals(o);
}

// Local line fit per target point (the "local line fit" variant of Censi 2008, section III: the
// line through the nearest target points, here a total-least-squares fit over up to k of them,
// which is less sensitive to range noise than the line through exactly two points).
void IcpTarget::Impl::computeNormals(const IcpOptions& o) {
  normals.assign(points.size(), Eigen::Vector2d::Zero());
  if (o.two_point_lines) {  // (kept only when asked for: a SLAM run holds many targets)
    corner_slots = std::min(kMaxCornerLines, static_cast<std::size_t>(std::max(1, o.normal_neighbors - 1)));
    corner_count.assign(points.size(), 0);
    corner_lines.resize(corner_slots * points.size());
  }
  // No more neighbour slots than points (with more, every point is found either way): idx and d2
  // are k long, and normal_neighbors has no upper bound (SLAM's may come from a config or a state).
  const auto k =
      std::min(static_cast<std::size_t>(std::max(2, o.normal_neighbors)), std::max<std::size_t>(2, points.size()));
  std::vector<std::uint32_t> idx(k);
  std::vector<double> d2(k);
  const double r2 = o.normal_max_radius_m * o.normal_max_radius_m;
  const double flat2 = o.max_line_flatness * o.max_line_flatness;
  auto fit = [&](std::size_t i, const std::uint32_t* idx, const double* d2, std::size_t n) {
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    std::size_t m = 0;
    for (std::size_t j = 0; j < n; ++j)
      if (d2[j] <= r2) {
        mean += points[idx[j]];
        ++m;
      }
    if (m < 2) return;
    mean /= static_cast<double>(m);
    double a = 0, b = 0, c = 0;
    for (std::size_t j = 0; j < n; ++j)
      if (d2[j] <= r2) {
        const Eigen::Vector2d d = points[idx[j]] - mean;
        a += d.x() * d.x();
        b += d.x() * d.y();
        c += d.y() * d.y();
      }
    // Eigenvalues of [[a, b], [b, c]] in closed form; the line direction is the major axis.
    const double half_tr = 0.5 * (a + c);
    const double disc = std::sqrt(0.25 * (a - c) * (a - c) + b * b);
    const double lmax = half_tr + disc;
    const double lmin = std::max(0.0, half_tr - disc);
    if (!(lmax > 1e-18) || lmin > flat2 * lmax) {
      if (corner_count.empty()) return;
      CornerLine* lines = &corner_lines[corner_slots * i];
      std::size_t c = 0;
      for (std::size_t j = 0; j < n && c < corner_slots; ++j) {
        if (idx[j] == i || !(d2[j] <= r2)) continue;
        const Eigen::Vector2d d = points[idx[j]] - points[i];
        const double len = d.norm();
        if (!(len > 0.0)) continue;  // (a duplicate of the point: no line)
        lines[c++] = {idx[j], Eigen::Vector2d(-d.y() / len, d.x() / len)};
      }
      corner_count[i] = static_cast<std::uint8_t>(c);
      return;
    }
    // Normal = eigenvector of lmin: (b, lmin - a) or (lmin - c, b), whichever is better
    // conditioned; sign as (-sin phi, cos phi) with phi = atan2(2b, a - c) / 2 in (-pi/2, pi/2].
    Eigen::Vector2d n1(b, lmin - a), n2(lmin - c, b);
    Eigen::Vector2d nrm = n1.squaredNorm() >= n2.squaredNorm() ? n1 : n2;
    const double len = nrm.norm();
    if (!(len > 0.0)) return;
    nrm /= len;
    if (nrm.y() < 0.0 || (nrm.y() == 0.0 && nrm.x() > 0.0)) nrm = -nrm;
    normals[i] = nrm;
  };
  if (bearing) {
    bearing->knnOfEach(k, r2, idx.data(), d2.data(), fit);
  } else {
    for (std::size_t i = 0; i < points.size(); ++i)  // (the fit drops those beyond the radius)
      fit(i, idx.data(), d2.data(), tree->knn(points[i], k, idx.data(), d2.data()));
  }
}

IcpTarget::IcpTarget(const Points2& points_target, const IcpOptions& options)
    : impl_(std::make_unique<Impl>(internal::finitePoints(points_target), options)) {}
IcpTarget::~IcpTarget() = default;
IcpTarget::IcpTarget(IcpTarget&&) noexcept = default;
IcpTarget& IcpTarget::operator=(IcpTarget&&) noexcept = default;
std::size_t IcpTarget::size() const { return impl_->points.size(); }
const Points2& IcpTarget::points() const { return impl_->points; }
const Points2& IcpTarget::normals() const { return impl_->normals; }
bool IcpTarget::allIdentical() const { return impl_->identical; }
std::size_t IcpTarget::nearest(const Eigen::Vector2d& p, double* dist_sq) const {
  return impl_->nearestWithin(p, std::numeric_limits<double>::infinity(), dist_sq, nullptr);
}
std::size_t IcpTarget::nearestWithin(const Eigen::Vector2d& p, double max_dist_sq, double* dist_sq,
                                     std::uint32_t* hint) const {
  return impl_->nearestWithin(p, max_dist_sq, dist_sq, hint);
}

}  // namespace lidar2d::registration
