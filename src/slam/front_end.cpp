#include "src/slam/internal/front_end.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <string>

#include "src/slam/internal/points.hpp"

namespace lidar2d::slam::internal {

using registration::alignIcp;
using registration::CorrelativeGrid;
using registration::IcpTarget;

SE2 FrontEnd::firstPose(const Frame& f) const { return opt.use_odometry && f.T_odom_robot ? *f.T_odom_robot : SE2(); }

FrontEnd::Prediction FrontEnd::predict(const Frame& f) {
  // Odometry when present and sane, else constant velocity (identity across gaps).
  Prediction p;
  SE2& delta = p.delta;
  bool& odom_trusted = p.odom_trusted;
  bool& time_ok = p.time_ok;
  if (have_prev) {
    const double dt = f.time - time_prev;
    if (dt < 0.0) {
      s_.event(f, fmt::format("time goes backwards by {:.3f} s", -dt));
      time_ok = false;
    } else if (dt > opt.time_gap_s) {
      s_.event(f, fmt::format("gap of {:.1f} s in the log", dt));
      time_ok = false;
    }
  }
  if (opt.use_odometry && f.T_odom_robot) {
    if (odometry_missing) {
      s_.event(f, fmt::format("odometry back after {} scans without it", odometry_missing_count));
      odometry_missing = false;
    }
    odometry_seen = true;
    if (have_prev && odom_prev) {
      const SE2 d = odom_prev->inverse() * *f.T_odom_robot;
      if (!d.isFinite() || d.translation().norm() > opt.odometry_jump_m ||
          std::abs(d.theta()) > opt.odometry_jump_rad) {
        s_.event(f, fmt::format("odometry jumps by {:.2f} m / {:.1f} deg: not used for this scan",
                                d.translation().norm(), std::abs(d.theta()) / kDeg));
      } else {
        delta = d;
        odom_trusted = true;
      }
    }
  } else if (opt.use_odometry && odometry_seen) {
    if (!odometry_missing) s_.event(f, "scans without odometry from here: constant-velocity prediction");
    odometry_missing = true;
    ++odometry_missing_count;
  }
  if (have_prev && !odom_trusted) delta = time_ok ? velocityStep() : SE2();
  return p;
}

FrontEnd::Tracked FrontEnd::track(const Frame& f, const Points2& pts, const Prediction& p) {
  Tracked out;
  const SE2 T_pred = T_local_prev * p.delta;
  bool used_fallback = false;
  std::vector<SE2> alternatives;
  const SE2 pred_delta = T_local_prev.inverse() * T_pred;
  if (pred_delta.translation().norm() > opt.alternative_start_m ||
      std::abs(pred_delta.theta()) > opt.alternative_start_rad) {
    alternatives.push_back(T_local_prev);
    if (p.odom_trusted) alternatives.push_back(T_local_prev * (recent_steps.empty() ? SE2() : recent_steps.back()));
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
  // Tried below 90% explained without odometry (the prediction is only a guess), below 80% with
  // it: on freiburg-079 the 80-90% band tried ICP thousands of times and never won, while on
  // Intel 0.7 to 0.8 held the result under changes of other parameters (0.5 did not).
  const double earlier_below = p.odom_trusted ? kEarlierWithOdometry : kConfirmExplained;
  std::optional<SE2> T_match =
      frontEndMatch(pts, T_pred, alternatives, earlier, earlier_below, out.degenerate, out.dir, used_fallback);
  if (used_fallback) ++s_.stats.correlative_fallbacks;
  out.T_local_robot = T_pred;
  if (T_match) {
    out.T_local_robot = *T_match;
    out.matched = true;
    consecutive_failures = 0;
    ++s_.stats.matched;
    if (out.degenerate) ++s_.stats.degenerate;
  } else {
    ++s_.stats.unmatched;
    ++consecutive_failures;
    if (consecutive_failures == 1)
      s_.event(f, pts.size() < opt.min_points ? fmt::format("only {} valid points: pose predicted", pts.size())
                                              : std::string("scan does not match the local map: pose predicted"));
    if (consecutive_failures >= 5 && pts.size() >= opt.min_points) {
      s_.event(f, "lost track for 5 scans: local map restarted here (kidnapping?); loop closure may reconnect");
      out.restart = true;
      consecutive_failures = 0;
    }
  }
  return out;
}

void FrontEnd::addNode(std::size_t n, bool restart) {
  if (restart) local_nodes.clear();
  local_nodes.push_back(n);
  while (static_cast<int>(local_nodes.size()) > opt.local_map_nodes) local_nodes.pop_front();
  rebuildLocalMap();
}

void FrontEnd::remember(const Frame& f, const SE2& T_local, bool first, bool time_ok) {
  if (!first) {
    if (!time_ok) recent_steps.clear();
    recent_steps.push_back(time_ok ? T_local_prev.inverse() * T_local : SE2());
    if (recent_steps.size() > kVelocitySteps) recent_steps.pop_front();
    recent_poses.push_back(T_local);
    if (recent_poses.size() > kEarlierBack.back()) recent_poses.pop_front();
  }
  T_local_prev = T_local;
  have_prev = true;
  time_prev = f.time;
  if (f.T_odom_robot) odom_prev = f.T_odom_robot;
}

void FrontEnd::rebuildLocalMap() {
  local_points.clear();
  for (std::size_t n : local_nodes)
    for (const auto& p : s_.node_points[n]) local_points.push_back(s_.nodes[n].T_local_robot * p);
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
SE2 FrontEnd::velocityStep() const {
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
std::optional<SE2> FrontEnd::frontEndMatch(const Points2& pts, const SE2& T_pred, const std::vector<SE2>& alternatives,
                                           const std::vector<SE2>& earlier, double earlier_below, bool& degenerate,
                                           Eigen::Vector2d& dir, bool& used_fallback) {
  degenerate = false;
  used_fallback = false;
  if (!local_target || local_target->size() < opt.min_points || pts.size() < opt.min_points) return std::nullopt;
  auto tryFrom = [&](const SE2& init, registration::Result& out, double& explained) {
    out = opt.front_end_likelihood_field ? registration::matchLikelihoodField(*local_field, pts, init, local_lf)
                                         : alignIcp(*local_target, pts, init, icp);
    const bool ok =
        out.status == registration::Status::kConverged || out.status == registration::Status::kMaxIterations;
    explained = ok && out.T_target_source.isFinite()
                    ? explainedFraction(*local_target, pts, out.T_target_source, opt.match_inlier_distance_m)
                    : 0.0;
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
  const bool confirmed = explained >= kConfirmExplained && correction.translation().norm() <= 0.05 &&
                         std::abs(correction.theta()) <= 2.0 * kDeg;
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
    if (!local_grid)
      local_grid = std::make_unique<CorrelativeGrid>(CorrelativeGrid::fromPoints(local_points, fallback));
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

}  // namespace lidar2d::slam::internal
