#pragma once
// SLAM's front end: each scan matched against a local map of the last few nodes, in the drift-prone
// "local" frame, from the motion prior's prediction (motion_prior.hpp), searched over a window
// sized to the prior's uncertainty; a match that contradicts the prior is taken only on strong
// scan evidence.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <deque>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "src/slam/internal/motion_prior.hpp"
#include "src/slam/internal/points.hpp"
#include "src/slam/internal/state.hpp"

namespace lidar2d::slam::internal {

class FrontEnd {
 public:
  /// Reads the options and settings of `s`, and its nodes when the local map is rebuilt; records
  /// events and counters there.
  explicit FrontEnd(SlamState& s)
      : s_(s),
        opt(s.opt),
        icp(s.match.icp),
        local_lf(s.match.local_lf),
        fallback(s.match.fallback),
        prior_(s.opt) {}
  FrontEnd(const FrontEnd&) = delete;
  FrontEnd& operator=(const FrontEnd&) = delete;

  using Prediction = MotionPrediction;
  /// The scan's match.
  struct Tracked {
    SE2 T_local_robot;  ///< the match, or the prediction when unmatched
    /// How the scan was placed; nothing when it was left at the prediction (neither matched nor
    /// vouched for by the odometry, FrontEnd::OdometryVouches: not a node, a step towards a lost
    /// track). Placed by odometry, it becomes a node, not a failure.
    std::optional<Placement> placement;
    bool degenerate = false;  ///< the match (or the one refining the placement) could not pin `dir`
    Eigen::Vector2d dir = Eigen::Vector2d::Zero();  ///< local frame, the direction the scan could not pin
    bool restart = false;                           ///< tracking lost: the local map restarts at this scan
    std::size_t lost_before = 0;  ///< restart: the scans just before it left at the prediction, in a row
    bool overrode_prior = false;                    ///< the match contradicts the prior (strong scan evidence)
    bool matched() const { return placement == Placement::kMatched; }
  };

  /// Why an unmatched scan under a trusted odometry prior (odometryTrusted) is placed by the
  /// odometry rather than counted towards a lost track: it overlaps almost nothing of the local map
  /// at the prediction (it sees only new ground), or the best match near the prediction, though too
  /// weak to take (or the prediction itself, where ICP found too few pairs or slid away), explains
  /// at least as much of it as any match farther away (the scan points nowhere else), or it refines
  /// the placement (refinesPlacement) where a match farther away explains more without outweighing
  /// the prior.
  enum class OdometryVouches { kNo, kNewGround, kBestMatchNearIt, kNearMatchRefines };

  /// True once a scan was remembered.
  bool started() const { return have_prev; }
  /// Where the first scan anchors the local frame: its odometry pose (so the map lines up with
  /// it), or the origin.
  SE2 firstPose(const Frame& f) const;
  /// The prediction for `f` (MotionPrior::predict); records its events.
  Prediction predict(const Frame& f);
  /// Matches `pts` (robot frame, voxel-filtered) of `f`, a scan after the first; counts matched,
  /// unmatched, degenerate scans and correlative fallbacks, and records failures as events.
  Tracked track(const Frame& f, const Points2& pts, const Prediction& p);
  /// A node at `T_local` with its points `pts` (robot frame) was added (`restart`: the local map
  /// starts again from it): rebuilds the local map from the last local_map_nodes nodes. The front
  /// end keeps its own copy, so it never reads the graph the back end may be extending.
  void addNode(const SE2& T_local, const Points2& pts, bool restart);
  /// Remembers scan `f`, predicted by `p`, at `T_local` for the next prediction; `first`: the first
  /// scan (no step), `pinned`: the scan measured its step (MotionPrior::remember).
  void remember(const Frame& f, const Prediction& p, const SE2& T_local, bool first, bool pinned = true);

  /// One match of the scan: its result, the share of the scan it explains and its distance from
  /// the prediction in sigmas.
  struct Candidate {
    registration::Result res;
    double explained = 0.0;
    double sigmas = 0.0;
    Overlap overlap;
    SE2 T;  ///< the result, remapped along a degenerate direction (remapDegenerate)
    bool degenerate = false;
    Eigen::Vector2d dir = Eigen::Vector2d::Zero();  ///< local frame, the direction the scan could not pin
    bool searched = false;  ///< ICP started from the correlative search's answer over the whole window
  };
  /// Whether match `c` replaces `best` among the matches within the prior's gate: it explains
  /// clearly more of the scan (5%); or about as much and the prior clearly prefers it
  /// (kPriorTieNats: along an aliased corridor a match one door further explains as much as the
  /// one at the prediction, and may pin every direction where that one does not); or about as
  /// much, about as likely, and it pins every direction where `best` does not (a degenerate match
  /// keeps the prediction along the corridor, a guess after a gap); or about as much with a
  /// clearly lower residual cost.
  static bool replaces(const Candidate& c, const Candidate& best);
  /// Whether a prior that may vouch (frontEndMatch: narrow or drawn from the robot's own steps, no
  /// gap) vouches for `c`, the best match within its gate, where `c` explains under
  /// `min_explained` of the scan because the scan sees new ground: at least kMinOverlap of the scan
  /// overlaps the local map, `min_explained` of those points are explained, and `c` lies within
  /// kVouchSigmas of the prediction or the correlative search found it (it scored every pose of the
  /// window; ICP from the prediction or another start only descends into the nearest minimum).
  static bool priorVouchesFor(const Candidate& c, double min_explained);
  /// Whether `c`, the best match within the gate of a scan the odometry places (too weak to take as
  /// a match), refines that placement: within kRefineSigmas of the prediction, at least
  /// kMinOverlap of the scan overlapping the local map and kRefineExplainedInOverlap of those points
  /// explained. A degenerate match qualifies too: remapped along its weak direction, it refines the
  /// heading and the direction it pins (FrontEnd::track then asks refine_min_turn_sigmas of it).
  static bool refinesPlacement(const Candidate& c);

 private:
  // Two matches explaining about as much: the prior prefers one when its log-density is this much
  // higher (2 nats: one within 1 sigma of the prediction against one beyond 2.2 sigmas).
  static constexpr double kPriorTieNats = 2.0;
  static constexpr double kConfirmExplained = 0.9;     // a match explaining this much confirms its start
  static constexpr double kEarlierWithOdometry = 0.8;  // see frontEndMatch's `earlier`
  // A prior wider than this (sigma) is beyond ICP's basin of convergence: the correlative search
  // runs unless a match is confirmed.
  static constexpr double kIcpBasinM = 0.3;
  static constexpr double kIcpBasinRad = 20.0 * kDeg;
  // A scan point this near the local map overlaps it (ICP's own reach, icp_max_correspondence_m's
  // default); a match within the prior's gate is judged on the overlapping points when at least
  // kMinOverlap of the scan overlaps.
  static constexpr double kOverlapM = 0.5;
  static constexpr double kMinOverlap = 0.3;
  // The prior vouches for such a match only this near the prediction (Mahalanobis distance), unless
  // the correlative search found it: a match explaining under min_explained_fraction of the scan is
  // weak evidence, and one 2-4 sigmas out that ICP reached from a start was further from the truth
  // than the prediction on every such scan of the benchmark's runs (28 of 28; docs/slam.md, step 4).
  static constexpr double kVouchSigmas = 2.0;
  // A scan the odometry places is put at the best match near the prediction when that match lies
  // within this many sigmas of it and explains this share of the points that overlap the local map
  // (refinesPlacement). Of the scans placed by odometry on the corrected logs as keyframes 2-3 m
  // apart (seeds 1-3, without this rule), 398 had such a match: nearer the truth's heading than the
  // odometry by more than 2 degrees on 165, further on 12; summed heading error 1397 -> 702 degrees.
  static constexpr double kRefineSigmas = 1.0;
  static constexpr double kRefineExplainedInOverlap = 0.3;
  // An unmatched scan under an odometry prior of which less than this overlaps the local map at the
  // prediction sees only new ground (FrontEnd::track).
  static constexpr double kNewGroundOverlap = 0.1;
  // An event states the odometry's scale factor when it moved this much since the last one stated.
  static constexpr double kReportScaleChange = 0.01;
  // Which earlier scans' poses are starting points (scans back, ascending).
  static constexpr std::array<std::size_t, 4> kEarlierBack{2, 4, 8, 16};

  /// What frontEndMatch found.
  struct MatchOutcome {
    std::optional<SE2> T;       ///< the pose, or nothing when the scan was not matched
    bool degenerate = false;
    Eigen::Vector2d dir = Eigen::Vector2d::Zero();  ///< local frame
    bool used_fallback = false;                     ///< the correlative search ran
    bool overrode_prior = false;                    ///< T contradicts the prior (taken on scan evidence)
    std::optional<Candidate> rejected;              ///< a match contradicting the prior, without the evidence
    double explained = 0.0;                         ///< the share of the scan T explains
    /// The share the best match within the prior's gate explains (unmatched: or the prediction).
    double explained_in_gate = 0.0;
    /// Nothing within the gate matched, no match beyond it was refused, and the odometry vouches
    /// for the prediction (OdometryVouches): placed by the odometry when unmatched (Tracked::placement).
    OdometryVouches vouches = OdometryVouches::kNo;
    /// The best match within the gate when it refines a placement by the odometry (refinesPlacement,
    /// `refine_odometry_placement`), whether taken as a match or not.
    std::optional<Candidate> refining;
  };

  void rebuildLocalMap();
  void remapDegenerate(Candidate& c, const Prediction& p, const SE2& T_pred) const;
  /// Whether `p` is an odometry prior the front end trusts: no gap since the last match, time as
  /// predicted, a plausible step.
  bool odometryTrusted(const Prediction& p) const;
  /// Whether, under a trusted odometry prior, under kNewGroundOverlap of the scan at the prediction
  /// overlaps the local map.
  bool onlyNewGroundAt(const Points2& pts, const Prediction& p, const SE2& T_pred) const;
  MatchOutcome frontEndMatch(const Points2& pts, const Prediction& p, const SE2& T_pred,
                             const std::vector<SE2>& alternatives, const std::vector<SE2>& earlier,
                             double earlier_below);

  SlamState& s_;
  const SlamOptions& opt;
  const registration::IcpOptions& icp;
  const registration::LikelihoodFieldOptions& local_lf;
  const registration::CorrelativeOptions& fallback;

  MotionPrior prior_;
  bool have_prev = false;
  SE2 T_local_prev;
  std::optional<SE2> last_step;  // the front end's last step (robot frame) when time went forward
  std::deque<SE2> recent_poses;  // the front end's poses of the last kEarlierBack.back() scans, oldest first
  int consecutive_failures = 0;
  bool prev_matched = false;         // the previous scan was matched and pinned in every direction
  double reported_scale = 1.0;       // the odometry scale the latest event stated
  bool since_gap_unmatched = false;  // no scan matched since the last gap: where the robot is is in doubt
  std::deque<std::pair<SE2, Points2>> local_nodes;  // the local map's nodes: pose, points (robot frame)
  std::unique_ptr<registration::IcpTarget> local_target;
  std::unique_ptr<registration::LikelihoodField> local_field;  // front_end_likelihood_field
  Points2 local_points;
  registration::CorrelativeGrid local_grid;  // of local_points when local_grid_built (memory reused)
  bool local_grid_built = false;
};

}  // namespace lidar2d::slam::internal
