#include "src/slam/internal/loop_closure.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <functional>
#include <limits>
#include <numbers>
#include <queue>
#include <string>
#include <utility>

#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "src/slam/internal/descriptor_loops.hpp"
#include "src/slam/internal/motion_prior.hpp"
#include "src/slam/internal/points.hpp"

namespace lidar2d::slam::internal {

using registration::alignIcp;
using registration::IcpTarget;

void LoopClosure::finishSubmap(Submap& sm) {
  const SE2 T_anchor_local = s_.nodes[sm.anchor].T_local_robot.inverse();
  sm.points_anchor.clear();
  sm.nodes_min_anchor = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  sm.nodes_max_anchor = -sm.nodes_min_anchor;
  for (std::size_t n : sm.nodes) {
    const SE2 T = T_anchor_local * s_.nodes[n].T_local_robot;
    sm.nodes_min_anchor = sm.nodes_min_anchor.cwiseMin(T.translation());
    sm.nodes_max_anchor = sm.nodes_max_anchor.cwiseMax(T.translation());
    for (const auto& p : s_.node_points[n]) sm.points_anchor.push_back(T * p);
  }
  sm.points_anchor = voxelFilter(sm.points_anchor, opt.map_voxel_m);
  sm.icp = std::make_unique<IcpTarget>(sm.points_anchor, loop_icp);
  sm.finished = true;
}

std::optional<std::vector<char>> LoopClosure::searchNear(std::size_t n) {
  const Node& node = s_.nodes[n];
  const Points2& pts = s_.node_points[n];
  if (pts.size() < opt.min_points) return std::nullopt;
  // Candidate submaps by distance, nearest first.
  std::vector<std::pair<double, std::size_t>> candidates;
  std::vector<char> covered(s_.submaps.size(), 0);  // submaps this search considers
  // The window follows the estimate's drift, and a submap that far may hold the revisit.
  const double window_m = s_.proximityWindowM(n);
  const double radius_m = std::max(opt.loop_search_radius_m, window_m);
  const bool unplaced = s_.untied_since && n >= *s_.untied_since && !s_.untiedHasOdometryLink();
  for (std::size_t s = 0; s < s_.submaps.size(); ++s) {
    const Submap& sm = s_.submaps[s];
    if (!sm.finished) continue;
    // Submaps still in the local map are tied to this node by the sequential chain already.
    if (sm.nodes.back() + static_cast<std::size_t>(opt.local_map_nodes) >= n) continue;
    // A fragment not yet tied to the map before it, with no odometry across the break (a resumed
    // session, or a lost track without odometry), lies where it was only guessed to be: its distance
    // to that map's submaps means nothing (searchUntied and the descriptors look for its place).
    if (unplaced && sm.nodes.back() < *s_.untied_since) continue;
    const double d = nearestNodeM(sm, node.T_world_robot.translation());
    if (d <= radius_m) {
      candidates.emplace_back(d, s);
      covered[s] = 1;
    }
  }
  std::sort(candidates.begin(), candidates.end());
  int searches_left = opt.loop_searches_per_node;
  // A fragment after a lost track, not yet tied to the map before it, searches at every node: each
  // node of a revisit is a chance to tie it (and to confirm a pending closure). So do the nodes
  // after one placed by the odometry without a match (search_every_node_until).
  const bool every_node = n % static_cast<std::size_t>(opt.loop_search_every_nodes) == 0 ||
                          (s_.untied_since && n >= *s_.untied_since) || n <= s_.search_every_node_until;
  // Listed when rejected: a searched closure (link-following ones are routine).
  auto listRejected = [&](Constraint&& c) {
    ++s_.stats.loop_rejected;
    s_.addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
  };
  std::optional<Points2> sparse;  // the scan for the searches, filtered at the first one
  for (const auto& [dist, s] : candidates) {
    Submap& sm = s_.submaps[s];
    Constraint blank;
    blank.kind = Constraint::Kind::kLoop;
    blank.from = sm.anchor;
    blank.to = n;
    Constraint c = blank;
    if (sm.last_link_node && n - *sm.last_link_node <= static_cast<std::size_t>(opt.loop_link_memory_nodes)) {
      const std::size_t m = *sm.last_link_node;
      refine(c, sm, pts, sm.last_link_T_anchor_node * (s_.nodes[m].T_local_robot.inverse() * node.T_local_robot));
      if (c.accepted) acceptLoop(c, sm);
      continue;
    }
    if (!every_node || searches_left <= 0) continue;
    --searches_left;
    auto attempt = [&](const registration::CorrelativeOptions& window) { return search(n, s, window, sparse, c); };
    // The least window first: where it holds a match, the nearer place is the likelier one (a wider
    // window in a building of look-alike rooms finds a better-scoring wrong place as often as not).
    // Only where it holds none that refines, the window the drift since the latest closure calls
    // for. Each window's closures are confirmed by the same window's: a place the wider one finds
    // would otherwise contradict a right closure the least one left pending.
    bool scored = attempt(loop_search);
    const bool widened = (!scored || !c.accepted) && window_m > loop_search.linear_window_m;
    if (widened) {
      if (scored) listRejected(std::move(c));
      registration::CorrelativeOptions wide = loop_search;
      wide.linear_window_m = window_m;
      scored = attempt(wide);
    }
    if (!scored) continue;  // no candidate: nothing to record
    if (!c.accepted) {
      listRejected(std::move(c));
      continue;
    }
    submitSearched(std::move(c), sm, widened ? sm.wide_pending : sm.pending);
  }
  return covered;
}

bool LoopClosure::search(std::size_t n, std::size_t s, const registration::CorrelativeOptions& window,
                         std::optional<Points2>& sparse, Constraint& c) {
  const Submap& sm = s_.submaps[s];
  const Points2& pts = s_.node_points[n];
  ++s_.stats.loop_searches;
  c = Constraint{};
  c.kind = Constraint::Kind::kLoop;
  c.from = sm.anchor;
  c.to = n;
  c.searched = true;
  const SE2 guess = s_.nodes[sm.anchor].T_world_robot.inverse() * s_.nodes[n].T_world_robot;
  if (!sparse) sparse = voxelFilter(pts, 2.0 * opt.scan_voxel_m);
  const auto cr = registration::matchCorrelative(gridOf(s), *sparse, guess, window);
  c.score = cr.score;
  if (!cr.T_search.isFinite() || cr.score < opt.loop_min_score) return false;
  refine(c, sm, pts, cr.T_search);
  return true;
}

void LoopClosure::confirmPendingAtEnd() {
  const std::size_t N = s_.nodes.size();
  const auto every = static_cast<std::size_t>(opt.loop_search_every_nodes);
  const auto confirm_window = static_cast<std::size_t>(opt.loop_confirm_window_nodes);
  for (std::size_t s = 0; s < s_.submaps.size(); ++s) {
    Submap& sm = s_.submaps[s];
    for (const bool wide : {false, true}) {
      std::optional<Constraint>& pending = wide ? sm.wide_pending : sm.pending;
      // Only a closure the log's end cut short of its confirmation window: an older one had the
      // nodes after it to be confirmed by.
      if (!pending || pending->to + confirm_window < N - 1) continue;
      const std::size_t p = pending->to;
      // The nodes the schedule skipped around it: those since the search before it, and every node
      // after it (a search after it that disagreed would have refuted it already).
      const std::size_t first = p >= every ? p - every + 1 : 0;
      const std::size_t last = std::min(N - 1, p + confirm_window);
      for (std::size_t m = first; m <= last && pending && pending->to == p; ++m) {
        if (m == p || s_.node_points[m].size() < opt.min_points) continue;
        if (sm.nodes.back() + static_cast<std::size_t>(opt.local_map_nodes) >= m) continue;
        registration::CorrelativeOptions window = loop_search;
        if (wide) window.linear_window_m = std::max(window.linear_window_m, s_.proximityWindowM(m));
        std::optional<Points2> sparse;
        Constraint c;
        if (!search(m, s, window, sparse, c)) continue;
        if (!c.accepted) {
          ++s_.stats.loop_rejected;
          s_.addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
          continue;
        }
        submitSearched(std::move(c), sm, pending);
      }
    }
  }
}

bool LoopClosure::untiedSearchDue(std::size_t age) {
  if (age < 4 * kUntiedEveryNodes) return age % kUntiedEveryNodes == 0;
  // From 2^k to 2^(k+1) nodes, every 2^(k-2)-th node.
  return age % (std::bit_floor(age) / 4) == 0;
}

void LoopClosure::searchUntied(std::size_t n) {
  if (!s_.untied_since || n < *s_.untied_since) return;
  const std::size_t first = *s_.untied_since;
  if (!untiedSearchDue(n - first)) return;
  const Points2& pts = s_.node_points[n];
  if (pts.size() < opt.min_points) return;
  std::vector<std::size_t> before;  // finished submaps of the map before the fragment
  for (std::size_t s = 0; s < s_.submaps.size(); ++s)
    if (s_.submaps[s].finished && s_.submaps[s].nodes.back() < first) before.push_back(s);
  if (before.empty()) return;
  const Points2 sparse = voxelFilter(pts, 2.0 * opt.scan_voxel_m);
  // A submap holding a closure of this fragment awaiting confirmation first, then the others in turn.
  std::vector<std::size_t> tries;
  for (std::size_t s : before)
    if (s_.submaps[s].untied_pending && s_.submaps[s].untied_pending->to >= first) tries.push_back(s);
  for (std::size_t k = 0; k < std::min(kUntiedSubmapsPerSearch, before.size()); ++k) {
    const std::size_t s = before[untied_cursor++ % before.size()];
    if (std::find(tries.begin(), tries.end(), s) == tries.end()) tries.push_back(s);
  }
  struct Candidate {
    double score = 0.0;
    std::size_t submap = 0;
    SE2 T;
  };
  std::vector<Candidate> found;
  for (const std::size_t s : tries) {
    const Submap& sm = s_.submaps[s];
    // Anywhere the robot was while mapping the submap (a margin around its nodes), any heading.
    registration::CorrelativeOptions window = untied_search;
    const Eigen::Vector2d half = 0.5 * (sm.nodes_max_anchor - sm.nodes_min_anchor);
    window.linear_window_m = std::min(half.maxCoeff() + kUntiedMarginM, kUntiedMaxWindowM);
    window.angular_window_rad = std::numbers::pi;
    window.angular_step_rad = kUntiedAngularStepRad;
    // Branch and bound prunes every branch that cannot reach a closure's score: in ground the
    // submap does not hold (most searches of a fragment), little is left to score.
    window.min_score = opt.loop_min_score;
    const Eigen::Vector2d mid = 0.5 * (sm.nodes_max_anchor + sm.nodes_min_anchor);
    const auto cr = registration::matchCorrelative(coarseGridOf(s), sparse, SE2(mid.x(), mid.y(), 0.0), window);
    ++s_.stats.loop_searches;
    if (cr.T_search.isFinite() && cr.score >= opt.loop_min_score) found.push_back({cr.score, s, cr.T_search});
  }
  // Best first, and the next when a better one fails its tests: a look-alike in one submap may
  // outscore the right place in another (the mit-csail bag's resumed session: a corridor that sees
  // through the walls of submap 11 at 0.91, the right place in submap 13 at 0.88, never refined).
  std::stable_sort(found.begin(), found.end(),
                   [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  for (const Candidate& f : found) {
    Submap& sm = s_.submaps[f.submap];
    Constraint c;
    c.kind = Constraint::Kind::kLoop;
    c.from = sm.anchor;
    c.to = n;
    c.searched = true;
    c.score = f.score;
    refine(c, sm, pts, f.T);
    // As for a descriptor closure: across a lost track the estimate says nothing, so a look-alike
    // place is told from the right one only by the scan, which must not see through the submap's walls.
    if (c.accepted) {
      if (const double through = DescriptorLoops::seeThroughFraction(*sm.icp, pts, c.T_from_to);
          through > opt.descriptor_max_see_through) {
        c.accepted = false;
        c.reason = fmt::format("sees through the submap's walls ({:.0f}% of the beams)", 100.0 * through);
      }
    }
    if (c.accepted) {
      submitSearched(std::move(c), sm, sm.untied_pending);
      return;
    }
    ++s_.stats.loop_rejected;
    s_.addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
  }
}

void LoopClosure::refine(Constraint& c, const Submap& sm, const Points2& pts, const SE2& init) const {
  const registration::Result res = alignIcp(*sm.icp, pts, init, loop_icp);
  c.T_from_to = res.T_target_source;
  c.explained = res.T_target_source.isFinite()
                    ? explainedFraction(*sm.icp, pts, res.T_target_source, opt.match_inlier_distance_m)
                    : 0.0;
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
}

void LoopClosure::submitSearched(Constraint c, Submap& sm) { submitSearched(std::move(c), sm, sm.pending); }

void LoopClosure::submitSearched(Constraint c, Submap& sm, std::optional<Constraint>& pending) {
  std::optional<Constraint> confirmed;
  if (pending) {
    const Constraint& p = *pending;
    const SE2 predicted = p.T_from_to * (s_.nodes[p.to].T_local_robot.inverse() * s_.nodes[c.to].T_local_robot);
    const SE2 diff = predicted.inverse() * c.T_from_to;
    const std::size_t apart = c.to > p.to ? c.to - p.to : p.to - c.to;  // confirmPendingAtEnd: either order
    const bool recent = apart <= static_cast<std::size_t>(opt.loop_confirm_window_nodes);
    if (recent && diff.translation().norm() <= opt.loop_confirm_tolerance_m &&
        std::abs(diff.theta()) <= opt.loop_confirm_tolerance_rad) {
      confirmed = p;
    } else {
      Constraint old = p;
      old.accepted = false;
      old.reason = recent ? "contradicted by a later search" : "not confirmed by a later search";
      ++s_.stats.loop_rejected;
      s_.addEdge(std::move(old), Eigen::Matrix3d::Zero(), 0.0);
    }
    pending.reset();
  }
  if (!confirmed) {
    pending = std::move(c);
    return;
  }
  acceptLoop(*confirmed, sm);
  s_.searched_loop_pending = true;
  acceptLoop(std::move(c), sm);
}

void LoopClosure::acceptLoop(Constraint c, Submap& sm) {
  // A relocalization showing the robot carried (it contradicts the odometry across the lost track)
  // needs the scan's evidence against where the odometry put it: enough of its points there in the
  // free space of the map before the fragment. Ground the map does not hold is no evidence: a narrow
  // laser lost facing a wall at the right place sees what the submaps there lack, and its closure to
  // a look-alike room would otherwise drop the right odometry as a kidnapping.
  const bool ties_untied = s_.untied_since && c.from < *s_.untied_since && c.to >= *s_.untied_since;
  const double sigmas = ties_untied && s_.untiedHasOdometryLink() ? carriedSigmas(c) : 0.0;
  if (sigmas > opt.prior_gate_sigmas) {
    std::optional<std::string> no_evidence;  // why the scans do not show the robot carried
    const double in_free = inFreeSpaceWhereEstimated(c.to, *s_.untied_since);
    if (in_free < kCarriedInFree) {
      no_evidence = fmt::format("where the odometry puts the scan only {:.0f}% of it lies in the map's free space",
                                100.0 * in_free);
    } else {
      // In a corridor of look-alike doors the relocalization may be the look-alike, a few sigmas
      // beyond the odometry's gate, while the right place lies within it: where a match within the
      // gate explains the scan as well, the scans cannot tell the two apart and the odometry stands.
      const double near_explained = explainedNearEstimate(c.to, *s_.untied_since);
      if (near_explained >= c.explained - kCarriedExplainsMore)
        no_evidence = fmt::format("a match within the odometry's gate explains {:.0f}% of the scan against its {:.0f}%",
                                  100.0 * near_explained, 100.0 * c.explained);
    }
    if (no_evidence) {
      ++s_.stats.loop_rejected;
      c.accepted = false;
      c.reason = fmt::format(
          "contradicts the odometry across the lost track, but {}: no evidence the robot was carried", *no_evidence);
      if (carry_refused_for != s_.untied_since) {  // one event per fragment
        carry_refused_for = s_.untied_since;
        s_.back_end_events.push_back(
            {s_.node_frame_index[c.to], s_.nodes[c.to].time,
             fmt::format("a closure would tie the fragment from node {} to submap {} {:.1f} sigmas from the odometry "
                         "across the lost track, but {}: no evidence the robot was carried, the odometry is kept",
                         *s_.untied_since, s_.nodes[c.from].submap, sigmas, *no_evidence)});
      }
      s_.addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
      return;
    }
  }
  // Along a direction the submap cannot pin the scan (a corridor's axis) the closure holds wherever
  // the estimate put it: it constrains only the other directions, and it does not show the
  // estimate to be right (the descriptor search keeps looking for the drift along the corridor).
  const std::optional<Eigen::Vector2d> weak =
      weakDirection(*sm.icp, s_.node_points[c.to], c.T_from_to, opt.match_inlier_distance_m, opt.degeneracy_threshold);
  // A searched closure that neither the estimate nor the latest closure expects is a look-alike
  // place: in a building of identical rooms a wrong closure and the link-following ones after it
  // agree with each other, and their cluster outweighs the right closures under the robust loss.
  // Descriptor closures and relocalizations correct drift no estimate foresees: not checked.
  if (c.searched && !c.descriptor && !ties_untied) {
    const std::optional<Eigen::Vector2d> weak_world =
        weak ? std::optional<Eigen::Vector2d>(s_.nodes[c.from].T_world_robot.rotation() * *weak) : std::nullopt;
    if (auto why = contradictsLatestClosure(c, weak_world)) {
      ++s_.stats.loop_rejected;
      c.accepted = false;
      c.reason = std::move(*why);
      s_.addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
      return;
    }
  }
  ++s_.stats.loop_accepted;
  Eigen::Matrix3d sqrt_info =
      weak ? directionalSqrtInfo(*weak, std::numeric_limits<double>::infinity(), opt.loop_sigma_m, opt.loop_sigma_rad)
           : diagSqrtInfo(opt.loop_sigma_m, opt.loop_sigma_rad);
  if (!weak && (!s_.last_loop_node || c.to > *s_.last_loop_node)) s_.last_loop_node = c.to;
  const bool descriptor = c.descriptor;
  if (descriptor) {
    ++s_.stats.descriptor_accepted;
    s_.descriptor_loop_accepted = true;
    const double correction =
        ((s_.nodes[c.from].T_world_robot * c.T_from_to).translation() - s_.nodes[c.to].T_world_robot.translation())
            .norm();
    s_.back_end_events.push_back(
        {s_.node_frame_index[c.to], s_.nodes[c.to].time,
         fmt::format("loop closure found by descriptors: node {} to submap {}, correcting {:.2f} m of drift", c.to,
                     s_.nodes[c.from].submap, correction)});
  }
  if (ties_untied) {
    ++s_.stats.relocalizations;
    dropCarriedOdometry(sigmas);
    s_.back_end_events.push_back({s_.node_frame_index[c.to], s_.nodes[c.to].time,
                         fmt::format("relocalized: the fragment from node {} (after lost tracking) is tied to submap {} "
                                     "by node {}",
                                     *s_.untied_since, s_.nodes[c.from].submap, c.to)});
    s_.untied_since.reset();
  }
  if (!sm.last_link_node || c.to > *sm.last_link_node) {
    sm.last_link_node = c.to;
    sm.last_link_T_anchor_node = c.T_from_to;
  }
  ++s_.loops_since_optimization;
  // From the submap's node nearest the matched pose, not from its anchor: the match places the
  // scan against the submap's points near that node, and on a log with scans metres apart the
  // submap's far end lies tens of metres from its anchor, where the submap's own drift (a degree
  // over 20 m is 0.35 m) would enter the closure.
  const SE2 T_anchor_local = s_.nodes[sm.anchor].T_local_robot.inverse();
  std::size_t nearest = sm.anchor;
  double nearest_m = std::numeric_limits<double>::infinity();
  for (const std::size_t k : sm.nodes) {
    const double d = ((T_anchor_local * s_.nodes[k].T_local_robot).translation() - c.T_from_to.translation()).norm();
    if (d < nearest_m) nearest_m = d, nearest = k;
  }
  if (nearest != sm.anchor) {
    const SE2 T_anchor_nearest = T_anchor_local * s_.nodes[nearest].T_local_robot;
    // The edge's translation error is expressed in its from-node's frame: the information's
    // translational columns turn with it.
    sqrt_info.leftCols<2>() = (sqrt_info.leftCols<2>() * T_anchor_nearest.rotation()).eval();
    c.from = nearest;
    c.T_from_to = T_anchor_nearest.inverse() * c.T_from_to;
  }
  // A descriptor closure corrects metres of drift: under the robust loss it could not pull the
  // chain of stiff front-end edges that far. It has passed the stricter tests (and a second
  // closure confirms it), so it is a plain quadratic constraint.
  s_.addEdge(std::move(c), sqrt_info, descriptor ? 0.0 : opt.loop_huber);
}

namespace {

/// Whether a closure's edge constrains both directions of the translation (a closure along a
/// corridor's axis has no information along it).
bool pinsBoth(const PoseGraphEdge& e) {
  const Eigen::Matrix3d& S = e.sqrt_information;
  return std::abs(S(0, 0) * S(1, 1) - S(0, 1) * S(1, 0)) > 1e-12;
}

}  // namespace

std::optional<std::string> LoopClosure::contradictsLatestClosure(
    const Constraint& c, const std::optional<Eigen::Vector2d>& weak_world) const {
  // The drift allowance is the odometry's: without odometry nothing measures the motion between
  // scans (on the intel bag without it, right closures disagreed with the latest one by 2-4 m).
  if (!s_.node_odometry[c.to]) return std::nullopt;
  // The latest closure accepted (a relocalization may tie an earlier node than the fragment's own
  // closures since) that pins its node in both directions and that the latest optimisation kept.
  // Accepted constraints and edges are in the same order.
  const Constraint* ref = nullptr;
  std::size_t edge = s_.edges.size();
  for (auto it = s_.constraints.rbegin(); it != s_.constraints.rend() && !ref; ++it) {
    if (!it->accepted) continue;
    const PoseGraphEdge& e = s_.edges[--edge];
    if (it->kind == Constraint::Kind::kLoop && it->to < c.to && pinsBoth(e) && !s_.edgeFaded(edge)) ref = &*it;
  }
  if (!ref) return std::nullopt;
  const std::size_t m = ref->to;
  // Across a lost track the front end's chain says nothing of where the robot went.
  for (const std::size_t r : s_.restarts)
    if (r > m && r <= c.to) return std::nullopt;
  const Eigen::Vector2d by_closure = (s_.nodes[c.from].T_world_robot * c.T_from_to).translation();
  const Eigen::Vector2d by_latest = (s_.nodes[ref->from].T_world_robot * ref->T_from_to *
                                     (s_.nodes[m].T_local_robot.inverse() * s_.nodes[c.to].T_local_robot))
                                        .translation();
  const Eigen::Vector2d by_estimate = s_.nodes[c.to].T_world_robot.translation();
  auto apart = [&](const Eigen::Vector2d& p) {
    Eigen::Vector2d d = by_closure - p;
    if (weak_world) d -= d.dot(*weak_world) * *weak_world;
    return d.norm();
  };
  const double from_latest = apart(by_latest), from_estimate = apart(by_estimate);
  // The drift either may hold: the path since the latest closure, or, where longer, the path the
  // graph's links span between the closure's two nodes (a part of the map no closure has tied to the
  // rest since it was mapped drifted over all of it: orebro's keyframes came back to their start 2 m
  // from where the graph held it, 87 m of path through the graph from it, and every closure there
  // was refused).
  const double open_m = s_.node_path_m[c.to] - s_.node_path_m[m];
  double drift_m = open_m;
  const auto consistent = [&] {
    const double tolerance_m = kConsistentM + opt.loop_window_per_m * drift_m;
    return from_latest <= tolerance_m || from_estimate <= tolerance_m;
  };
  if (consistent()) return std::nullopt;
  drift_m = std::max(drift_m, untiedPathM(c.from, c.to));
  if (consistent()) return std::nullopt;
  return fmt::format(
      "contradicts the estimate by {:.2f} m and the closure at node {} by {:.2f} m, {:.1f} m of path before and "
      "{:.1f} m of path between its nodes (more than {:.2f} m): a look-alike place",
      from_estimate, m, from_latest, open_m, drift_m, kConsistentM + opt.loop_window_per_m * drift_m);
}

double LoopClosure::untiedPathM(std::size_t a, std::size_t b) const {
  // Dijkstra over the accepted links: a step between consecutive nodes weighs the front end's path
  // between them, a closure nothing.
  const std::size_t N = s_.nodes.size();
  std::vector<std::vector<std::pair<std::size_t, double>>> adj(N);
  for (const Constraint& k : s_.constraints) {
    if (!k.accepted || k.from >= N || k.to >= N) continue;
    const double w = k.kind == Constraint::Kind::kLoop ? 0.0 : std::abs(s_.node_path_m[k.to] - s_.node_path_m[k.from]);
    adj[k.from].emplace_back(k.to, w);
    adj[k.to].emplace_back(k.from, w);
  }
  std::vector<double> dist(N, std::numeric_limits<double>::infinity());
  using Item = std::pair<double, std::size_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> q;
  dist[b] = 0.0;
  q.emplace(0.0, b);
  while (!q.empty()) {
    const auto [d, n] = q.top();
    q.pop();
    if (n == a) return d;
    if (d > dist[n]) continue;
    for (const auto& [m, w] : adj[n])
      if (d + w < dist[m]) {
        dist[m] = d + w;
        q.emplace(dist[m], m);
      }
  }
  return std::abs(s_.node_path_m[b] - s_.node_path_m[a]);
}

double LoopClosure::carriedSigmas(const Constraint& c) const {
  const std::size_t r = s_.restart_odometry->node;
  // The step across the lost track the closure implies (node r - 1 as estimated, node c.to where
  // the closure puts it, node r by the front end's poses after the lost track), in the odometry
  // step's own sigmas.
  const SE2 T_world_to_by_closure = s_.nodes[c.from].T_world_robot * c.T_from_to;
  const SE2 T_r_to = s_.nodes[r].T_local_robot.inverse() * s_.nodes[c.to].T_local_robot;
  const SE2 step = s_.nodes[r - 1].T_world_robot.inverse() * T_world_to_by_closure * T_r_to.inverse();
  return carriedOdometry().distance(step);
}

MotionPrediction LoopClosure::carriedOdometry() const {
  const SlamState::RestartOdometry& ro = *s_.restart_odometry;
  const Constraint& odo = s_.constraints[ro.constraint];
  return odometryPrediction(opt, odo.T_from_to, s_.nodes[ro.node].time - s_.nodes[ro.node - 1].time);
}

double LoopClosure::nearestNodeM(const Submap& sm, const Eigen::Vector2d& at) const {
  double d = std::numeric_limits<double>::infinity();
  for (const std::size_t k : sm.nodes) d = std::min(d, (s_.nodes[k].T_world_robot.translation() - at).norm());
  return d;
}

double LoopClosure::inFreeSpaceWhereEstimated(std::size_t n, std::size_t first) const {
  const Points2& pts = s_.node_points[n];
  if (pts.empty()) return 0.0;
  const SE2& T_world_node = s_.nodes[n].T_world_robot;
  // The submaps' grids are built here, not kept: this runs only for closures that would show a
  // robot carried, a few per lost track.
  std::vector<char> in_free(pts.size(), 0);
  const double reach = opt.max_range_m;  // a submap's free space lies within this of its nodes
  for (const Submap& sm : s_.submaps) {
    if (!sm.finished || sm.nodes.back() >= first) continue;
    const SE2 T_anchor_node = s_.nodes[sm.anchor].T_world_robot.inverse() * T_world_node;
    const Eigen::Vector2d t = T_anchor_node.translation();
    if ((t.array() < sm.nodes_min_anchor.array() - reach).any() ||
        (t.array() > sm.nodes_max_anchor.array() + reach).any())
      continue;
    const OccupancyImage image = submapImage(sm, opt.map_voxel_m);
    if (image.width() == 0) continue;
    const SE2 T_map_node = image.origin().inverse() * T_anchor_node;
    const double res = image.resolution();
    // Free: the point's cell and every cell within the match's inlier distance seen free (a point
    // on a wall, a little off, is not counted against the pose); free as the submaps' descriptor
    // databases read the same images.
    const int margin = static_cast<int>(std::ceil(opt.match_inlier_distance_m / res));
    const int free_max = s_.match.descriptor_db.free_max;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      if (in_free[i]) continue;
      const Eigen::Vector2d q = T_map_node * pts[i] / res;
      const int cx = static_cast<int>(std::floor(q.x())), cy = static_cast<int>(std::floor(q.y()));
      bool free = true;
      for (int dy = -margin; dy <= margin && free; ++dy)
        for (int dx = -margin; dx <= margin && free; ++dx) {
          const int x = cx + dx, y = cy + dy;
          free = image.contains(x, y) && image.at(x, y) >= 0 && image.at(x, y) <= free_max;
        }
      in_free[i] = free;
    }
  }
  return static_cast<double>(std::count(in_free.begin(), in_free.end(), 1)) / static_cast<double>(pts.size());
}

double LoopClosure::explainedNearEstimate(std::size_t n, std::size_t first) {
  const MotionPrediction p = carriedOdometry();
  registration::CorrelativeOptions gate = loop_search;
  gate.linear_window_m = std::min(opt.prior_gate_sigmas * p.sigma_m, opt.loop_max_linear_window_m);
  gate.angular_window_rad =
      std::max(loop_search.angular_window_rad, std::min(opt.prior_gate_sigmas * p.sigma_rad, std::numbers::pi));
  const double radius_m = std::max(opt.loop_search_radius_m, gate.linear_window_m);
  const Eigen::Vector2d at = s_.nodes[n].T_world_robot.translation();
  double best = 0.0;
  std::optional<Points2> sparse;
  for (std::size_t k = 0; k < s_.submaps.size(); ++k) {
    const Submap& sm = s_.submaps[k];
    if (!sm.finished || sm.nodes.back() >= first || nearestNodeM(sm, at) > radius_m) continue;
    Constraint c;
    if (search(n, k, gate, sparse, c) && c.accepted) best = std::max(best, c.explained);
  }
  return best;
}

void LoopClosure::dropCarriedOdometry(double sigmas) {
  if (!s_.untiedHasOdometryLink()) return;
  const SlamState::RestartOdometry ro = *s_.restart_odometry;
  s_.restart_odometry.reset();
  const std::size_t r = ro.node;
  Constraint& odo = s_.constraints[ro.constraint];
  if (!(sigmas > opt.prior_gate_sigmas)) return;
  s_.edges.erase(s_.edges.begin() + static_cast<std::ptrdiff_t>(ro.edge));
  odo.accepted = false;
  odo.reason = fmt::format("contradicted by the relocalization by {:.1f} sigmas (the robot was carried)", sigmas);
  s_.back_end_events.push_back(
      {s_.node_frame_index[r], s_.nodes[r].time,
       fmt::format("the odometry across the lost track at node {} contradicts the relocalization by {:.1f} sigmas: "
                   "the robot was carried, the odometry link is dropped",
                   r, sigmas)});
}

void LoopClosure::expirePending() {
  for (Submap& sm : s_.submaps)
    for (std::optional<Constraint>* pending : {&sm.pending, &sm.wide_pending, &sm.untied_pending})
      if (*pending) {
        Constraint old = **pending;
        old.accepted = false;
        old.reason = "not confirmed by a later search";
        ++s_.stats.loop_rejected;
        s_.addEdge(std::move(old), Eigen::Matrix3d::Zero(), 0.0);
        pending->reset();
      }
}

// A grid with its max-grids takes megabytes, and a long run would otherwise hold one per submap:
// only the `max_kept` most recently used of each kind are kept (`lru`: least recently used first).
const registration::CorrelativeGrid& LoopClosure::cachedGrid(
    std::size_t s, std::unique_ptr<registration::CorrelativeGrid> Submap::*grid, std::vector<std::size_t>& lru,
    std::size_t max_kept, const registration::CorrelativeOptions& options) {
  Submap& sm = s_.submaps[s];
  lru.erase(std::remove(lru.begin(), lru.end(), s), lru.end());
  lru.push_back(s);
  if (!(sm.*grid)) sm.*grid = std::make_unique<registration::CorrelativeGrid>(submapGrid(sm, options));
  while (lru.size() > max_kept) {
    (s_.submaps[lru.front()].*grid).reset();
    lru.erase(lru.begin());
  }
  return *(sm.*grid);
}

const registration::CorrelativeGrid& LoopClosure::gridOf(std::size_t s) {
  return cachedGrid(s, &Submap::grid, grid_lru, kMaxGrids, loop_search);
}

const registration::CorrelativeGrid& LoopClosure::coarseGridOf(std::size_t s) {
  return cachedGrid(s, &Submap::coarse_grid, coarse_lru, kMaxCoarseGrids, untied_search);
}

/// The score grid of a finished submap for the branch-and-bound searches, from its occupancy grid
/// built with the mapping module: every node's scan inserted (log-odds, ray traced) at its pose in
/// the anchor's frame. A finished submap is frozen (the front end's relative poses of its nodes
/// no longer change), so the grid can be dropped and rebuilt alike.
OccupancyImage LoopClosure::submapImage(const Submap& sm, double resolution_m) const {
  mapping::MapOptions mo;
  mo.resolution_m = resolution_m;
  mo.insert.max_range_m = opt.max_range_m;
  const auto map = mapping::makeMap(mapping::MapModel::kLogOdds, mo);
  const SE2 T_anchor_local = s_.nodes[sm.anchor].T_local_robot.inverse();
  for (const std::size_t n : sm.nodes)
    map->insert(s_.node_scans[n].first, T_anchor_local * s_.nodes[n].T_local_robot * s_.node_scans[n].second);
  return mapping::toOccupancyImage(*map);
}

registration::CorrelativeGrid LoopClosure::submapGrid(const Submap& sm,
                                                      const registration::CorrelativeOptions& grid_options) const {
  const OccupancyImage image = submapImage(sm, grid_options.resolution_m);
  if (image.width() == 0) return registration::CorrelativeGrid::fromPoints(sm.points_anchor, grid_options);
  return registration::CorrelativeGrid::fromMap(image, grid_options);
}

}  // namespace lidar2d::slam::internal
