#include "src/registration/internal/icp_problem.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace lidar2d::registration::internal {

namespace {

// True when a target point has no line (its normal is (0, 0): see IcpTarget::normals).
bool hasNoLine(const Eigen::Vector2d& n) { return n.x() == 0.0 && n.y() == 0.0; }

}  // namespace

Icp::Icp(const IcpTarget& target, const Points2& source, const IcpOptions& o)
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

void Icp::findPairs(const SE2& T) {
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
    if (const std::size_t prev = last_match_[i]; prev < tp.size())
      bound2 = std::min(gate2, (q - tp[prev]).squaredNorm());
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

template <class Weight>
Linearisation Icp::lineariseWith(const SE2& T, bool with_cost, Weight&& weight) const {
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

Linearisation Icp::linearise(const SE2& T, bool with_cost) const {
  if (o_.loss.kind == RobustLoss::Kind::kHuber) {
    // min(1, a / |r|) without a data-dependent branch (a / a is exactly 1).
    const double a = o_.loss.scale_m;
    return lineariseWith(T, with_cost, [a](double r) { return a / std::max(a, std::abs(r)); });
  }
  return lineariseWith(T, with_cost, [this](double r) { return o_.loss.weight(r); });
}

Result failure(const SE2& init, Status status, std::string message) {
  Result r;
  r.T_target_source = init.isFinite() ? init : SE2();
  r.converged = false;
  r.status = status;
  r.message = std::move(message);
  return r;
}

Result tooFewInliers(const SE2& init, int iteration, std::size_t pairs, const IcpOptions& o) {
  return failure(init, Status::kTooFewInliers,
                 fmt::format("iteration {}: {} correspondences survived the rejection, {} needed", iteration, pairs,
                             o.min_inliers));
}

namespace {

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
    r.covariance =
        sigma2 * es.eigenvectors() * es.eigenvalues().cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
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

}  // namespace

Result finalResult(Icp& icp, const SE2& T, int iterations, bool converged, const IcpOptions& o) {
  Result res;
  res.T_target_source = T;
  res.iterations = iterations;
  res.converged = converged;
  res.status = converged ? Status::kConverged : Status::kMaxIterations;
  if (!converged) res.message = fmt::format("no convergence within {} iterations", o.max_iterations);
  finishAt(res, icp, o);
  return res;
}

}  // namespace lidar2d::registration::internal
