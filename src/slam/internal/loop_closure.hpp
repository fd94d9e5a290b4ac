#pragma once
// SLAM's loop closure by proximity: finished submaps near a node's global estimate are matched by
// ICP from a recent link or by branch-and-bound search + ICP, and a searched closure is accepted only
// once a later search confirms it. Also the submaps' score grids (built on demand, a few kept).

#include <algorithm>
#include <cstddef>
#include <memory>
#include <numbers>
#include <optional>
#include <vector>

#include "src/slam/internal/motion_prior.hpp"
#include "src/slam/internal/state.hpp"

namespace lidar2d::slam::internal {

class LoopClosure {
 public:
  /// Reads and extends `s` (submaps, constraints, counters, the back end's flags).
  explicit LoopClosure(SlamState& s)
      : s_(s),
        opt(s.opt),
        loop_icp(s.match.loop_icp),
        loop_search(s.match.loop_search),
        untied_search(untiedSearch(s.match.loop_search)) {}
  LoopClosure(const LoopClosure&) = delete;
  LoopClosure& operator=(const LoopClosure&) = delete;

  /// Freezes `sm`: its nodes' points in the anchor's frame, voxel-filtered, its centre and ICP target.
  void finishSubmap(Submap& sm);
  /// Closures from node `n` to the finished submaps within loop_search_radius_m of it (submaps
  /// still in the local map excluded), nearest first. Returns which submaps it considered (by
  /// index), or nothing when the node has too few points to match.
  std::optional<std::vector<char>> searchNear(std::size_t n);
  /// A searched closure `c` into `sm`: pending until a second one from a later node agrees with it
  /// through the front end's relative poses (a wrong match in a self-similar place rarely repeats
  /// consistently), then both are accepted; a pending one that disagrees is rejected.
  void submitSearched(Constraint c, Submap& sm);
  /// ... awaiting confirmation in `pending` (one of `sm`'s: searchUntied keeps its own, so that its
  /// candidates and the other searches' do not contradict each other away).
  void submitSearched(Constraint c, Submap& sm, std::optional<Constraint>& pending);
  /// Relocalization of a fragment not yet tied to the map before it (after a lost track or a
  /// kidnapping, where its estimate says nothing about where it is): the nodes untiedSearchDue picks
  /// are searched by branch and bound in whole finished submaps from before the
  /// fragment, over every heading and the box the robot mapped each from, a few submaps per node in
  /// turn; the best match is refined and tested as a searched closure (submitSearched: confirmed by
  /// a later one before it is accepted); when the best fails those tests, the next best does them,
  /// and so on.
  void searchUntied(std::size_t n);
  /// Whether searchUntied searches at the fragment's node number `age` (0 = its first node): every
  /// kUntiedEveryNodes nodes while it is young, then four times per doubling of its length, so that
  /// a fragment that never comes back to the map costs a number of searches logarithmic in its length.
  static bool untiedSearchDue(std::size_t age);
  /// At the end of the run, the last chance to confirm a closure still pending within
  /// loop_confirm_window_nodes of the last node: its submap is
  /// searched from the nodes the schedule (loop_search_every_nodes) skipped since the search before
  /// the pending one's node, and from every node after it within loop_confirm_window_nodes, as
  /// submitSearched would have from a later search (either order: the two closures agree through the
  /// front end's relative pose). A log that ends where it began finds its closure in its last nodes,
  /// where no later search is left to confirm it.
  void confirmPendingAtEnd();
  /// Pending closures never confirmed are listed as rejected (at the end of the run).
  void expirePending();
  /// The correlative grid of submap `s`, built on demand; only the most recently used few are kept.
  const registration::CorrelativeGrid& gridOf(std::size_t s);
  /// Refines closure `c` (kind, from, to and `searched` set) into submap `sm` by ICP of the node's
  /// points `pts` from `init` (the node's pose in the anchor's frame): sets `c.T_from_to` and
  /// `c.explained`, and rejects `c` (accepted = false, with the reason) when ICP fails, when it
  /// explains fewer than loop_min_explained_fraction of the points, or when it moved farther from
  /// `init` than a searched closure (0.3 m / 5 deg) or a link-following one (0.2 m / 3 deg) may.
  void refine(Constraint& c, const Submap& sm, const Points2& pts, const SE2& init) const;

 private:
  static constexpr std::size_t kMaxGrids = 8;
  static constexpr std::size_t kMaxCoarseGrids = 32;
  // searchUntied's grid: a whole submap at every heading costs (window / cell)^2 x headings, about
  // a second at the loop search's 5 cm; at 20 cm a few tens of ms, and ICP refines from there.
  static constexpr double kUntiedResolutionM = 0.2;
  static constexpr double kUntiedAngularStepRad = 0.5 * std::numbers::pi / 180.0;
  static registration::CorrelativeOptions untiedSearch(registration::CorrelativeOptions o) {
    o.resolution_m = std::max(o.resolution_m, kUntiedResolutionM);
    o.blur_sigma_m = std::max(o.blur_sigma_m, 0.5 * kUntiedResolutionM);
    return o;
  }
  static constexpr std::size_t kUntiedEveryNodes = 3;
  static constexpr std::size_t kUntiedSubmapsPerSearch = 4;
  static constexpr double kUntiedMarginM = 2.0;      // beyond the box of a submap's nodes
  static constexpr double kUntiedMaxWindowM = 15.0;  // the largest half-window of that search
  // acceptLoop: a relocalization shows the robot carried only where at least this share of the scan
  // lies in the map's free space at the estimate's pose (about twice what noise and a slightly
  // misplaced pose put there).
  static constexpr double kCarriedInFree = 0.1;
  // acceptLoop: ... and only where no match within the odometry's gate explains the scan nearly as
  // well (within this share of its points).
  static constexpr double kCarriedExplainsMore = 0.05;
  // contradictsLatestClosure: what a closure may differ from the latest one's prediction and from
  // the estimate over no path at all. Two closures' errors and the estimate's (pending corrections
  // not yet optimized in) stay well within it; a look-alike room or corridor stretch, the wrong
  // closures it guards against, lies metres away.
  static constexpr double kConsistentM = 1.0;

  /// The score grid of submap `s` at searchUntied's coarse resolution, built on demand (a few kept).
  const registration::CorrelativeGrid& coarseGridOf(std::size_t s);
  registration::CorrelativeGrid submapGrid(const Submap& sm,
                                           const registration::CorrelativeOptions& grid_options) const;
  const registration::CorrelativeGrid& cachedGrid(std::size_t s,
                                                  std::unique_ptr<registration::CorrelativeGrid> Submap::*grid,
                                                  std::vector<std::size_t>& lru, std::size_t max_kept,
                                                  const registration::CorrelativeOptions& options);
  void acceptLoop(Constraint c, Submap& sm);
  /// One branch-and-bound search of node `n` in submap `s` over `window` around the estimate, and
  /// the refinement of its answer into `c` (a searched closure; refine); false when nothing scored
  /// loop_min_score. `sparse`: node n's points for the search, filtered on first use.
  bool search(std::size_t n, std::size_t s, const registration::CorrelativeOptions& window,
              std::optional<Points2>& sparse, Constraint& c);
  /// Why a searched closure `c` (to node c.to, in the frame of node c.from) contradicts both the
  /// estimate and the latest accepted closure carried on along the front end's chain, beyond
  /// kConsistentM plus loop_window_per_m of the path since that closure or, where longer, of the
  /// path the graph's links span between c.from and c.to (untiedPathM); nullopt when it agrees with
  /// either, when no such closure precedes it on the same fragment, or without odometry.
  /// `weak_world` (unit, world frame): the closure's unconstrained direction, left out of both.
  std::optional<std::string> contradictsLatestClosure(const Constraint& c,
                                                      const std::optional<Eigen::Vector2d>& weak_world) const;
  /// A closure ties the untied fragment to the map before it, `sigmas` (carriedSigmas) from the
  /// odometry across the lost track: beyond prior_gate_sigmas that odometry is wrong (a kidnapped
  /// robot) and its constraint leaves the graph (listed as rejected, with an event).
  void dropCarriedOdometry(double sigmas);
  /// How far (in the odometry step's sigmas) the untied fragment's closure `c` puts the step across
  /// the lost track from the odometry's (the fragment must have its odometry link).
  double carriedSigmas(const Constraint& c) const;
  /// The odometry step across the lost track of the untied fragment (it must have its odometry
  /// link) as a prediction: the step and its sigmas for the time it took.
  MotionPrediction carriedOdometry() const;
  /// The distance [m] from `at` (world frame) to the estimate of submap `sm`'s nearest node, not to its
  /// centre: on a log with scans metres apart a submap's nodes span tens of metres of path, and a
  /// revisit of one end lies far from the centre of an L-shaped or U-shaped stretch.
  double nearestNodeM(const Submap& sm, const Eigen::Vector2d& at) const;
  /// The shortest path [m] between nodes `a` and `b` through the graph's accepted links, each link
  /// between consecutive nodes counting the front end's path between them and each closure none:
  /// the path over which the estimate of one relative to the other drifted.
  double untiedPathM(std::size_t a, std::size_t b) const;
  /// The share of node n's scan (of the untied fragment, with its odometry link) that the best match
  /// within the odometry's gate around its estimate explains (searched in every finished submap before
  /// node `first` near it, refined, and passing refine's tests; prior_gate_sigmas of the odometry
  /// step's sigmas across the lost track); 0 when none does.
  double explainedNearEstimate(std::size_t n, std::size_t first);
  /// The share of node n's scan that lies, with the node where the estimate puts it, in the free
  /// space of a finished submap before node `first` (cells seen free within the inlier distance).
  double inFreeSpaceWhereEstimated(std::size_t n, std::size_t first) const;
  /// Submap `sm`'s occupancy grid: every node's scan inserted (log-odds, ray traced) at its pose in
  /// the anchor's frame.
  OccupancyImage submapImage(const Submap& sm, double resolution_m) const;

  SlamState& s_;
  const SlamOptions& opt;
  const registration::IcpOptions& loop_icp;
  const registration::CorrelativeOptions& loop_search;
  const registration::CorrelativeOptions untied_search;
  std::vector<std::size_t> grid_lru;  // submaps holding a grid, least recently used first
  std::size_t untied_cursor = 0;      // the next submap searchUntied tries, in turn
  std::vector<std::size_t> coarse_lru;  // submaps holding a coarse grid, least recently used first
  std::optional<std::size_t> carry_refused_for;  // the fragment (untied_since) whose refusal was reported
};

}  // namespace lidar2d::slam::internal
