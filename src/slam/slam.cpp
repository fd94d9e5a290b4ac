#include "lidar2d/slam/slam.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <deque>
#include <unordered_map>
#include <optional>

#include "lidar2d/core/error.hpp"
#include "lidar2d/localization/lines.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/registration/correlative.hpp"
#include "lidar2d/registration/icp.hpp"
#include "lidar2d/registration/likelihood_field.hpp"

namespace lidar2d::slam {
namespace {

using registration::alignIcp;
using registration::CorrelativeGrid;
using registration::CorrelativeOptions;
using registration::IcpOptions;
using registration::IcpTarget;

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// Centroid of the points in each `cell_m` square. Stacked scans of the same wall would otherwise
/// give each target point near-duplicate neighbours from other scans, and a line fit over a
/// neighbourhood of duplicates has no direction (no normal): point-to-line ICP then loses its
/// correspondences exactly where the robot stands still or turns on the spot.
Points2 voxelFilter(const Points2& pts, double cell_m) {
  struct Acc {
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    int n = 0;
  };
  std::unordered_map<std::uint64_t, std::size_t> index;
  std::vector<Acc> acc;
  index.reserve(pts.size());
  acc.reserve(pts.size());
  for (const auto& p : pts) {
    const auto ix = static_cast<std::int64_t>(std::floor(p.x() / cell_m));
    const auto iy = static_cast<std::int64_t>(std::floor(p.y() / cell_m));
    const std::uint64_t key = (static_cast<std::uint64_t>(ix) << 32) ^ (static_cast<std::uint64_t>(iy) & 0xffffffffULL);
    auto [it, inserted] = index.try_emplace(key, acc.size());
    if (inserted) acc.emplace_back();
    acc[it->second].sum += p;
    ++acc[it->second].n;
  }
  Points2 out;
  out.reserve(acc.size());
  for (const auto& a : acc) out.push_back(a.sum / a.n);
  return out;
}

/// One scan's record: the node it hangs off and its pose relative to that node.
struct ScanRecord {
  std::size_t frame_index = 0;
  double time = 0.0;
  std::size_t node = 0;
  SE2 T_node_scan;
  bool is_node = false;
  bool matched = false;
  bool degenerate = false;
  double seconds = 0.0;
};

/// A submap: consecutive nodes, their points in the frame of the first (anchor) node.
struct Submap {
  std::size_t anchor = 0;
  std::vector<std::size_t> nodes;
  bool finished = false;
  Points2 points_anchor;
  Eigen::Vector2d center_anchor = Eigen::Vector2d::Zero();
  std::unique_ptr<IcpTarget> icp;
  std::unique_ptr<CorrelativeGrid> grid;  // built at the first branch-and-bound search
  std::optional<std::size_t> last_link_node;
  SE2 last_link_T_anchor_node;
  std::optional<Constraint> pending;  // searched closure awaiting confirmation
  std::unique_ptr<localization::Database> db;  // line-pair descriptors of its nodes (anchor frame)
};

}  // namespace

const char* toString(Constraint::Kind k) {
  switch (k) {
    case Constraint::Kind::kSequential:
      return "sequential";
    case Constraint::Kind::kOdometry:
      return "odometry";
    case Constraint::Kind::kLoop:
      return "loop";
  }
  return "unknown";
}

struct Slam::Impl {
  explicit Impl(const SlamOptions& o) : opt(o) {
    opt.validate();
    icp.max_correspondence_dist_m = opt.icp_max_correspondence_m;
    icp.max_iterations = 30;
    // The thresholds SLAM's figures (BENCHMARK.md) were measured with, kept when point-to-line's
    // default became 1 mm / 1 mrad (IcpOptions::defaultTranslationEps).
    icp.translation_eps_m = 1e-4;
    icp.rotation_eps_rad = 1e-4;
    // Likewise without point-to-line's two-point lines (IcpOptions::two_point_lines, 2026-12-01):
    // with them intel's relation error rose from 0.0209 to 0.0222 m, and without odometry from
    // 0.0353 to 0.166 m (BENCHMARK.md, "What changed since the previous table", tenth session).
    icp.two_point_lines = false;
    // SLAM thins its scans with its own voxel filter (scan_voxel_m); ICP's spacing filter on top of
    // it (IcpOptions::min_source_spacing_m, 2026-12-01) lost the simulated office's loops, and intel
    // without odometry went from 0.0353 to 0.0637 m (BENCHMARK.md, eleventh session).
    icp.min_source_spacing_m = 0.0;
    // Local maps and submaps stack several scans in a frame far from their sensors: the bearing
    // walk (made for one scan seen from its own origin) would visit many points per query there.
    icp.neighbor_search = registration::NeighborSearch::kKdTree;
    icp.normal_neighbors = opt.normal_neighbors;
    icp.max_line_flatness = opt.max_line_flatness;
    loop_icp = icp;
    // The local map's points are merged from several scans (not in beam order): no wall segments.
    local_lf.resolution_m = opt.map_voxel_m;
    local_lf.levels = 2;
    local_lf.truncation_m = 0.2;
    local_lf.connect_max_gap_m = 0.0;
    loop_icp.max_correspondence_dist_m = std::min(opt.icp_max_correspondence_m, 0.3);
    fallback.linear_window_m = opt.fallback_linear_window_m;
    fallback.angular_window_rad = opt.fallback_angular_window_rad;
    fallback.refine = false;
    fallback.min_score = 0.0;
    // A fixed 0.5 degree step: derived from the farthest point (Hess 2016, eq. 7) it would be ~0.1
    // degree for 30 m returns, five times the work; ICP refines the answer anyway.
    fallback.angular_step_rad = 0.5 * kDeg;
    loop_search = fallback;
    loop_search.linear_window_m = opt.loop_linear_window_m;
    loop_search.angular_window_rad = opt.loop_angular_window_rad;
    loop_search.min_score = 0.0;
    descriptor_search = loop_search;
    descriptor_search.linear_window_m = opt.descriptor_linear_window_m;
    descriptor_search.angular_window_rad = opt.descriptor_angular_window_rad;
    // The localizer's query options (line extraction, key radius, vote bins) describe SLAM's scans
    // too: both sides of the lookup are real scans here.
    descriptor_query.max_query_lines = opt.descriptor_max_lines;
    descriptor_query.max_range_m = opt.max_range_m;
    descriptor_db.lines = descriptor_query.lines;
    descriptor_db.max_lines = std::min<std::size_t>(64, std::max<std::size_t>(2, opt.descriptor_max_lines));
  }

  SlamOptions opt;
  IcpOptions icp, loop_icp;
  registration::LikelihoodFieldOptions local_lf;  // front_end_likelihood_field
  CorrelativeOptions fallback, loop_search, descriptor_search;
  localization::LocalizerOptions descriptor_query;
  localization::DatabaseOptions descriptor_db;

  std::vector<ScanRecord> scans;
  std::vector<Node> nodes;
  std::vector<Points2> node_points;  // robot frame
  std::vector<std::pair<LaserScan, SE2>> node_scans;  // each node's scan and T_robot_laser (submap grids)
  std::vector<std::optional<SE2>> node_odometry;
  std::vector<std::vector<localization::Line>> node_lines;  // robot frame, longest first (descriptor loops)
  std::vector<double> node_path_m;  // front-end path length from the first node [m]
  std::optional<std::size_t> last_loop_node;  // latest node with an accepted closure
  std::vector<Constraint> constraints;
  std::vector<PoseGraphEdge> edges;  // of the accepted constraints
  std::vector<Event> events;
  SlamStats stats;
  std::vector<Submap> submaps;
  static constexpr std::size_t kMaxGrids = 8;
  static constexpr std::size_t kVelocitySteps = 5;  // steps behind the constant-velocity prediction
  static constexpr double kConfirmExplained = 0.9;  // a match explaining this much confirms its start
  static constexpr double kEarlierWithOdometry = 0.8;  // see frontEndMatch's `earlier`
  // Which earlier scans' poses are starting points (scans back, ascending).
  static constexpr std::array<std::size_t, 4> kEarlierBack{2, 4, 8, 16};
  std::vector<std::size_t> grid_lru;  // submaps holding a grid, least recently used first

  // Front-end state.
  bool have_prev = false;
  SE2 T_local_prev;
  std::optional<SE2> odom_prev;
  bool odometry_seen = false, odometry_missing = false;
  std::size_t odometry_missing_count = 0;
  double time_prev = 0.0;
  // The front end's last few steps (robot frame), oldest first; emptied across gaps. The
  // constant-velocity prediction is their component-wise median (`velocityStep`).
  std::deque<SE2> recent_steps;
  std::deque<SE2> recent_poses;  // the front end's poses of the last kEarlierBack.back() scans, oldest first
  int consecutive_failures = 0;
  std::deque<std::size_t> local_nodes;
  std::unique_ptr<IcpTarget> local_target;
  std::unique_ptr<registration::LikelihoodField> local_field;  // front_end_likelihood_field
  Points2 local_points;
  std::unique_ptr<CorrelativeGrid> local_grid;

  // Back-end state.
  SE2 T_world_local;
  std::size_t nodes_since_optimization = 0;
  std::size_t loops_since_optimization = 0;
  bool searched_loop_pending = false;
  bool descriptor_loop_accepted = false;
  bool finished = false;

  void event(const Frame& f, std::string what) { events.push_back({f.index, f.time, std::move(what)}); }

  /// The share of `pts` that lie within match_inlier_distance_m of a target point once moved by T.
  double explainedFraction(const IcpTarget& target, const Points2& pts, const SE2& T) const {
    if (pts.empty()) return 0.0;
    const double d2max = opt.match_inlier_distance_m * opt.match_inlier_distance_m;
    std::size_t n = 0;
    for (const auto& p : pts) {
      double d2 = 0.0;
      if (target.nearest(T * p, &d2) < target.size() && d2 <= d2max) ++n;
    }
    return static_cast<double>(n) / static_cast<double>(pts.size());
  }

  /// The share of (up to 150 evenly chosen) beams of `pts` (robot frame, seen from the robot's
  /// origin) that cross a line of `target` (a point with a normal, within 0.1 m of the crossing,
  /// the beam at least 20 degrees off the line) more than 0.3 m before their endpoint, with the
  /// robot at `T`: walls of the target the scan should have seen but looked through.
  static double seeThroughFraction(const IcpTarget& target, const Points2& pts, const SE2& T) {
    if (pts.empty() || target.size() == 0) return 0.0;
    constexpr double kMargin = 0.3, kStep = 0.1, kNear2 = 0.1 * 0.1;
    const double min_sin = std::sin(20.0 * kDeg);
    const std::size_t stride = std::max<std::size_t>(1, pts.size() / 150);
    const Eigen::Vector2d o = T.translation();
    std::size_t n = 0, through = 0;
    for (std::size_t i = 0; i < pts.size(); i += stride) {
      ++n;
      const Eigen::Vector2d q = T * pts[i];
      const double len = (q - o).norm() - kMargin;
      const Eigen::Vector2d dir = (q - o).normalized();
      for (double t = kMargin; t < len; t += kStep) {
        const Eigen::Vector2d a = o + t * dir;
        double d2 = 0.0;
        const std::size_t j = target.nearestWithin(a, kNear2, &d2);
        if (j >= target.size()) continue;
        const Eigen::Vector2d& nj = target.normals()[j];
        if (nj.squaredNorm() < 0.5 || std::abs(nj.dot(dir)) < min_sin) continue;
        const Eigen::Vector2d& pj = target.points()[j];
        const double d0 = nj.dot(a - pj), d1 = d0 + kStep * nj.dot(dir);
        if (d0 * d1 > 0.0) continue;
        const Eigen::Vector2d c = a + dir * (kStep * d0 / (d0 - d1));
        if ((c - pj).squaredNorm() <= kNear2) {
          ++through;
          break;
        }
      }
    }
    return static_cast<double>(through) / static_cast<double>(n);
  }

  Points2 scanPoints(const Frame& f) const {
    Points2 pts;
    const LaserScan& s = f.scan;
    pts.reserve(s.size());
    for (std::size_t i : s.validIndices()) {
      const double r = s.ranges()[i];
      if (!(r < opt.max_range_m)) continue;
      const double a = s.angle(i);
      pts.push_back(f.T_robot_laser * Eigen::Vector2d(r * std::cos(a), r * std::sin(a)));
    }
    return pts;
  }

  void rebuildLocalMap() {
    local_points.clear();
    for (std::size_t n : local_nodes)
      for (const auto& p : node_points[n]) local_points.push_back(nodes[n].T_local_robot * p);
    local_points = voxelFilter(local_points, opt.map_voxel_m);
    local_target = std::make_unique<IcpTarget>(local_points, icp);
    if (opt.front_end_likelihood_field)
      local_field = std::make_unique<registration::LikelihoodField>(
          registration::LikelihoodField::fromPoints(local_points, local_lf));
    local_grid.reset();
  }

  /// The constant-velocity step: the component-wise median (x, y, theta) of the last
  /// `kVelocitySteps` steps, identity before the first. Not the last step alone: a scan stamped out
  /// of order (the Intel bag has some) matches 0.1-0.2 m behind its neighbours, and repeating that
  /// step along a corridor - where the scan cannot correct the prediction's translation along it
  /// (degeneracy) - drove the estimate backwards by that much on every scan until the corridor
  /// ended (metres of error without odometry).
  SE2 velocityStep() const {
    if (recent_steps.empty()) return SE2();
    std::array<std::array<double, kVelocitySteps>, 3> v{};
    const std::size_t n = recent_steps.size();
    for (std::size_t i = 0; i < n; ++i) {
      v[0][i] = recent_steps[i].x();
      v[1][i] = recent_steps[i].y();
      v[2][i] = recent_steps[i].theta();
    }
    auto median = [n](std::array<double, kVelocitySteps>& a) {
      const auto mid = a.begin() + static_cast<std::ptrdiff_t>(n / 2);
      std::nth_element(a.begin(), mid, a.begin() + static_cast<std::ptrdiff_t>(n));
      return *mid;
    };
    return SE2(median(v[0]), median(v[1]), median(v[2]));
  }

  /// Front-end match of `pts` against the local map from `T_pred`. Returns the pose, or nothing
  /// when the scan could not be matched; sets `degenerate`/`dir` (local frame) and `used_fallback`.
  /// `alternatives`: other starting points, tried when the prediction is not confirmed. `earlier`:
  /// the poses of earlier scans, tried when the best match still explains under `earlier_below`.
  std::optional<SE2> frontEndMatch(const Points2& pts, const SE2& T_pred, const std::vector<SE2>& alternatives,
                                   const std::vector<SE2>& earlier, double earlier_below,
                                   bool& degenerate, Eigen::Vector2d& dir, bool& used_fallback) {
    degenerate = false;
    used_fallback = false;
    if (!local_target || local_target->size() < opt.min_points || pts.size() < opt.min_points) return std::nullopt;
    auto tryFrom = [&](const SE2& init, registration::Result& out, double& explained) {
      out = opt.front_end_likelihood_field ? registration::matchLikelihoodField(*local_field, pts, init, local_lf)
                                           : alignIcp(*local_target, pts, init, icp);
      const bool ok = out.status == registration::Status::kConverged || out.status == registration::Status::kMaxIterations;
      explained = ok && out.T_target_source.isFinite() ? explainedFraction(*local_target, pts, out.T_target_source) : 0.0;
    };
    registration::Result res;
    double explained = 0.0;
    tryFrom(T_pred, res, explained);
    // Other starting points (no motion, constant velocity) when the prediction may be wrong: wheel
    // odometry interpolated at badly stamped scans can be tens of degrees off, and ICP from there
    // settles in a wrong minimum that still explains much of the scan. Another start wins when its
    // result explains clearly more points (5% of the scan) than the prediction's, or about as many
    // with a clearly lower residual cost.
    // Only when the prediction was not confirmed: the match moved it or explains too little.
    const SE2 correction = T_pred.inverse() * res.T_target_source;
    const bool confirmed = explained >= kConfirmExplained && correction.translation().norm() <= 0.05 && std::abs(correction.theta()) <= 2.0 * kDeg;
    auto consider = [&](const SE2& start) {
      registration::Result r;
      double e = 0.0;
      tryFrom(start, r, e);
      if (e > explained + 0.05 || (e > explained - 0.05 && r.final_cost < 0.8 * res.final_cost)) {
        res = r;
        explained = e;
      }
    };
    if (!confirmed) {
      for (const SE2& alt : alternatives) consider(alt);
      // Earlier scans' poses only while the match explains too little: where they won on Intel
      // (with odometry) the prediction's match explained a median 41% of the scan, a few up to 89%.
      if (explained < earlier_below)
        for (const SE2& start : earlier) consider(start);
    }
    if (explained < opt.min_explained_fraction) {
      // Olson's correlative search over a window around the prediction, then ICP from its answer.
      if (!local_grid) local_grid = std::make_unique<CorrelativeGrid>(CorrelativeGrid::fromPoints(local_points, fallback));
      const auto cr = registration::matchCorrelative(*local_grid, pts, T_pred, fallback);
      used_fallback = true;
      if (!cr.T_search.isFinite()) return std::nullopt;
      tryFrom(cr.T_search, res, explained);
      if (explained < opt.min_explained_fraction) return std::nullopt;
    }
    SE2 T = res.T_target_source;
    // Degeneracy (Zhang, Kaess & Singh 2016): the translational block of the information matrix per
    // matched point; a weak eigen-direction is not pinned by the scan, so the translation along it
    // is taken from the prediction (solution remapping) instead of whatever the solver slid to.
    if (res.num_inliers > 0) {
      const Eigen::Matrix2d Ht = res.information.topLeftCorner<2, 2>() / static_cast<double>(res.num_inliers);
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(Ht);
      if (es.info() == Eigen::Success && es.eigenvalues()(0) < opt.degeneracy_threshold) {
        degenerate = true;
        dir = es.eigenvectors().col(0).normalized();
        const Eigen::Vector2d t = T.translation() - dir * dir.dot(T.translation() - T_pred.translation());
        T = SE2(t, T.theta());
      }
    }
    return T;
  }

  void addEdge(Constraint c, const Eigen::Matrix3d& sqrt_info, double huber) {
    if (c.accepted) edges.push_back({c.from, c.to, c.T_from_to, sqrt_info, huber});
    constraints.push_back(std::move(c));
  }

  static Eigen::Matrix3d diagSqrtInfo(double sm, double sr) {
    return Eigen::Vector3d(1.0 / sm, 1.0 / sm, 1.0 / sr).asDiagonal();
  }

  void addNode(const Frame& f, std::size_t scan_index, const SE2& T_local, Points2 pts, const Points2& raw,
               bool degenerate, const Eigen::Vector2d& dir_local, bool restart, bool odom_trusted) {
    const std::size_t n = nodes.size();
    Node node;
    node.scan = scan_index;
    node.time = f.time;
    node.T_local_robot = T_local;
    node.T_world_robot = T_world_local * T_local;
    node.degenerate = degenerate;
    if (degenerate) {
      const Eigen::Vector2d d = T_local.rotation().transpose() * dir_local;
      node.degenerate_dir_rad = std::atan2(d.y(), d.x());
    }
    if (submaps.empty() || submaps.back().finished) {
      submaps.emplace_back();
      submaps.back().anchor = n;
    }
    node.submap = submaps.size() - 1;
    submaps.back().nodes.push_back(n);
    nodes.push_back(node);
    node_points.push_back(std::move(pts));
    node_scans.emplace_back(f.scan, f.T_robot_laser);
    node_odometry.push_back(f.T_odom_robot && odom_trusted ? f.T_odom_robot : std::nullopt);
    node_path_m.push_back(n == 0 ? 0.0
                                 : node_path_m[n - 1] +
                                       (nodes[n - 1].T_local_robot.translation() - T_local.translation()).norm());
    node_lines.emplace_back();
    if (opt.descriptor_loops) {
      const auto t0 = Clock::now();
      // From every point in scan order (the voxel filter would blur the corners the split needs).
      node_lines.back() = localization::extractLines(raw, descriptor_query.lines);
      if (node_lines.back().size() > opt.descriptor_max_lines) node_lines.back().resize(opt.descriptor_max_lines);
      stats.descriptor_seconds += secondsSince(t0);
    }

    if (n > 0) {
      const Node& prev = nodes[n - 1];
      Constraint c;
      c.kind = Constraint::Kind::kSequential;
      c.from = n - 1;
      c.to = n;
      c.T_from_to = prev.T_local_robot.inverse() * T_local;
      Eigen::Matrix3d sqrt_info = diagSqrtInfo(opt.sequential_sigma_m, opt.sequential_sigma_rad);
      if (restart) {
        // Tracking was lost: the link is only the prediction.
        sqrt_info = diagSqrtInfo(opt.odometry_sigma_m * 20.0, opt.odometry_sigma_rad * 20.0);
      } else if (degenerate) {
        // Along the degenerate direction the relative pose is as good as the prediction.
        const Eigen::Vector2d v = prev.T_local_robot.rotation().transpose() * dir_local;
        const Eigen::Vector2d p(-v.y(), v.x());
        sqrt_info.setZero();
        sqrt_info.block<1, 2>(0, 0) = v.transpose() / (opt.odometry_sigma_m * 2.0);
        sqrt_info.block<1, 2>(1, 0) = p.transpose() / opt.sequential_sigma_m;
        sqrt_info(2, 2) = 1.0 / opt.sequential_sigma_rad;
      }
      addEdge(std::move(c), sqrt_info, 0.0);
      if (node_odometry[n - 1] && node_odometry[n]) {
        Constraint o;
        o.kind = Constraint::Kind::kOdometry;
        o.from = n - 1;
        o.to = n;
        o.T_from_to = node_odometry[n - 1]->inverse() * *node_odometry[n];
        const double sm = opt.odometry_sigma_m + 0.1 * o.T_from_to.translation().norm();
        const double sr = opt.odometry_sigma_rad + 0.1 * std::abs(o.T_from_to.theta());
        addEdge(std::move(o), diagSqrtInfo(sm, sr), 0.0);
      }
    }

    if (restart) local_nodes.clear();
    local_nodes.push_back(n);
    while (static_cast<int>(local_nodes.size()) > opt.local_map_nodes) local_nodes.pop_front();
    rebuildLocalMap();

    Submap& sm = submaps.back();
    if (static_cast<int>(sm.nodes.size()) >= opt.submap_nodes) finishSubmap(sm);

    ++nodes_since_optimization;
    searchLoops(n);
    // A closure found by search may move the global estimate a lot (later searches are centred on
    // it): optimise soon. Closures that follow a link refine what is known: optimise now and then.
    const bool prompt = searched_loop_pending && static_cast<int>(nodes_since_optimization) >= opt.optimize_every_nodes;
    const bool periodic = loops_since_optimization > 0 && static_cast<int>(nodes_since_optimization) >= 10 * opt.optimize_every_nodes;
    if (descriptor_loop_accepted) {
      // A descriptor closure corrects a large drift: the estimate must follow it at once, or the
      // proximity search keeps looking in the wrong place.
      optimize(std::max(opt.intermediate_iterations, opt.graph.max_iterations));
      descriptor_loop_accepted = false;
    } else if (periodic || prompt) {
      optimize(opt.intermediate_iterations);
    }
  }

  void finishSubmap(Submap& sm) {
    const SE2 T_anchor_local = nodes[sm.anchor].T_local_robot.inverse();
    sm.points_anchor.clear();
    Eigen::Vector2d center = Eigen::Vector2d::Zero();
    for (std::size_t n : sm.nodes) {
      const SE2 T = T_anchor_local * nodes[n].T_local_robot;
      center += T.translation();
      for (const auto& p : node_points[n]) sm.points_anchor.push_back(T * p);
    }
    sm.center_anchor = center / static_cast<double>(sm.nodes.size());
    sm.points_anchor = voxelFilter(sm.points_anchor, opt.map_voxel_m);
    sm.icp = std::make_unique<IcpTarget>(sm.points_anchor, loop_icp);
    sm.finished = true;
    if (opt.descriptor_loops) {
      // Every node is a database position (anchor frame) with its lines turned into the anchor's
      // orientation: the localizer's lookup then answers poses in the anchor frame.
      const auto t0 = Clock::now();
      std::vector<localization::Database::Position> positions;
      std::vector<localization::Database::LineFeature> features;
      for (std::size_t n : sm.nodes) {
        if (node_lines[n].size() < 2) continue;
        const SE2 T = T_anchor_local * nodes[n].T_local_robot;
        localization::Database::Position pos;
        pos.x = static_cast<float>(T.x());
        pos.y = static_cast<float>(T.y());
        pos.first_line = static_cast<std::uint32_t>(features.size());
        pos.num_lines = static_cast<std::uint32_t>(node_lines[n].size());
        for (const auto& l : node_lines[n])
          features.push_back({static_cast<float>(wrapAngle(l.normal_angle + T.theta())), static_cast<float>(l.distance),
                              static_cast<float>(l.length)});
        positions.push_back(pos);
      }
      sm.db = std::make_unique<localization::Database>(
          localization::Database::fromParts(descriptor_db, 0, std::move(positions), std::move(features)));
      stats.descriptor_seconds += secondsSince(t0);
    }
  }

  void searchLoops(std::size_t n) {
    const Node& node = nodes[n];
    const Points2& pts = node_points[n];
    if (pts.size() < opt.min_points) return;
    // Candidate submaps by distance, nearest first.
    std::vector<std::pair<double, std::size_t>> candidates;
    std::vector<char> covered(submaps.size(), 0);  // submaps this search considers
    for (std::size_t s = 0; s < submaps.size(); ++s) {
      const Submap& sm = submaps[s];
      if (!sm.finished) continue;
      // Submaps still in the local map are tied to this node by the sequential chain already.
      if (sm.nodes.back() + static_cast<std::size_t>(opt.local_map_nodes) >= n) continue;
      const Eigen::Vector2d center_world = nodes[sm.anchor].T_world_robot * sm.center_anchor;
      const double d = (center_world - node.T_world_robot.translation()).norm();
      if (d <= opt.loop_search_radius_m) {
        candidates.emplace_back(d, s);
        covered[s] = 1;
      }
    }
    std::sort(candidates.begin(), candidates.end());
    int searches_left = opt.loop_searches_per_node;
    for (const auto& [dist, s] : candidates) {
      Submap& sm = submaps[s];
      const SE2& T_world_anchor = nodes[sm.anchor].T_world_robot;

      Constraint c;
      c.kind = Constraint::Kind::kLoop;
      c.from = sm.anchor;
      c.to = n;
      SE2 init;
      if (sm.last_link_node && n - *sm.last_link_node <= static_cast<std::size_t>(opt.loop_link_memory_nodes)) {
        const std::size_t m = *sm.last_link_node;
        init = sm.last_link_T_anchor_node * (nodes[m].T_local_robot.inverse() * node.T_local_robot);
      } else if (n % static_cast<std::size_t>(opt.loop_search_every_nodes) == 0 && searches_left > 0) {
        --searches_left;
        const SE2 guess = T_world_anchor.inverse() * node.T_world_robot;
        const auto cr = registration::matchCorrelative(gridOf(s), voxelFilter(pts, 2.0 * opt.scan_voxel_m), guess, loop_search);
        ++stats.loop_searches;
        c.searched = true;
        c.score = cr.score;
        if (!cr.T_search.isFinite() || cr.score < opt.loop_min_score) continue;  // no candidate: nothing to record
        init = cr.T_search;
      } else {
        continue;
      }
      const registration::Result res = alignIcp(*sm.icp, pts, init, loop_icp);
      c.T_from_to = res.T_target_source;
      c.explained = res.T_target_source.isFinite() ? explainedFraction(*sm.icp, pts, res.T_target_source) : 0.0;
      const bool ok = res.status == registration::Status::kConverged || res.status == registration::Status::kMaxIterations;
      const SE2 d = init.inverse() * res.T_target_source;
      if (!ok) {
        c.accepted = false;
        c.reason = fmt::format("refinement failed ({})", registration::toString(res.status));
      } else if (c.explained < opt.loop_min_explained_fraction) {
        c.accepted = false;
        c.reason = fmt::format("explains {:.0f}% of the points", 100.0 * c.explained);
      } else if (!c.searched && (d.translation().norm() > 0.2 || std::abs(d.theta()) > 3.0 * kDeg)) {
        c.accepted = false;
        c.reason = "disagrees with the submap's recent link";
      } else if (c.searched && (d.translation().norm() > 0.3 || std::abs(d.theta()) > 5.0 * kDeg)) {
        c.accepted = false;
        c.reason = "refinement left the search's answer";
      }
      if (!c.accepted) {
        if (c.searched) {
          // Only searched closures are worth listing when rejected; link-following ones are routine.
          ++stats.loop_rejected;
          addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
        }
        continue;
      }
      if (c.searched) {
        submitSearched(std::move(c), sm);
        continue;
      }
      acceptLoop(c, sm);
    }
    descriptorLoops(n, covered);
  }

  /// A searched closure is only accepted once a second, independent search from a later node
  /// agrees with it through the front end's chain of relative poses (a wrong match in a
  /// self-similar place rarely repeats consistently); until then it is pending.
  void submitSearched(Constraint c, Submap& sm) {
    std::optional<Constraint> confirmed;
    if (sm.pending) {
      const Constraint& p = *sm.pending;
      const SE2 predicted = p.T_from_to * (nodes[p.to].T_local_robot.inverse() * nodes[c.to].T_local_robot);
      const SE2 diff = predicted.inverse() * c.T_from_to;
      const bool recent = c.to - p.to <= static_cast<std::size_t>(opt.loop_confirm_window_nodes);
      if (recent && diff.translation().norm() <= opt.loop_confirm_tolerance_m &&
          std::abs(diff.theta()) <= opt.loop_confirm_tolerance_rad) {
        confirmed = p;
      } else {
        Constraint old = p;
        old.accepted = false;
        old.reason = recent ? "contradicted by a later search" : "not confirmed by a later search";
        ++stats.loop_rejected;
        addEdge(std::move(old), Eigen::Matrix3d::Zero(), 0.0);
      }
      sm.pending.reset();
    }
    if (!confirmed) {
      sm.pending = std::move(c);
      return;
    }
    acceptLoop(*confirmed, sm);
    searched_loop_pending = true;
    acceptLoop(std::move(c), sm);
  }

  /// Descriptor loop candidates (large drift): the current node's lines are looked up in the
  /// descriptor index of every old submap; the best-voted (submap, pose) hypotheses are verified
  /// like searched closures (branch and bound in a small window, ICP, score, explained fraction).
  /// Only a hypothesis in a submap the proximity search does not consider can become a descriptor
  /// closure, and only when it is plausible for the drift (the correction it makes), the submaps
  /// around the current estimate do not explain the scan already, and no distinct hypothesis
  /// passes as well (an aliased place). Hypotheses in the submaps the proximity search considers
  /// take part as competitors only: when one of them wins, the estimate has not drifted.
  void descriptorLoops(std::size_t n, const std::vector<char>& covered) {
    if (!opt.descriptor_loops || node_lines[n].size() < 2) return;
    const auto t0 = Clock::now();
    const Node& node = nodes[n];
    // Look up one node in descriptor_every_nodes while the proximity search finds nothing, and
    // every node on from a pending descriptor closure until a second one confirms it (from a node
    // some way on: the same view from nearly the same pose confirms nothing).
    bool confirming = false;
    for (std::size_t s = 0; s < submaps.size(); ++s) {
      const auto& p = submaps[s].pending;
      confirming = confirming || (!covered[s] && p && p->descriptor &&
                                  n - p->to >= static_cast<std::size_t>(opt.loop_search_every_nodes) &&
                                  n - p->to <= static_cast<std::size_t>(opt.loop_confirm_window_nodes));
    }
    const bool quiet = !last_loop_node || n - *last_loop_node > static_cast<std::size_t>(opt.descriptor_quiet_nodes);
    if (!confirming && !(quiet && n % static_cast<std::size_t>(opt.descriptor_every_nodes) == 0)) return;
    std::vector<std::size_t> targets;
    for (std::size_t s = 0; s < submaps.size(); ++s) {
      const Submap& sm = submaps[s];
      if (!sm.db || sm.db->empty()) continue;
      if (sm.nodes.back() + static_cast<std::size_t>(opt.descriptor_min_age_nodes) > n) continue;
      targets.push_back(s);
    }
    if (targets.empty()) return;
    ++stats.descriptor_queries;

    struct Hypothesis {
      double votes = 0.0;
      std::size_t submap = 0;
      SE2 T_anchor_node;
    };
    std::vector<Hypothesis> hyps;
    for (std::size_t s : targets)
      for (const auto& v : localization::voteLinePairs(*submaps[s].db, node_lines[n], descriptor_query, 4))
        if (v.votes >= opt.descriptor_min_votes) hyps.push_back({v.votes, s, v.T_world_robot});
    std::stable_sort(hyps.begin(), hyps.end(), [](const Hypothesis& a, const Hypothesis& b) { return a.votes > b.votes; });

    const Points2& pts = node_points[n];
    const Points2 coarse = voxelFilter(pts, 2.0 * opt.scan_voxel_m);
    // How well the submaps around the current estimate explain the scan where it is now: when they
    // do, the estimate has not drifted and a hypothesis elsewhere is an aliased place.
    double current_explained = 0.0;
    for (std::size_t s = 0; s < submaps.size(); ++s)
      if (covered[s] && submaps[s].icp)
        current_explained = std::max(current_explained,
                                     explainedFraction(*submaps[s].icp, pts,
                                                       nodes[submaps[s].anchor].T_world_robot.inverse() * node.T_world_robot));
    std::vector<Constraint> passed;  // verified and plausible, in vote order
    std::vector<char> passed_covered;
    std::vector<SE2> tried;  // world poses of the hypotheses verified (neighbouring bins of one pose are skipped)
    for (const Hypothesis& h : hyps) {
      if (static_cast<int>(tried.size()) >= opt.descriptor_max_candidates) break;
      Submap& sm = submaps[h.submap];
      const SE2& T_world_anchor = nodes[sm.anchor].T_world_robot;
      const SE2 guess_world = T_world_anchor * h.T_anchor_node;
      bool dup = false;
      for (const SE2& t : tried)
        dup = dup || ((t.translation() - guess_world.translation()).norm() < 2.0 * descriptor_query.vote_bin_m &&
                      std::abs(angleDiff(t.theta(), guess_world.theta())) < 2.0 * descriptor_query.vote_bin_rad);
      if (dup) continue;
      tried.push_back(guess_world);
      ++stats.descriptor_hypotheses;
      const auto cr = registration::matchCorrelative(gridOf(h.submap), coarse, h.T_anchor_node, descriptor_search);
      if (!cr.T_search.isFinite() || cr.score < opt.loop_min_score) continue;  // no candidate: nothing to record
      Constraint c;
      c.kind = Constraint::Kind::kLoop;
      c.from = sm.anchor;
      c.to = n;
      c.searched = true;
      c.descriptor = true;
      c.score = cr.score;
      const registration::Result res = alignIcp(*sm.icp, pts, cr.T_search, loop_icp);
      c.T_from_to = res.T_target_source;
      c.explained = res.T_target_source.isFinite() ? explainedFraction(*sm.icp, pts, res.T_target_source) : 0.0;
      const bool ok = res.status == registration::Status::kConverged || res.status == registration::Status::kMaxIterations;
      const SE2 d = cr.T_search.inverse() * res.T_target_source;
      // The correction the closure makes to the current estimate must fit the drift the front end
      // can have accumulated since it last saw that submap.
      const SE2 implied = T_world_anchor * c.T_from_to;
      const double correction = (implied.translation() - node.T_world_robot.translation()).norm();
      const double turn = std::abs(angleDiff(implied.theta(), node.T_world_robot.theta()));
      const double path = node_path_m[n] - node_path_m[sm.nodes.back()];
      const double allowed = opt.descriptor_max_correction_m + opt.descriptor_drift_fraction * path;
      if (!ok) {
        c.accepted = false;
        c.reason = fmt::format("refinement failed ({})", registration::toString(res.status));
      } else if (c.explained < opt.loop_min_explained_fraction) {
        c.accepted = false;
        c.reason = fmt::format("explains {:.0f}% of the points", 100.0 * c.explained);
      } else if (d.translation().norm() > 0.3 || std::abs(d.theta()) > 5.0 * kDeg) {
        c.accepted = false;
        c.reason = "refinement left the search's answer";
      } else if (correction > allowed || turn > opt.descriptor_max_rotation_rad) {
        c.accepted = false;
        c.reason = fmt::format("implausible correction of {:.1f} m / {:.0f} deg after {:.0f} m of path", correction,
                               turn / kDeg, path);
      } else if (const double through = seeThroughFraction(*sm.icp, pts, c.T_from_to);
                 through > opt.descriptor_max_see_through) {
        c.accepted = false;
        c.reason = fmt::format("sees through the submap's walls ({:.0f}% of the beams)", 100.0 * through);
      } else if (!covered[h.submap] && current_explained >= opt.loop_min_explained_fraction) {
        c.accepted = false;
        c.reason = fmt::format("the current estimate explains {:.0f}% of the points already", 100.0 * current_explained);
      }
      if (c.accepted) {
        passed.push_back(std::move(c));
        passed_covered.push_back(covered[h.submap]);
      } else if (!covered[h.submap]) {
        ++stats.loop_rejected;
        addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
      }
    }
    // Two distinct places that both pass: the scan cannot tell them apart (a symmetric building).
    bool ambiguous = false;
    for (std::size_t i = 1; i < passed.size(); ++i) {
      const SE2 a = nodes[passed[0].from].T_world_robot * passed[0].T_from_to;
      const SE2 b = nodes[passed[i].from].T_world_robot * passed[i].T_from_to;
      ambiguous = ambiguous || (a.translation() - b.translation()).norm() > 1.0 ||
                  std::abs(angleDiff(a.theta(), b.theta())) > 10.0 * kDeg;
    }
    bool near_estimate = false;  // a submap around the current estimate matches: no drift to correct
    for (char cov : passed_covered) near_estimate = near_estimate || cov;
    for (std::size_t i = 0; i < passed.size(); ++i) {
      if (passed_covered[i]) continue;
      Constraint& c = passed[i];
      if (ambiguous) {
        c.accepted = false;
        c.reason = fmt::format("ambiguous: {} distinct places match", passed.size());
        ++stats.loop_rejected;
        addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
      } else if (!near_estimate && i == 0) {
        Submap& sm = submaps[nodes[c.from].submap];
        submitSearched(std::move(c), sm);
      }
    }
    stats.descriptor_seconds += secondsSince(t0);
  }

  /// The score grid of a finished submap for the branch-and-bound searches, from its occupancy grid
  /// built with the mapping module: every node's scan inserted (log-odds, ray traced) at its pose in
  /// the anchor's frame. A finished submap is frozen (the front end's relative poses of its nodes
  /// no longer change), so the grid can be dropped and rebuilt alike.
  CorrelativeGrid submapGrid(const Submap& sm) const {
    mapping::MapOptions mo;
    mo.resolution_m = loop_search.resolution_m;
    mo.insert.max_range_m = opt.max_range_m;
    const auto map = mapping::makeMap(mapping::MapModel::kLogOdds, mo);
    const SE2 T_anchor_local = nodes[sm.anchor].T_local_robot.inverse();
    for (const std::size_t n : sm.nodes)
      map->insert(node_scans[n].first, T_anchor_local * nodes[n].T_local_robot * node_scans[n].second);
    const OccupancyImage image = mapping::toOccupancyImage(*map);
    if (image.width() == 0) return CorrelativeGrid::fromPoints(sm.points_anchor, loop_search);
    return CorrelativeGrid::fromMap(image, loop_search);
  }

  /// The correlative grid of submap `s`, built on demand. Only the most recently used few are kept:
  /// a grid with its max-grids takes megabytes, and a long run would otherwise hold one per submap.
  const CorrelativeGrid& gridOf(std::size_t s) {
    Submap& sm = submaps[s];
    grid_lru.erase(std::remove(grid_lru.begin(), grid_lru.end(), s), grid_lru.end());
    grid_lru.push_back(s);
    if (!sm.grid) sm.grid = std::make_unique<CorrelativeGrid>(submapGrid(sm));
    while (grid_lru.size() > kMaxGrids) {
      submaps[grid_lru.front()].grid.reset();
      grid_lru.erase(grid_lru.begin());
    }
    return *sm.grid;
  }

  void acceptLoop(Constraint c, Submap& sm) {
    ++stats.loop_accepted;
    if (!last_loop_node || c.to > *last_loop_node) last_loop_node = c.to;
    const bool descriptor = c.descriptor;
    if (descriptor) {
      ++stats.descriptor_accepted;
      descriptor_loop_accepted = true;
      const ScanRecord& r = scans[nodes[c.to].scan];
      const double correction =
          ((nodes[c.from].T_world_robot * c.T_from_to).translation() - nodes[c.to].T_world_robot.translation()).norm();
      events.push_back({r.frame_index, r.time,
                        fmt::format("loop closure found by descriptors: node {} to submap {}, correcting {:.2f} m of drift",
                                    c.to, nodes[c.from].submap, correction)});
    }
    if (!sm.last_link_node || c.to > *sm.last_link_node) {
      sm.last_link_node = c.to;
      sm.last_link_T_anchor_node = c.T_from_to;
    }
    ++loops_since_optimization;
    // A descriptor closure corrects metres of drift: under the robust loss it could not pull the
    // chain of stiff front-end edges that far. It has passed the stricter tests (and a second
    // closure confirms it), so it is a plain quadratic constraint.
    addEdge(std::move(c), diagSqrtInfo(opt.loop_sigma_m, opt.loop_sigma_rad), descriptor ? 0.0 : opt.loop_huber);
  }

  /// Pending closures that were never confirmed are listed as rejected at the end.
  void expirePending() {
    for (Submap& sm : submaps)
      if (sm.pending) {
        Constraint old = *sm.pending;
        old.accepted = false;
        old.reason = "not confirmed by a later search";
        ++stats.loop_rejected;
        addEdge(std::move(old), Eigen::Matrix3d::Zero(), 0.0);
        sm.pending.reset();
      }
  }

  void optimize(int iterations) {
    if (nodes.size() < 2) return;
    std::vector<SE2> poses;
    poses.reserve(nodes.size());
    for (const Node& n : nodes) poses.push_back(n.T_world_robot);
    PoseGraphOptions go = opt.graph;
    go.max_iterations = iterations;
    const PoseGraphSummary summary = optimizePoseGraph(poses, edges, 0, go);
    ++stats.optimizations;
    stats.optimization_seconds += summary.seconds;
    if (summary.usable)
      for (std::size_t i = 0; i < nodes.size(); ++i) nodes[i].T_world_robot = poses[i];
    T_world_local = nodes.back().T_world_robot * nodes.back().T_local_robot.inverse();
    nodes_since_optimization = 0;
    loops_since_optimization = 0;
    searched_loop_pending = false;
  }

  void add(const Frame& f) {
    const auto t0 = Clock::now();
    if (finished) throw invalidArgument("add() after finish()", {"Slam", 0, "add"});
    const Points2 raw = scanPoints(f);
    Points2 pts = voxelFilter(raw, opt.scan_voxel_m);
    ScanRecord rec;
    rec.frame_index = f.index;
    rec.time = f.time;
    const std::size_t scan_index = scans.size();

    // Prediction: odometry when present and sane, else constant velocity (identity across gaps).
    SE2 delta;
    bool odom_trusted = false;
    bool time_ok = true;
    if (have_prev) {
      const double dt = f.time - time_prev;
      if (dt < 0.0) {
        event(f, fmt::format("time goes backwards by {:.3f} s", -dt));
        time_ok = false;
      } else if (dt > opt.time_gap_s) {
        event(f, fmt::format("gap of {:.1f} s in the log", dt));
        time_ok = false;
      }
    }
    if (opt.use_odometry && f.T_odom_robot) {
      if (odometry_missing) {
        event(f, fmt::format("odometry back after {} scans without it", odometry_missing_count));
        odometry_missing = false;
      }
      odometry_seen = true;
      if (have_prev && odom_prev) {
        const SE2 d = odom_prev->inverse() * *f.T_odom_robot;
        if (!d.isFinite() || d.translation().norm() > opt.odometry_jump_m || std::abs(d.theta()) > opt.odometry_jump_rad) {
          event(f, fmt::format("odometry jumps by {:.2f} m / {:.1f} deg: not used for this scan",
                               d.translation().norm(), std::abs(d.theta()) / kDeg));
        } else {
          delta = d;
          odom_trusted = true;
        }
      }
    } else if (opt.use_odometry && odometry_seen) {
      if (!odometry_missing) event(f, "scans without odometry from here: constant-velocity prediction");
      odometry_missing = true;
      ++odometry_missing_count;
    }
    if (have_prev && !odom_trusted) delta = time_ok ? velocityStep() : SE2();

    if (!have_prev) {
      // The first scan anchors everything (at its odometry pose, so the map lines up with it).
      const SE2 T0 = opt.use_odometry && f.T_odom_robot ? *f.T_odom_robot : SE2();
      T_world_local = SE2();
      rec.node = 0;
      rec.is_node = true;
      rec.matched = true;
      scans.push_back(rec);
      addNode(f, scan_index, T0, std::move(pts), raw, false, Eigen::Vector2d::Zero(), false, true);
      T_local_prev = T0;
    } else {
      const SE2 T_pred = T_local_prev * delta;
      bool degenerate = false, used_fallback = false;
      Eigen::Vector2d dir = Eigen::Vector2d::Zero();
      std::vector<SE2> alternatives;
      const SE2 pred_delta = T_local_prev.inverse() * T_pred;
      if (pred_delta.translation().norm() > opt.alternative_start_m || std::abs(pred_delta.theta()) > opt.alternative_start_rad) {
        alternatives.push_back(T_local_prev);
        if (odom_trusted) alternatives.push_back(T_local_prev * (recent_steps.empty() ? SE2() : recent_steps.back()));
      }
      // Also the poses of a few earlier scans: a scan logged late (the Intel bag has runs of them,
      // up to a second old while the robot turns at 40 deg/s) was taken near one of them, tens of
      // degrees from the prediction (constant velocity, or odometry interpolated at its wrong
      // stamp); and the scan after it continues from the scan before it, not from its pose.
      std::vector<SE2> earlier;
      for (const std::size_t back : kEarlierBack) {
        if (recent_poses.size() < back) break;
        const SE2& T = recent_poses[recent_poses.size() - back];
        const SE2 d = T_pred.inverse() * T;
        if (d.translation().norm() > opt.alternative_start_m || std::abs(d.theta()) > opt.alternative_start_rad)
          earlier.push_back(T);
      }
      // Tried below 90% explained without odometry (the prediction is only a guess; scan-only
      // Intel is sensitive to this threshold, BENCHMARK.md), below 80% with it: on freiburg-079
      // the 80-90% band tried ICP 2900 times and never won (a quarter more time), while on Intel
      // 0.8 and 0.7 held the result at 0.017-0.022 m under changes of other parameters (0.5 did
      // not).
      const double earlier_below = odom_trusted ? kEarlierWithOdometry : kConfirmExplained;
      std::optional<SE2> T_match =
          frontEndMatch(pts, T_pred, alternatives, earlier, earlier_below, degenerate, dir, used_fallback);
      if (used_fallback) ++stats.correlative_fallbacks;
      SE2 T_est = T_pred;
      bool restart = false;
      if (T_match) {
        T_est = *T_match;
        rec.matched = true;
        consecutive_failures = 0;
        ++stats.matched;
        if (degenerate) ++stats.degenerate;
      } else {
        ++stats.unmatched;
        ++consecutive_failures;
        if (consecutive_failures == 1)
          event(f, pts.size() < opt.min_points ? fmt::format("only {} valid points: pose predicted", pts.size())
                                               : std::string("scan does not match the local map: pose predicted"));
        if (consecutive_failures >= 5 && pts.size() >= opt.min_points) {
          event(f, "lost track for 5 scans: local map restarted here (kidnapping?); loop closure may reconnect");
          restart = true;
          consecutive_failures = 0;
        }
      }
      rec.degenerate = degenerate;
      const Node& last = nodes.back();
      const SE2 rel = last.T_local_robot.inverse() * T_est;
      const bool moved = rel.translation().norm() >= opt.node_min_translation_m ||
                         std::abs(rel.theta()) >= opt.node_min_rotation_rad ||
                         f.time - last.time >= opt.node_max_interval_s;
      if (restart || (rec.matched && moved && pts.size() >= opt.min_points)) {
        rec.node = nodes.size();
        rec.is_node = true;
        scans.push_back(rec);
        addNode(f, scan_index, T_est, std::move(pts), raw, degenerate, dir, restart, odom_trusted);
      } else {
        rec.node = nodes.size() - 1;
        rec.T_node_scan = rel;
        scans.push_back(rec);
      }
      if (!time_ok) recent_steps.clear();
      recent_steps.push_back(time_ok ? T_local_prev.inverse() * T_est : SE2());
      if (recent_steps.size() > kVelocitySteps) recent_steps.pop_front();
      recent_poses.push_back(T_est);
      if (recent_poses.size() > kEarlierBack.back()) recent_poses.pop_front();
      T_local_prev = T_est;
    }
    have_prev = true;
    time_prev = f.time;
    if (f.T_odom_robot) odom_prev = f.T_odom_robot;
    ++stats.scans;
    scans.back().seconds = secondsSince(t0);
    stats.total_seconds += scans.back().seconds;
  }
};

Slam::Slam(const SlamOptions& options) : impl_(std::make_unique<Impl>(options)) {}
Slam::~Slam() = default;

void Slam::add(const Frame& frame) { impl_->add(frame); }

void Slam::finish() {
  if (impl_->finished) return;
  const auto t0 = Clock::now();
  impl_->expirePending();
  impl_->optimize(impl_->opt.graph.max_iterations);
  impl_->finished = true;
  impl_->stats.nodes = impl_->nodes.size();
  impl_->stats.submaps = impl_->submaps.size();
  impl_->stats.total_seconds += secondsSince(t0);
}

std::vector<ScanEstimate> Slam::trajectory() const {
  std::vector<ScanEstimate> out;
  out.reserve(impl_->scans.size());
  for (const ScanRecord& r : impl_->scans) {
    ScanEstimate e;
    e.frame_index = r.frame_index;
    e.time = r.time;
    e.node = r.node;
    e.is_node = r.is_node;
    e.matched = r.matched;
    e.degenerate = r.degenerate;
    e.seconds = r.seconds;
    e.T_world_robot = impl_->nodes[r.node].T_world_robot * r.T_node_scan;
    out.push_back(e);
  }
  return out;
}

const std::vector<Node>& Slam::nodes() const { return impl_->nodes; }
const std::vector<Constraint>& Slam::constraints() const { return impl_->constraints; }
const std::vector<Event>& Slam::events() const { return impl_->events; }
const SlamStats& Slam::stats() const {
  impl_->stats.nodes = impl_->nodes.size();
  impl_->stats.submaps = impl_->submaps.size();
  return impl_->stats;
}
const SlamOptions& Slam::options() const { return impl_->opt; }

}  // namespace lidar2d::slam
