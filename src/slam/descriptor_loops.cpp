#include "src/slam/internal/descriptor_loops.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <utility>

#include "src/slam/internal/points.hpp"

namespace lidar2d::slam::internal {


void DescriptorLoops::describeNode(const Points2& raw) {
  s_.node_lines.emplace_back();
  if (opt.descriptor_loops) {
    const auto t0 = Clock::now();
    // From every point in scan order (the voxel filter would blur the corners the split needs).
    s_.node_lines.back() = localization::extractLines(raw, descriptor_query.lines);
    if (s_.node_lines.back().size() > opt.descriptor_max_lines) s_.node_lines.back().resize(opt.descriptor_max_lines);
    s_.stats.descriptor_seconds += secondsSince(t0);
  }
}

void DescriptorLoops::indexSubmap(Submap& sm) {
  const SE2 T_anchor_local = s_.nodes[sm.anchor].T_local_robot.inverse();
  // Every node is a database position (anchor frame) with its lines turned into the anchor's
  // orientation: the localizer's lookup then answers poses in the anchor frame.
  const auto t0 = Clock::now();
  std::vector<localization::Database::Position> positions;
  std::vector<localization::Database::LineFeature> features;
  for (std::size_t n : sm.nodes) {
    if (s_.node_lines[n].size() < 2) continue;
    const SE2 T = T_anchor_local * s_.nodes[n].T_local_robot;
    localization::Database::Position pos;
    pos.x = static_cast<float>(T.x());
    pos.y = static_cast<float>(T.y());
    pos.first_line = static_cast<std::uint32_t>(features.size());
    pos.num_lines = static_cast<std::uint32_t>(s_.node_lines[n].size());
    for (const auto& l : s_.node_lines[n])
      features.push_back({static_cast<float>(wrapAngle(l.normal_angle + T.theta())), static_cast<float>(l.distance),
                          static_cast<float>(l.length)});
    positions.push_back(pos);
  }
  sm.db = std::make_unique<localization::Database>(
      localization::Database::fromParts(descriptor_db, 0, std::move(positions), std::move(features)));
  s_.stats.descriptor_seconds += secondsSince(t0);
}

/// Descriptor loop candidates (large drift): the current node's lines are looked up in the
/// descriptor index of every old submap; the best-voted (submap, pose) hypotheses are verified
/// like searched closures (branch and bound in a small window, ICP, score, explained fraction).
/// Only a hypothesis in a submap the proximity search does not consider can become a descriptor
/// closure, and only when it is plausible for the drift (the correction it makes), the submaps
/// around the current estimate do not explain the scan already, and no distinct hypothesis
/// passes as well (an aliased place). Hypotheses in the submaps the proximity search considers
/// take part as competitors only: when one of them wins, the estimate has not drifted.
void DescriptorLoops::search(std::size_t n, const std::vector<char>& covered) {
  if (!opt.descriptor_loops || s_.node_lines[n].size() < 2) return;
  const auto t0 = Clock::now();
  const Node& node = s_.nodes[n];
  const double window_m = s_.proximityWindowM(n);  // the proximity search's (LoopClosure::searchNear)
  // Look up one node in descriptor_every_nodes while the proximity search finds nothing, and
  // every node on from a pending descriptor closure until a second one confirms it (from a node
  // some way on: the same view from nearly the same pose confirms nothing).
  bool confirming = false;
  for (std::size_t s = 0; s < s_.submaps.size(); ++s) {
    const auto& p = s_.submaps[s].pending;
    confirming = confirming || (!covered[s] && p && p->descriptor &&
                                n - p->to >= static_cast<std::size_t>(opt.loop_search_every_nodes) &&
                                n - p->to <= static_cast<std::size_t>(opt.loop_confirm_window_nodes));
  }
  const bool quiet =
      !s_.last_loop_node || n - *s_.last_loop_node > static_cast<std::size_t>(opt.descriptor_quiet_nodes);
  // A fragment after a lost track, not yet tied to the map before it: every one of its nodes is
  // looked up in the submaps before it (no age limit: they lie in another frame) until a closure
  // ties it; a robot carried into new ground may come back to the map only much later.
  const std::optional<std::size_t> untied = s_.untied_since;
  const bool relocalizing = untied && n >= *untied;
  // Submaps before the fragment being relocalized lie in another frame: no age or drift limits.
  const auto before_fragment = [&](const Submap& sm) { return relocalizing && sm.nodes.back() < *untied; };
  const bool due = n % static_cast<std::size_t>(opt.descriptor_every_nodes) == 0;
  if (!confirming && !relocalizing && !(quiet && due)) return;
  std::vector<std::size_t> targets;
  for (std::size_t s = 0; s < s_.submaps.size(); ++s) {
    const Submap& sm = s_.submaps[s];
    if (!sm.db || sm.db->empty()) continue;
    if (!before_fragment(sm) && sm.nodes.back() + static_cast<std::size_t>(opt.descriptor_min_age_nodes) > n) continue;
    targets.push_back(s);
  }
  if (targets.empty()) return;
  ++s_.stats.descriptor_queries;

  struct Hypothesis {
    double votes = 0.0;
    std::size_t submap = 0;
    SE2 T_anchor_node;
  };
  std::vector<Hypothesis> hyps;
  for (std::size_t s : targets)
    for (const auto& v : localization::voteLinePairs(*s_.submaps[s].db, s_.node_lines[n], descriptor_query, 4))
      if (v.votes >= opt.descriptor_min_votes) hyps.push_back({v.votes, s, v.T_world_robot});
  std::stable_sort(hyps.begin(), hyps.end(),
                   [](const Hypothesis& a, const Hypothesis& b) { return a.votes > b.votes; });

  const Points2& pts = s_.node_points[n];
  const Points2 coarse = voxelFilter(pts, 2.0 * opt.scan_voxel_m);
  // How well the submaps around the current estimate explain the scan where it is now: when they
  // do, the estimate has not drifted and a hypothesis elsewhere is an aliased place. Only submaps
  // as old as the ones queried: the recent ones were built since the drift, in its frame, and
  // explain the scan however far the estimate has drifted.
  double current_explained = 0.0;
  for (std::size_t s = 0; s < s_.submaps.size(); ++s)
    if (covered[s] && s_.submaps[s].icp &&
        s_.submaps[s].nodes.back() + static_cast<std::size_t>(opt.descriptor_min_age_nodes) <= n)
      current_explained =
          std::max(current_explained,
                   explainedFraction(*s_.submaps[s].icp, pts,
                                     s_.nodes[s_.submaps[s].anchor].T_world_robot.inverse() * node.T_world_robot,
                                     opt.match_inlier_distance_m));
  std::vector<Constraint> passed;  // verified and plausible, in vote order
  std::vector<char> passed_covered;
  std::vector<SE2> tried;  // world poses of the hypotheses verified (neighbouring bins of one pose are skipped)
  for (const Hypothesis& h : hyps) {
    if (static_cast<int>(tried.size()) >= opt.descriptor_max_candidates) break;
    Submap& sm = s_.submaps[h.submap];
    const SE2& T_world_anchor = s_.nodes[sm.anchor].T_world_robot;
    const SE2 guess_world = T_world_anchor * h.T_anchor_node;
    bool dup = false;
    for (const SE2& t : tried)
      dup = dup || ((t.translation() - guess_world.translation()).norm() < 2.0 * descriptor_query.vote_bin_m &&
                    std::abs(angleDiff(t.theta(), guess_world.theta())) < 2.0 * descriptor_query.vote_bin_rad);
    if (dup) continue;
    tried.push_back(guess_world);
    ++s_.stats.descriptor_hypotheses;
    // Near the estimate: within the proximity search's window of it, a place that search could
    // have found itself (a competitor only). Not "in a submap it considers": a submap's 30 nodes
    // may span tens of metres, and its far end lies beyond that window.
    const auto nearEstimate = [&](const SE2& T_world) {
      return covered[h.submap] && (T_world.translation() - node.T_world_robot.translation()).norm() <= window_m &&
             std::abs(angleDiff(T_world.theta(), node.T_world_robot.theta())) <= opt.loop_angular_window_rad;
    };
    bool near = nearEstimate(guess_world);
    const auto cr =
        registration::matchCorrelative(closure_.gridOf(h.submap), coarse, h.T_anchor_node, descriptor_search);
    if (!cr.T_search.isFinite() || cr.score < opt.loop_min_score) continue;  // no candidate: nothing to record
    Constraint c;
    c.kind = Constraint::Kind::kLoop;
    c.from = sm.anchor;
    c.to = n;
    c.searched = true;
    c.descriptor = true;
    c.score = cr.score;
    closure_.refine(c, sm, pts, cr.T_search);
    if (c.accepted) {
      // The correction the closure makes to the current estimate must fit the drift the front end
      // can have accumulated since it last saw that submap.
      const SE2 implied = T_world_anchor * c.T_from_to;
      near = nearEstimate(implied);
      const double correction = (implied.translation() - node.T_world_robot.translation()).norm();
      const double turn = std::abs(angleDiff(implied.theta(), node.T_world_robot.theta()));
      const double path = s_.node_path_m[n] - s_.node_path_m[sm.nodes.back()];
      const double allowed = opt.descriptor_max_correction_m + opt.descriptor_drift_fraction * path;
      // Across a lost track the estimate is only the prediction: any correction is plausible.
      if (!before_fragment(sm) && (correction > allowed || turn > opt.descriptor_max_rotation_rad)) {
        c.accepted = false;
        c.reason = fmt::format("implausible correction of {:.1f} m / {:.0f} deg after {:.0f} m of path", correction,
                               turn / kDeg, path);
      } else if (const double through = seeThroughFraction(*sm.icp, pts, c.T_from_to);
                 through > opt.descriptor_max_see_through) {
        c.accepted = false;
        c.reason = fmt::format("sees through the submap's walls ({:.0f}% of the beams)", 100.0 * through);
      } else if (!near && current_explained >= opt.loop_min_explained_fraction) {
        c.accepted = false;
        c.reason =
            fmt::format("the current estimate explains {:.0f}% of the points already", 100.0 * current_explained);
      }
    }
    if (c.accepted) {
      passed.push_back(std::move(c));
      passed_covered.push_back(near);
    } else if (!near) {
      ++s_.stats.loop_rejected;
      s_.addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
    }
  }
  // Two distinct places that both pass: the scan cannot tell them apart (a symmetric building).
  bool ambiguous = false;
  for (std::size_t i = 1; i < passed.size(); ++i) {
    const SE2 a = s_.nodes[passed[0].from].T_world_robot * passed[0].T_from_to;
    const SE2 b = s_.nodes[passed[i].from].T_world_robot * passed[i].T_from_to;
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
      ++s_.stats.loop_rejected;
      s_.addEdge(std::move(c), Eigen::Matrix3d::Zero(), 0.0);
    } else if (!near_estimate && i == 0) {
      Submap& sm = s_.submaps[s_.nodes[c.from].submap];
      closure_.submitSearched(std::move(c), sm);
    }
  }
  s_.stats.descriptor_seconds += secondsSince(t0);
}

/// The share of (up to 150 evenly chosen) beams of `pts` (robot frame, seen from the robot's
/// origin) that cross a line of `target` (a point with a normal, within 0.1 m of the crossing,
/// the beam at least 20 degrees off the line) more than 0.3 m before their endpoint, with the
/// robot at `T`: walls of the target the scan should have seen but looked through.
double DescriptorLoops::seeThroughFraction(const registration::IcpTarget& target, const Points2& pts, const SE2& T) {
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

}  // namespace lidar2d::slam::internal
