#include "lidar2d/degeneracy/degeneracy.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <numeric>

#include "lidar2d/core/error.hpp"
#include "lidar2d/geometry/line_fit.hpp"
#include "src/geometry/eigen2.hpp"
#include "src/geometry/kdtree2.hpp"

namespace lidar2d::degeneracy {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = std::numbers::pi;

// nanoflann result set appending every point within the radius to CSR arrays (no per-query vector).
struct AppendResultSet {
  double radius2;
  std::vector<std::uint32_t>* idx;
  std::vector<float>* d2;
  std::size_t n = 0;
  bool full() const { return true; }
  double worstDist() const { return radius2; }
  bool addPoint(double dist, std::uint32_t index) {
    if (dist <= radius2) {
      idx->push_back(index);
      d2->push_back(static_cast<float>(dist));
      ++n;
    }
    return true;
  }
  std::size_t size() const { return n; }
};

// The finite points of a scan and their neighbours within a radius (themselves included), found once
// on one k-d tree and shared by both detectors.
struct Prepared {
  Points2 pts;                              // finite points kept by the thinning, input order
  std::vector<std::int32_t> kept_of_input;  // per input point: the kept point it was merged into, or -1
  std::vector<std::uint32_t> start;         // CSR: neighbours of i are idx[start[i] .. start[i+1])
  std::vector<std::uint32_t> idx;
  std::vector<float> d2;  // squared distances [m^2]
  std::string reason;     // non-empty: the input checks failed (cannot decide)
};

// Neighbourhood radius of a point at range r: max(base, r * per_m).
struct Radius {
  double base = 0.0, per_m = 0.0;
  double at(const Eigen::Vector2d& p) const { return std::max(base, p.norm() * per_m); }
};

Prepared prepare(const Points2& input, const InputOptions& o, Radius radius) {
  Prepared p;
  p.pts.reserve(input.size());
  p.kept_of_input.assign(input.size(), -1);
  std::size_t finite = 0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  const double spacing2 = o.min_spacing_m * o.min_spacing_m;
  for (std::size_t i = 0; i < input.size(); ++i) {
    if (!input[i].allFinite()) continue;
    ++finite;
    mean += input[i];
    if (!p.pts.empty() && (input[i] - p.pts.back()).squaredNorm() < spacing2) {
      p.kept_of_input[i] = static_cast<std::int32_t>(p.pts.size() - 1);
      continue;
    }
    p.kept_of_input[i] = static_cast<std::int32_t>(p.pts.size());
    p.pts.push_back(input[i]);
  }
  if (finite < o.min_points) {
    p.reason = fmt::format("too few points ({} finite, {} needed)", finite, o.min_points);
    return p;
  }
  mean /= static_cast<double>(finite);
  double ss = 0.0;
  for (const auto& q : input)
    if (q.allFinite()) ss += (q - mean).squaredNorm();
  const double spread = std::sqrt(ss / static_cast<double>(finite));
  if (!(spread >= o.min_spread_m)) {
    p.reason = fmt::format("all points on one spot (spread {:.3f} m < {:.3f} m)", spread, o.min_spread_m);
    return p;
  }
  const std::size_t n = p.pts.size();
  geometry::Points2Adaptor adaptor{&p.pts};
  geometry::KdTree2::Tree tree(2, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(8));
  p.start.resize(n + 1);
  p.idx.reserve(n * 16);
  p.d2.reserve(n * 16);
  const nanoflann::SearchParams params(32, 0.0f, false);
  for (std::size_t i = 0; i < n; ++i) {
    p.start[i] = static_cast<std::uint32_t>(p.idx.size());
    const double ri = radius.at(p.pts[i]);
    AppendResultSet rs{ri * ri, &p.idx, &p.d2};
    const double q[2] = {p.pts[i].x(), p.pts[i].y()};
    tree.findNeighbors(rs, q, params);
  }
  p.start[n] = static_cast<std::uint32_t>(p.idx.size());
  return p;
}

std::string checkInput(const InputOptions& o, const char* prefix) {
  if (o.min_points < 3) return fmt::format("{}input.min_points must be >= 3", prefix);
  if (!(o.min_spread_m >= 0.0) || !std::isfinite(o.min_spread_m))
    return fmt::format("{}input.min_spread_m must be finite and >= 0", prefix);
  if (!(o.min_spacing_m >= 0.0) || !std::isfinite(o.min_spacing_m))
    return fmt::format("{}input.min_spacing_m must be finite and >= 0", prefix);
  return {};
}

void require(const std::string& bad) {
  if (!bad.empty()) throw invalidArgument(bad, ErrorLocation({}, 0, "degeneracy options"));
}

// ---- geometric ----

GeometricResult geometricFrom(const Prepared& p, std::size_t num_input, const GeometricOptions& o) {
  GeometricResult r;
  r.cluster_of_point.assign(num_input, -1);
  if (!p.reason.empty()) {
    r.reason = p.reason;
    return r;
  }
  const std::size_t n = p.pts.size();
  // DBSCAN (Ester et al. 1996): core points have >= core_min_points neighbours within eps; clusters are
  // the core points reachable from each other plus the border points within eps of them. eps grows with
  // the range (sparser returns far away), so the neighbourhoods of a point are those found from it.
  const Radius eps{o.cluster_eps_m, o.cluster_eps_per_m};
  std::vector<float> eps2(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double e = eps.at(p.pts[i]);
    eps2[i] = static_cast<float>(e * e);
  }
  auto neighbours_within = [&](std::size_t i) {
    std::size_t c = 0;
    for (std::uint32_t j = p.start[i]; j < p.start[i + 1]; ++j) c += p.d2[j] <= eps2[i];
    return c;
  };
  std::vector<int> label(n, -1);
  std::vector<std::uint8_t> core(n, 0);
  for (std::size_t i = 0; i < n; ++i) core[i] = neighbours_within(i) >= o.core_min_points;
  std::vector<std::vector<std::uint32_t>> clusters;
  std::vector<std::uint32_t> stack;
  for (std::size_t i = 0; i < n; ++i) {
    if (!core[i] || label[i] >= 0) continue;
    const int id = static_cast<int>(clusters.size());
    clusters.emplace_back();
    auto& members = clusters.back();
    label[i] = id;
    stack.assign(1, static_cast<std::uint32_t>(i));
    while (!stack.empty()) {
      const std::uint32_t c = stack.back();
      stack.pop_back();
      members.push_back(c);
      if (!core[c]) continue;  // border point: belongs, does not expand
      for (std::uint32_t j = p.start[c]; j < p.start[c + 1]; ++j) {
        if (p.d2[j] > eps2[c]) continue;
        const std::uint32_t nb = p.idx[j];
        if (label[nb] >= 0) continue;
        label[nb] = id;
        stack.push_back(nb);
      }
    }
  }
  // Keep the clusters of an accepted size; order each around the sensor (beam order, also for a 360
  // degree scan whose seam cuts a cluster) and fit lines, splitting where one line does not fit: a
  // piece is a line when its total-least-squares fit is within max_line_rms_m, else it is split
  // Douglas-Peucker style at the point farthest from its chord (a corner of an L-shaped cluster, the
  // far side of a curved one); pieces too small or too deep to split are unstructured.
  geometry::LineSplitOptions split;
  split.rule = geometry::SplitRule::kFitResidual;
  split.threshold_m = o.max_line_rms_m;
  split.min_points = o.min_line_points;
  split.max_depth = o.max_split_depth;
  split.fit = {geometry::LineNormal::kMinorEigenvector, geometry::LineResidual::kMinorEigenvalue,
               geometry::LineEnds::kExtremes};
  std::vector<geometry::LinePiece> pieces;
  Points2 q;
  std::vector<int> cluster_of_kept(n, -1);
  for (auto& members : clusters) {
    if (members.size() < o.min_cluster_points) continue;
    const int id = static_cast<int>(r.num_clusters++);
    for (std::uint32_t m : members) cluster_of_kept[m] = id;
    // Input order is beam order: sort by index, then start after the largest index gap (counted
    // around the end), so that a cluster cut by the seam of a 360 degree scan stays one chain.
    std::sort(members.begin(), members.end());
    std::size_t start = 0;
    std::size_t best_gap = members.front() + n - members.back();
    for (std::size_t k = 1; k < members.size(); ++k)
      if (members[k] - members[k - 1] > best_gap) {
        best_gap = members[k] - members[k - 1];
        start = k;
      }
    q.clear();
    for (std::size_t k = 0; k < members.size(); ++k) q.push_back(p.pts[members[(start + k) % members.size()]]);
    r.num_clustered_points += q.size();
    for (std::size_t b = 0; b < q.size(); b += o.max_cluster_points) {
      pieces.clear();
      geometry::splitIntoLines(q, b, std::min(q.size(), b + o.max_cluster_points), split, &pieces);
      for (const geometry::LinePiece& piece : pieces) {
        if (piece.kind != geometry::LinePiece::Kind::kLine) {
          r.num_unstructured_points += piece.end - piece.first;
          continue;
        }
        Line l;
        l.centroid = piece.fit.centroid;
        l.direction = piece.fit.direction;
        l.a = piece.fit.a;
        l.b = piece.fit.b;
        l.rms_m = piece.fit.rms_m;
        l.num_points = piece.fit.num_points;
        l.cluster = id;
        r.lines.push_back(l);
      }
    }
  }
  for (std::size_t i = 0; i < num_input; ++i)
    if (p.kept_of_input[i] >= 0) r.cluster_of_point[i] = cluster_of_kept[static_cast<std::size_t>(p.kept_of_input[i])];
  if (r.num_clustered_points < o.input.min_points) {
    r.reason = fmt::format("too little structure ({} clustered points, {} needed)", r.num_clustered_points,
                           o.input.min_points);
    return r;
  }
  // Translational constraint: lines constrain along their normal, unstructured points every direction.
  double a = 0.5 * static_cast<double>(r.num_unstructured_points), b = 0.0, c = a;
  for (const Line& l : r.lines) {
    const double w = static_cast<double>(l.num_points);
    const double nx = -l.direction.y(), ny = l.direction.x();
    a += w * nx * nx;
    b += w * nx * ny;
    c += w * ny * ny;
  }
  const geometry::SymEigen2Angle e = geometry::symEigen2Angle(a, b, c);
  // The weakest direction d is the eigenvector of the smallest eigenvalue of M = sum n n^T: d^T M d is
  // the constraint along d.
  r.direction_rad = e.lo_angle;
  r.score = std::max(0.0, e.lo) / static_cast<double>(r.num_clustered_points);
  const Eigen::Vector2d d(std::cos(r.direction_rad), std::sin(r.direction_rad));
  const double cos_tol = std::cos(o.parallel_tol_deg * kPi / 180.0);
  for (const Line& l : r.lines)
    if (std::abs(l.direction.dot(d)) >= cos_tol) r.parallel_length_m += l.length();
  if (r.score >= o.threshold) {
    r.verdict = Verdict::kWellConstrained;
  } else if (r.parallel_length_m >= o.min_parallel_length_m) {
    r.verdict = Verdict::kDegenerate;
  } else {
    r.reason = fmt::format("weak along {:.1f} deg but no walls along it ({:.2f} m of parallel lines)",
                           r.direction_rad * 180.0 / kPi, r.parallel_length_m);
  }
  return r;
}

// ---- information ----

InformationResult informationFrom(const Prepared& p, const InformationOptions& o) {
  InformationResult r;
  if (!p.reason.empty()) {
    r.reason = p.reason;
    return r;
  }
  const std::size_t n = p.pts.size();
  const Radius radius{o.normal_radius_m, o.normal_radius_per_m};
  const double max_flat2 = o.max_flatness * o.max_flatness;
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  double sum_p2 = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    // Local line through the neighbours within the radius (Censi 2008's normals).
    double cnt = 0, sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0;
    const Eigen::Vector2d& pi = p.pts[i];
    const double ri = radius.at(pi);
    const float r2 = static_cast<float>(ri * ri);
    for (std::uint32_t j = p.start[i]; j < p.start[i + 1]; ++j) {
      if (p.d2[j] > r2) continue;
      const Eigen::Vector2d d = p.pts[p.idx[j]] - pi;  // relative to p_i: well conditioned
      cnt += 1;
      sx += d.x();
      sy += d.y();
      sxx += d.x() * d.x();
      sxy += d.x() * d.y();
      syy += d.y() * d.y();
    }
    if (cnt < static_cast<double>(o.normal_min_neighbors)) continue;
    const double mx = sx / cnt, my = sy / cnt;
    const geometry::SymEigen2 e = geometry::symEigen2(sxx / cnt - mx * mx, sxy / cnt - mx * my, syy / cnt - my * my);
    if (!(e.hi > 0.0) || std::max(0.0, e.lo) > max_flat2 * e.hi) continue;
    const Eigen::Vector2d& nrm = e.lo_vec;
    // Residual n . (T p - q) at T = identity: d/d(x, y, theta) = [n_x, n_y, n . perp(p)].
    const Eigen::Vector3d J(nrm.x(), nrm.y(), nrm.x() * -pi.y() + nrm.y() * pi.x());
    H.noalias() += J * J.transpose();
    sum_p2 += pi.squaredNorm();
    ++r.num_normals;
  }
  r.information = H;
  if (r.num_normals < o.input.min_points) {
    r.reason = fmt::format("too few points on lines ({} with a normal, {} needed)", r.num_normals, o.input.min_points);
    return r;
  }
  const geometry::SymEigen2Angle e = geometry::symEigen2Angle(H(0, 0), H(0, 1), H(1, 1));
  r.score = std::max(0.0, e.lo) / static_cast<double>(r.num_normals);
  r.direction_rad = e.lo_angle;
  r.rotation_score = sum_p2 > 0 ? H(2, 2) / sum_p2 : 0.0;
  r.verdict = r.score < o.threshold ? Verdict::kDegenerate : Verdict::kWellConstrained;
  return r;
}

}  // namespace

const char* toString(Verdict v) {
  switch (v) {
    case Verdict::kWellConstrained:
      return "well_constrained";
    case Verdict::kDegenerate:
      return "degenerate";
    case Verdict::kCannotDecide:
      return "cannot_decide";
  }
  return "unknown";
}

std::string GeometricOptions::check() const {
  if (auto bad = checkInput(input, "geometric."); !bad.empty()) return bad;
  if (!(cluster_eps_m > 0.0) || !std::isfinite(cluster_eps_m)) return "geometric.cluster_eps_m must be > 0";
  if (!(cluster_eps_per_m >= 0.0) || !std::isfinite(cluster_eps_per_m))
    return "geometric.cluster_eps_per_m must be >= 0";
  if (core_min_points < 1) return "geometric.core_min_points must be >= 1";
  if (min_cluster_points < 2) return "geometric.min_cluster_points must be >= 2";
  if (max_cluster_points < min_cluster_points) return "geometric.max_cluster_points must be >= min_cluster_points";
  if (!(max_line_rms_m > 0.0)) return "geometric.max_line_rms_m must be > 0";
  if (min_line_points < 2) return "geometric.min_line_points must be >= 2";
  if (max_split_depth < 0) return "geometric.max_split_depth must be >= 0";
  if (!(parallel_tol_deg >= 0.0 && parallel_tol_deg < 90.0)) return "geometric.parallel_tol_deg must be in [0, 90)";
  if (!(min_parallel_length_m >= 0.0)) return "geometric.min_parallel_length_m must be >= 0";
  if (!(threshold > 0.0 && threshold <= 0.5)) return "geometric.threshold must be in (0, 0.5]";
  return {};
}

std::string InformationOptions::check() const {
  if (auto bad = checkInput(input, "information."); !bad.empty()) return bad;
  if (!(normal_radius_m > 0.0) || !std::isfinite(normal_radius_m)) return "information.normal_radius_m must be > 0";
  if (!(normal_radius_per_m >= 0.0) || !std::isfinite(normal_radius_per_m))
    return "information.normal_radius_per_m must be >= 0";
  if (normal_min_neighbors < 2) return "information.normal_min_neighbors must be >= 2";
  if (!(max_flatness > 0.0 && max_flatness <= 1.0)) return "information.max_flatness must be in (0, 1]";
  if (!(threshold > 0.0 && threshold <= 0.5)) return "information.threshold must be in (0, 0.5]";
  return {};
}

std::string Options::check() const {
  if (auto bad = geometric.check(); !bad.empty()) return bad;
  if (auto bad = information.check(); !bad.empty()) return bad;
  if (!(confirm_factor >= 1.0) || !std::isfinite(confirm_factor)) return "confirm_factor must be >= 1";
  return {};
}

GeometricResult analyzeGeometric(const Points2& points_scan, const GeometricOptions& options) {
  require(options.check());
  return geometricFrom(prepare(points_scan, options.input, {options.cluster_eps_m, options.cluster_eps_per_m}),
                       points_scan.size(), options);
}

InformationResult analyzeInformation(const Points2& points_scan, const InformationOptions& options) {
  require(options.check());
  return informationFrom(prepare(points_scan, options.input, {options.normal_radius_m, options.normal_radius_per_m}),
                         options);
}

Eigen::Vector2d Result::direction() const { return {std::cos(direction_rad), std::sin(direction_rad)}; }

Result analyze(const Points2& points_scan, const Options& options) {
  require(options.check());
  // One k-d tree and one radius search per point, at the larger of the two radii; each detector
  // filters the neighbour lists by its own radius. The stricter input checks of the two apply.
  InputOptions input;
  input.min_points = std::max(options.geometric.input.min_points, options.information.input.min_points);
  input.min_spread_m = std::max(options.geometric.input.min_spread_m, options.information.input.min_spread_m);
  input.min_spacing_m = std::min(options.geometric.input.min_spacing_m, options.information.input.min_spacing_m);
  const Radius radius{std::max(options.geometric.cluster_eps_m, options.information.normal_radius_m),
                      std::max(options.geometric.cluster_eps_per_m, options.information.normal_radius_per_m)};
  const Prepared p = prepare(points_scan, input, radius);
  Result r;
  r.geometric = geometricFrom(p, points_scan.size(), options.geometric);
  r.information = informationFrom(p, options.information);
  if (!p.reason.empty()) {
    r.reason = p.reason;
    return r;
  }
  const GeometricResult& g = r.geometric;
  const InformationResult& h = r.information;
  const bool g_ok = g.verdict != Verdict::kCannotDecide, h_ok = h.verdict != Verdict::kCannotDecide;
  if (!g_ok && !h_ok) {
    r.reason = fmt::format("geometric: {}; information: {}", g.reason, h.reason);
    return r;
  }
  const bool g_deg = g.verdict == Verdict::kDegenerate, h_deg = h.verdict == Verdict::kDegenerate;
  const bool g_weak = g_ok && g.score < options.confirm_factor * options.geometric.threshold;
  const bool h_weak = h_ok && h.score < options.confirm_factor * options.information.threshold;
  bool degenerate = false;
  if (g_ok && h_ok)
    degenerate = (g_deg && h_weak) || (h_deg && g_weak);
  else
    degenerate = g_ok ? g_deg : h_deg;
  r.verdict = degenerate ? Verdict::kDegenerate : Verdict::kWellConstrained;
  if (h_ok) {
    r.score = h.score;
    r.direction_rad = h.direction_rad;
  } else {
    r.score = g.score;
    r.direction_rad = g.direction_rad;
  }
  return r;
}

std::optional<Eigen::Vector2d> weakestDirection(const Eigen::Matrix2d& H_per_point, double threshold) {
  if (!H_per_point.allFinite()) return std::nullopt;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(H_per_point);
  if (es.info() != Eigen::Success || !(es.eigenvalues()(0) < threshold)) return std::nullopt;
  return es.eigenvectors().col(0).normalized();
}

Eigen::Matrix3d wellConstrainedProjector(const Eigen::Matrix3d& H, double min_eigenvalue) {
  if (!H.allFinite()) return Eigen::Matrix3d::Zero();
  const Eigen::Matrix3d S = 0.5 * (H + H.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(S);
  Eigen::Matrix3d P = Eigen::Matrix3d::Zero();
  for (int i = 0; i < 3; ++i)
    if (es.eigenvalues()(i) >= min_eigenvalue) P += es.eigenvectors().col(i) * es.eigenvectors().col(i).transpose();
  return P;
}

Eigen::Matrix3d projectorRemovingDirection(double direction_rad) {
  Eigen::Matrix3d P = Eigen::Matrix3d::Identity();
  const Eigen::Vector2d d(std::cos(direction_rad), std::sin(direction_rad));
  P.topLeftCorner<2, 2>() -= d * d.transpose();
  return P;
}

SE2 remapPose(const SE2& init, const SE2& estimate, const Eigen::Matrix3d& P) {
  const Eigen::Vector3d delta(estimate.x() - init.x(), estimate.y() - init.y(),
                              angleDiff(estimate.theta(), init.theta()));
  return SE2::fromVector(init.vector() + P * delta);
}

SE2 constrainMatch(const SE2& T_match, const SE2& T_prior, const Result& source) {
  switch (source.verdict) {
    case Verdict::kWellConstrained:
      return T_match;
    case Verdict::kCannotDecide:
      return T_prior;
    case Verdict::kDegenerate:
      return remapPose(T_prior, T_match, projectorRemovingDirection(source.direction_rad + T_prior.theta()));
  }
  return T_prior;
}

}  // namespace lidar2d::degeneracy
