#include "lidar2d/registration/icp.hpp"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <vector>

#include "src/registration/internal/bearing_index.hpp"
#include "src/registration/internal/ceres_common.hpp"
#include "src/geometry/kdtree2.hpp"

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
  if (!(std::isfinite(point_pair_weight) && point_pair_weight >= 0.0)) return "point_pair_weight must be finite and >= 0";
  if (!(std::isfinite(min_source_spacing_m) && min_source_spacing_m >= 0.0))
    return "min_source_spacing_m must be finite and >= 0";
  return {};
}

// ---------------------------------------------------------------------------------------------
// Prepared target

namespace {

Points2 finitePoints(const Points2& in) {
  Points2 out;
  out.reserve(in.size());
  for (const auto& p : in)
    if (std::isfinite(p.x()) && std::isfinite(p.y())) out.push_back(p);
  return out;
}

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

bool allSame(const Points2& pts) {
  if (pts.empty()) return false;
  Eigen::Vector2d lo = pts.front(), hi = pts.front();
  for (const auto& p : pts) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).maxCoeff() <= 1e-9;
}

}  // namespace

struct IcpTarget::Impl {
  Points2 points;
  Points2 normals;
  bool identical = false;
  std::unique_ptr<geometry::KdTree2> tree;         // NeighborSearch::kKdTree
  std::unique_ptr<internal::BearingIndex> bearing;  // NeighborSearch::kBearingWalk
  // Point-to-line's two-point lines (IcpOptions::two_point_lines): for each point whose
  // neighbourhood fits no line, the line through it and each of its fitted neighbours (those
  // within normal_max_radius_m; the nearest kMaxCornerLines at most), nearest first:
  // corner_count[i] entries from corner_slots * i.
  static constexpr std::size_t kMaxCornerLines = 8;
  struct CornerLine {
    std::uint32_t neighbor;  // index of the neighbour
    Eigen::Vector2d normal;  // unit normal of the line through the point and the neighbour
  };
  std::size_t corner_slots = 0;
  std::vector<std::uint8_t> corner_count;
  std::vector<CornerLine> corner_lines;

  Impl(Points2 pts, const IcpOptions& o) : points(std::move(pts)), identical(allSame(points)) {
    if (o.neighbor_search == NeighborSearch::kKdTree)
      tree = std::make_unique<geometry::KdTree2>(points);
    else
      bearing = std::make_unique<internal::BearingIndex>(points);
    computeNormals(o);
  }

  [[gnu::always_inline]] std::size_t nearestWithin(const Eigen::Vector2d& p, double max_dist_sq, double* dist_sq,
                                                   std::uint32_t* hint) const {
    if (!p.allFinite()) {
      *dist_sq = std::numeric_limits<double>::infinity();
      return points.size();
    }
    if (bearing) return bearing->nearest(p, max_dist_sq, dist_sq, hint);
    const std::size_t j = tree->nearest(p, dist_sq);
    if (*dist_sq <= max_dist_sq) return j;
    *dist_sq = std::numeric_limits<double>::infinity();
    return points.size();
  }

  // Local line fit per target point (the "local line fit" variant of Censi 2008, section III: the
  // line through the nearest target points, here a total-least-squares fit over up to k of them,
  // which is less sensitive to range noise than the line through exactly two points).
  void computeNormals(const IcpOptions& o) {
    normals.assign(points.size(), Eigen::Vector2d::Zero());
    if (o.two_point_lines) {  // (kept only when asked for: a SLAM run holds many targets)
      corner_slots = std::min(kMaxCornerLines, static_cast<std::size_t>(std::max(1, o.normal_neighbors - 1)));
      corner_count.assign(points.size(), 0);
      corner_lines.resize(corner_slots * points.size());
    }
    const auto k = static_cast<std::size_t>(std::max(2, o.normal_neighbors));
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
};

IcpTarget::IcpTarget(const Points2& points_target, const IcpOptions& options)
    : impl_(std::make_unique<Impl>(finitePoints(points_target), options)) {}
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

// ---------------------------------------------------------------------------------------------
// Matching

namespace {

struct Pair {
  std::uint32_t src = 0;
  std::uint32_t tgt = 0;
  double key = 0.0;  // squared residual used for trimming [m^2]
};

// Normal equations of one linearisation (Gauss-Newton: H = sum w J^T J, g = sum w J^T r).
struct Linearisation {
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  double cost = 0.0;      // 0.5 * sum rho(r^2) [m^2]
  double wr2 = 0.0;       // sum w r^2 [m^2]
  std::size_t residuals = 0;
  // H without point-to-line's two-point lines (with the cost only): the information reported.
  Eigen::Matrix3d H_info = Eigen::Matrix3d::Zero();
};

// True when a target point has no line (its normal is (0, 0): see IcpTarget::normals).
bool hasNoLine(const Eigen::Vector2d& n) { return n.x() == 0.0 && n.y() == 0.0; }

class Icp {
 public:
  Icp(const IcpTarget& target, const Points2& source, const IcpOptions& o)
      : tgt_(target.impl()),
        src_(source),
        o_(o),
        p2l_(o.metric == IcpMetric::kPointToLine),
        two_point_(p2l_ && o.two_point_lines && !tgt_.corner_count.empty()),
        point_w_(p2l_ ? o.point_pair_weight : 0.0) {
    pairs_.reserve(src_.size());
    if (p2l_) {
      lines_.reserve(2 * src_.size());
      normal_.resize(src_.size());
      via_corner_.assign(src_.size(), 0);
    }
  }

  // Pairs each transformed source point with its nearest target point; rejects by distance (and,
  // for point-to-line, target points without a line), then keeps the closest fraction.
  void findPairs(const SE2& T) {
    pairs_.clear();
    const double gate2 = o_.max_correspondence_dist_m * o_.max_correspondence_dist_m;
    const Points2& tp = tgt_.points;
    const Points2& tn = tgt_.normals;
    if (last_match_.size() != src_.size()) {
      last_match_.assign(src_.size(), tp.size());
      hints_.assign(src_.size(), kNoHint);
    }
    // Search hints: each point's own from the last search, else (first search) the previous
    // point's, as a scan's points come in bearing order.
    std::uint32_t running_hint = kNoHint;
    for (std::size_t i = 0; i < src_.size(); ++i) {
      const Eigen::Vector2d q = T * src_[i];
      // The previous iteration's partner bounds the nearest distance (the search stays exact and
      // visits fewer points once the pose settles).
      double bound2 = gate2;
      if (const std::size_t prev = last_match_[i]; prev < tp.size()) bound2 = std::min(gate2, (q - tp[prev]).squaredNorm());
      double d2 = 0.0;
      std::uint32_t& hint = hints_[i];
      if (hint == kNoHint) hint = running_hint;
      const std::size_t j = tgt_.nearestWithin(q, bound2, &d2, &hint);  // (inlined: no call per query)
      running_hint = hint;
      last_match_[i] = j;
      if (j == tp.size()) continue;
      double key = d2;
      if (p2l_) {
        const Eigen::Vector2d* n = &tn[j];
        via_corner_[i] = 0;
        if (hasNoLine(*n) && two_point_) {
          // The line through the target point and whichever of its fitted neighbours is nearest
          // to q (Censi's two nearest points; ties to the neighbour nearer the target point).
          const auto* c = &tgt_.corner_lines[tgt_.corner_slots * j];
          double best2 = std::numeric_limits<double>::infinity();
          for (std::size_t k = 0, e = tgt_.corner_count[j]; k < e; ++k)
            if (const double dn2 = (tp[c[k].neighbor] - q).squaredNorm(); dn2 < best2) {
              best2 = dn2;
              n = &c[k].normal;
              via_corner_[i] = 1;
            }
        }
        normal_[i] = *n;
        if (hasNoLine(*n)) {
          if (point_w_ == 0.0) continue;
          key = point_w_ * point_w_ * d2;  // (the pair's two residuals, squared and summed)
        } else {
          const double r = n->dot(q - tp[j]);
          key = r * r;
        }
      }
      pairs_.push_back({static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j), key});
    }
    if (o_.trim_keep_fraction < 1.0 && pairs_.size() > 1) {
      const auto keep = static_cast<std::size_t>(std::ceil(o_.trim_keep_fraction * static_cast<double>(pairs_.size())));
      if (keep < pairs_.size()) {
        std::nth_element(pairs_.begin(), pairs_.begin() + static_cast<std::ptrdiff_t>(keep), pairs_.end(),
                         [](const Pair& a, const Pair& b) { return a.key < b.key; });
        pairs_.resize(keep);
      }
    }
    // Order-independent fingerprint of the kept (source, target) pairs.
    set_hash_ = 0;
    for (const Pair& pr : pairs_) set_hash_ += mix((static_cast<std::uint64_t>(pr.src) << 32) | pr.tgt);
    if (p2l_) {  // the pairs' data in order, read by every linearisation
      lines_.clear();
      // The pairs with a two-point line after the others (see info_lines_).
      auto gather = [&](bool corner) {
        for (const Pair& pr : pairs_) {
          if ((via_corner_[pr.src] != 0) != corner) continue;
          const Eigen::Vector2d& p = src_[pr.src];
          const Eigen::Vector2d& n = normal_[pr.src];
          const Eigen::Vector2d& m = tp[pr.tgt];
          if (hasNoLine(n)) {  // a point pair: its x and y offsets, weighted
            lines_.push_back({p.x(), p.y(), m.x(), m.y(), point_w_, 0.0});
            lines_.push_back({p.x(), p.y(), m.x(), m.y(), 0.0, point_w_});
            continue;
          }
          lines_.push_back({p.x(), p.y(), m.x(), m.y(), n.x(), n.y()});
        }
      };
      gather(false);
      info_lines_ = lines_.size();
      if (two_point_) gather(true);
    }
  }

  // Fingerprint of the pairs of the last findPairs.
  std::uint64_t setHash() const { return set_hash_; }

  // The normal equations at T; the cost and sum w r^2 only `with_cost` (the final linearisation:
  // the Gauss-Newton steps need H and g alone).
  Linearisation linearise(const SE2& T, bool with_cost = true) const {
    if (o_.loss.kind == RobustLoss::Kind::kHuber) {
      // min(1, a / |r|) without a data-dependent branch (a / a is exactly 1).
      const double a = o_.loss.scale_m;
      return lineariseWith(T, with_cost, [a](double r) { return a / std::max(a, std::abs(r)); });
    }
    return lineariseWith(T, with_cost, [this](double r) { return o_.loss.weight(r); });
  }

  template <class Weight>
  Linearisation lineariseWith(const SE2& T, bool with_cost, Weight&& weight) const {
    Linearisation L;
    const double c = std::cos(T.theta()), s = std::sin(T.theta());
    double h00 = 0, h01 = 0, h02 = 0, h11 = 0, h12 = 0, h22 = 0, g0 = 0, g1 = 0, g2 = 0;
    if (p2l_) {
      // Censi 2008, eq. (3): r = n^T (R p + t - m); J = n^T d(T p)/d(x, y, theta), with
      // d(T p)/d(x, y, theta) = [1 0 -s px - c py; 0 1 c px - s py] (SE2::pointJacobian).
      // The two-point lines come last: H_info is H before them.
      auto accumulate = [&](std::size_t begin, std::size_t end) {
        for (std::size_t k = begin; k < end; ++k) {
          const LineTerm& l = lines_[k];
          const double jx = -s * l.px - c * l.py;
          const double jy = c * l.px - s * l.py;
          const double qx = c * l.px - s * l.py + T.x() - l.mx;
          const double qy = s * l.px + c * l.py + T.y() - l.my;
          const double r = l.nx * qx + l.ny * qy;
          const double j2 = l.nx * jx + l.ny * jy;
          const double w = weight(r);
          const double wnx = w * l.nx, wny = w * l.ny, wj2 = w * j2;
          h00 += wnx * l.nx;
          h01 += wnx * l.ny;
          h02 += wnx * j2;
          h11 += wny * l.ny;
          h12 += wny * j2;
          h22 += wj2 * j2;
          g0 += wnx * r;
          g1 += wny * r;
          g2 += wj2 * r;
          if (with_cost) {
            L.cost += 0.5 * o_.loss.rho(r);
            L.wr2 += w * r * r;
          }
        }
      };
      accumulate(0, info_lines_);
      if (with_cost) L.H_info << h00, h01, h02, h01, h11, h12, h02, h12, h22;
      accumulate(info_lines_, lines_.size());
      L.residuals = lines_.size();
    } else {
      const Points2& tp = tgt_.points;
      for (const Pair& pr : pairs_) {
        const Eigen::Vector2d& p = src_[pr.src];
        const Eigen::Vector2d& m = tp[pr.tgt];
        // d(T p)/d(x, y, theta) = [1 0 -s px - c py; 0 1 c px - s py] (SE2::pointJacobian).
        const double jx = -s * p.x() - c * p.y();
        const double jy = c * p.x() - s * p.y();
        const double qx = c * p.x() - s * p.y() + T.x() - m.x();
        const double qy = s * p.x() + c * p.y() + T.y() - m.y();
        // Point-to-point: the robust loss acts on the pair's squared distance (one residual block
        // of two components, as in the Ceres variant).
        const double d = std::hypot(qx, qy);
        const double w = weight(d);
        h00 += w;
        h02 += w * jx;
        h11 += w;
        h12 += w * jy;
        h22 += w * (jx * jx + jy * jy);
        g0 += w * qx;
        g1 += w * qy;
        g2 += w * (jx * qx + jy * qy);
        if (with_cost) {
          L.cost += 0.5 * o_.loss.rho(d);
          L.wr2 += w * d * d;
        }
      }
      L.residuals = 2 * pairs_.size();
    }
    L.H << h00, h01, h02, h01, h11, h12, h02, h12, h22;
    if (with_cost && !p2l_) L.H_info = L.H;
    L.g << g0, g1, g2;
    return L;
  }

  // Point-to-line: one residual's data, a source point, its target point and the line's normal.
  struct LineTerm {
    double px, py, mx, my, nx, ny;
  };

  const std::vector<Pair>& pairs() const { return pairs_; }
  // Point-to-line: the residuals of the last search (a point pair gives two, its x and y offsets).
  const std::vector<LineTerm>& lines() const { return lines_; }
  const Points2& source() const { return src_; }
  const IcpTarget::Impl& target() const { return tgt_; }

 private:
  const IcpTarget::Impl& tgt_;  // (the search structures themselves: the search inlines)
  const Points2& src_;
  const IcpOptions& o_;
  const bool p2l_;
  const bool two_point_;  // point-to-line: IcpOptions::two_point_lines, and the target has them
  const double point_w_;  // point-to-line: weight of the point pairs (0: none)
  std::vector<Pair> pairs_;
  // Point-to-line: per source point, the normal of its pair's line in the last search ((0, 0): a
  // point pair), the target point's own or a two-point line's.
  Points2 normal_;
  // A pair's point-to-line data, gathered once per search for the linearisations that follow:
  // source point p, target point m and the normal n of its line; r(T) = n^T (T p - m).
  std::vector<LineTerm> lines_;  // per kept pair, in the order of pairs_, two-point lines last
  std::size_t info_lines_ = 0;   // lines_ before the two-point lines
  // Point-to-line: per source point, whether its pair's line in the last search is a two-point line.
  std::vector<std::uint8_t> via_corner_;
  std::vector<std::size_t> last_match_;  // per source point: its nearest target point last time, or size()
  static constexpr std::uint32_t kNoHint = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> hints_;     // per source point: its search hint (IcpTarget::nearestWithin)
  std::uint64_t set_hash_ = 0;

  static std::uint64_t mix(std::uint64_t z) {  // splitmix64 finaliser
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
};

// The fingerprints of the last few sets of pairs: when a search returns a set already solved, the
// iteration has reached a fixed point of the correspondence search (the same set again) or a cycle
// through a few sets; searching on cannot settle further, so the loop stops there.
class PairSetHistory {
 public:
  // True when `h` is one of the remembered fingerprints; remembers it either way.
  bool seenBefore(std::uint64_t h) {
    const bool seen = std::find(hashes_.begin(), hashes_.begin() + static_cast<std::ptrdiff_t>(count_), h) !=
                      hashes_.begin() + static_cast<std::ptrdiff_t>(count_);
    hashes_[next_] = h;
    next_ = (next_ + 1) % hashes_.size();
    count_ = std::min(count_ + 1, hashes_.size());
    return seen;
  }

 private:
  std::array<std::uint64_t, 8> hashes_{};
  std::size_t next_ = 0, count_ = 0;
};

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

Result failure(const SE2& init, Status status, std::string message) {
  Result r;
  r.T_target_source = init.isFinite() ? init : SE2();
  r.converged = false;
  r.status = status;
  r.message = std::move(message);
  return r;
}

// Fills information, covariance, cost and inliers of `r` from the final linearisation.
// The information leaves out point-to-line's two-point lines (IcpOptions::two_point_lines): they
// pin the pose in practice, but where they stand in for short noisy stretches of wall their
// normals are partly noise, and counting them would report a corridor's free direction as pinned.
void finish(Result& r, const Linearisation& L, std::size_t inliers) {
  r.information = L.H_info;
  r.final_cost = L.cost;
  r.num_inliers = inliers;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(L.H_info);
  const double lmin = es.eigenvalues()(0), lmax = es.eigenvalues()(2);
  if (lmax > 0.0 && lmin > 1e-12 * lmax && L.residuals > 3) {
    const double sigma2 = L.wr2 / static_cast<double>(L.residuals - 3);
    r.covariance = sigma2 * es.eigenvectors() * es.eigenvalues().cwiseInverse().asDiagonal() *
                   es.eigenvectors().transpose();
  } else {
    r.covariance = Eigen::Matrix3d::Identity() * std::numeric_limits<double>::infinity();
  }
}

// The final linearisation: correspondences searched again at the final estimate, so that H, the
// covariance, the cost and the inlier count describe the returned pose (and do not depend on the
// solver's path to it).
void finishAt(Result& r, Icp& icp, const IcpOptions& o) {
  icp.findPairs(r.T_target_source);
  if (icp.pairs().size() < o.min_inliers) {
    r.num_inliers = icp.pairs().size();
    return;  // keeps the infinite covariance and zero information
  }
  finish(r, icp.linearise(r.T_target_source), icp.pairs().size());
}

bool smallStep(const Eigen::Vector3d& dx, const IcpOptions& o) {
  return std::hypot(dx.x(), dx.y()) < o.translationEps() && std::abs(dx.z()) < o.rotationEps();
}

Result runGaussNewton(Icp& icp, const SE2& init, const IcpOptions& o) {
  Result res;
  Eigen::Vector3d x = init.vector();
  int it = 0;
  bool converged = false;
  PairSetHistory history;
  while (it < o.max_iterations) {
    ++it;
    icp.findPairs(SE2::fromVector(x));
    if (icp.pairs().size() < o.min_inliers)
      return failure(init, Status::kTooFewInliers,
                     fmt::format("iteration {}: {} correspondences survived the rejection, {} needed", it,
                                 icp.pairs().size(), o.min_inliers));
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
  res.T_target_source = SE2::fromVector(x);
  res.iterations = it;
  res.converged = converged;
  res.status = converged ? Status::kConverged : Status::kMaxIterations;
  if (!converged) res.message = fmt::format("no convergence within {} iterations", o.max_iterations);
  finishAt(res, icp, o);
  return res;
}

// All residuals of a correspondence search as one Ceres residual block, with analytic Jacobians
// over the pose (x, y, theta) of T_target_source. Point-to-line: one residual per line term
// (Censi's r = n^T (R p + t - m)); point-to-point: two per pair (R p + t - m). The robust loss
// (a Ceres LossFunction) is applied per line term or per pair inside the block
// (internal::robustScaling), so the block's squared norm is the sum of rho over them: the same
// objective as one residual block per pair with the loss attached, which is how this solver was
// first written; that spent most of its time in Ceres's per-block bookkeeping (evaluation
// dispatch, validity checks, the loss's Jacobian correction): 4.6-10.7x Gauss-Newton's time before,
// BENCHMARK.md ("Speed against the targets") for after.
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
        internal::robustScaling(loss_, r * r, f, g);
        residuals[k] = f * r;
        if (J != nullptr) {
          const double d = f + g * r * r;
          double* row = J + 3 * k;
          row[0] = d * t.nx;
          row[1] = d * t.ny;
          row[2] = d * (t.nx * jx + t.ny * jy);
        }
      } else {
        internal::robustScaling(loss_, qx * qx + qy * qy, f, g);
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

// Outer loop of correspondence searches; for each set of pairs Ceres minimises the robust cost
// (a few Levenberg-Marquardt iterations), then the pairs are searched again at the new pose.
Result runCeres(Icp& icp, const SE2& init, const IcpOptions& o) {
  const std::unique_ptr<ceres::LossFunction> loss = makeLoss(o.loss);
  const ceres::Solver::Options so = internal::poseSolverOptions(o.ceres_max_inner_iterations, 1e-12, 1e-10);
  double x[3] = {init.x(), init.y(), init.theta()};
  const ceres::Problem::Options po = internal::singleBlockProblemOptions();
  int it = 0;
  bool converged = false;
  PairSetHistory history;
  while (it < o.max_iterations) {
    ++it;
    const SE2 T(x[0], x[1], x[2]);
    icp.findPairs(T);
    if (icp.pairs().size() < o.min_inliers)
      return failure(init, Status::kTooFewInliers,
                     fmt::format("iteration {}: {} correspondences survived the rejection, {} needed", it,
                                 icp.pairs().size(), o.min_inliers));
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
  Result res;
  res.T_target_source = SE2(x[0], x[1], x[2]);
  res.iterations = it;
  res.converged = converged;
  res.status = converged ? Status::kConverged : Status::kMaxIterations;
  if (!converged) res.message = fmt::format("no convergence within {} iterations", o.max_iterations);
  finishAt(res, icp, o);
  return res;
}

}  // namespace

Result alignIcp(const IcpTarget& target, const Points2& points_source, const SE2& init_T_target_source,
                const IcpOptions& options) {
  if (const std::string bad = options.check(); !bad.empty())
    return failure(init_T_target_source, Status::kInvalidInput, "invalid option: " + bad);
  if (!init_T_target_source.isFinite())
    return failure(init_T_target_source, Status::kInvalidInput, "the initial guess is not finite");
  Points2 source = finitePoints(points_source);
  if (source.size() < options.min_points || target.size() < options.min_points)
    return failure(init_T_target_source, Status::kTooFewPoints,
                   fmt::format("{} finite source and {} finite target points, {} needed", source.size(), target.size(),
                               options.min_points));
  if (allSame(source) || target.allIdentical())
    return failure(init_T_target_source, Status::kDegenerate,
                   allSame(source) ? "all source points are identical" : "all target points are identical");
  if (options.min_source_spacing_m > 0.0) {
    Points2 kept = thinned(source, options.min_source_spacing_m);
    if (kept.size() >= options.min_points) source = std::move(kept);  // (thinning never makes a match fail)
  }
  Icp icp(target, source, options);
  return options.solver == Solver::kCeres ? runCeres(icp, init_T_target_source, options)
                                          : runGaussNewton(icp, init_T_target_source, options);
}

Result alignIcp(const Points2& points_target, const Points2& points_source, const SE2& init_T_target_source,
                const IcpOptions& options) {
  if (const std::string bad = options.check(); !bad.empty())
    return failure(init_T_target_source, Status::kInvalidInput, "invalid option: " + bad);
  return alignIcp(IcpTarget(points_target, options), points_source, init_T_target_source, options);
}

}  // namespace lidar2d::registration
