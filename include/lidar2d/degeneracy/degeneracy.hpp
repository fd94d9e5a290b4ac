#pragma once
/// @file
/// Degeneracy of a single scan: does the scan constrain the robot's translation in every direction,
/// and if not, along which direction is it free (the long axis of a corridor)?
///
/// Two detectors, each usable on its own, and their combination (`analyze`, the one call the matcher
/// and SLAM use):
/// - **Geometric** (`analyzeGeometric`): DBSCAN clusters on a k-d tree, a total-least-squares line
///   per cluster (split Douglas-Peucker style where one line does not fit: corners, curved or
///   cluttered clusters), then the translational constraint the lines and the non-line structures
///   give: M = sum over lines of (points * n n^T) + sum over non-line points of I/2 (a curved or
///   cluttered structure constrains every direction). Degenerate when the weakest direction d of M
///   carries almost nothing (d^T M d / points below a threshold) and well-fitted lines parallel to d
///   are there to say "corridor".
/// - **Information** (Zhang, Kaess & Singh 2016, "On degeneracy of optimization-based state
///   estimation problems", ICRA): the Gauss-Newton information matrix H = sum J_i^T J_i of the
///   point-to-line problem of the scan against itself at its own pose (J_i = [n_i^T, n_i . perp(p_i)],
///   n_i the normal of the line fitted to p_i's neighbours). Degenerate when the smallest eigenvalue
///   of its translational block, divided by the number of points with a normal (so that the threshold
///   does not depend on the beam count), falls below a threshold.
///
/// Input: the scan's points in beam order (as `LaserScan::toPoints` gives them): the thinning and the
/// line splitting walk the points in that order.
///
/// Frames and units: points are in the scan's own frame (the robot or laser frame) [m]; directions
/// are angles of an axis in that frame [rad], reported in (-pi/2, pi/2] (a direction and its
/// opposite are the same axis). Scores are dimensionless in [0, 0.5]: the translational information
/// along the weakest direction per point (0 = nothing constrains it, 0.5 = every direction is
/// constrained equally).
///
/// Bad input never throws: too few finite points, all points on one spot, or no usable structure give
/// `Verdict::kCannotDecide` (never a false "well constrained"). Options out of their domain throw
/// `lidar2d::Error` (kInvalidArgument) naming the field.

#include <Eigen/Core>
#include <cstddef>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"

namespace lidar2d::degeneracy {

/// What a detector concluded about a scan.
enum class Verdict {
  kWellConstrained,  ///< every translation direction is constrained
  kDegenerate,       ///< translation along `direction_rad` is (nearly) unconstrained
  kCannotDecide,     ///< too few points, all on one spot, or no usable structure
};
/// "well_constrained", "degenerate" or "cannot_decide".
const char* toString(Verdict v);

/// Checks shared by both detectors before they look at the structure.
struct InputOptions {
  std::size_t min_points = 20;  ///< fewer finite points: cannot decide, >= 3; the geometric detector also
                                ///< needs this many clustered points, the information detector this many
                                ///< points with a normal (after thinning)
  double min_spread_m = 0.2;    ///< RMS distance of the points from their centroid below this: all on one
                                ///< spot, cannot decide [m], >= 0
  /// Thinning before the analysis: a point closer than this to the last kept point (in input order, i.e.
  /// beam order) is merged into it [m], >= 0 (0 keeps every point). The dense returns of nearby walls
  /// would otherwise outweigh farther structure and cost time; it also makes the scores nearly
  /// independent of the beam count.
  double min_spacing_m = 0.07;
};

// ---------------------------------------------------------------------------------------------
// Geometric detector
// ---------------------------------------------------------------------------------------------

/// Options of the geometric (clusters + lines) detector.
struct GeometricOptions {
  InputOptions input;
  double cluster_eps_m = 0.25;            ///< DBSCAN neighbourhood radius near the sensor [m], > 0
  double cluster_eps_per_m = 0.025;       ///< ... grown with the point's range r to max(cluster_eps_m, r *
                                          ///< this) [m per m], >= 0: beams 1 degree apart are 0.017 m apart
                                          ///< per metre of range (0 = a fixed radius)
  std::size_t core_min_points = 3;        ///< DBSCAN: a core point has this many points within eps (itself
                                          ///< included), >= 1
  std::size_t min_cluster_points = 5;     ///< smaller clusters are clutter and ignored, >= 2
  std::size_t max_cluster_points = 2000;  ///< larger clusters are cut into pieces of at most this many
                                          ///< consecutive points (in input order, which must be beam
                                          ///< order) before the line fits, >= min_cluster_points
  double max_line_rms_m = 0.04;           ///< a piece is a line when the RMS orthogonal distance of its points from
                                          ///< the total-least-squares line is at most this [m], > 0; else it is split
                                          ///< at the point farthest from its end-to-end chord
  std::size_t min_line_points = 4;        ///< pieces with fewer points are not split further: their points are
                                          ///< "unstructured" (they constrain every direction equally), >= 2
  int max_split_depth = 8;                ///< recursion limit of the split, >= 0
  double parallel_tol_deg = 10.0;         ///< lines within this angle of the weakest direction count as parallel
                                          ///< to it ("corridor walls") [deg], in [0, 90)
  double min_parallel_length_m = 1.5;     ///< degenerate only when the parallel lines are at least this long in
                                          ///< total (else there is no corridor to speak of) [m], >= 0
  double threshold = 0.02;                ///< degenerate when the score (constraint along the weakest direction per
                                          ///< clustered point) is below this, in (0, 0.5]

  /// Empty when every field is in its domain, else a message naming the first bad field.
  std::string check() const;
};

/// A total-least-squares line fitted to a piece of a cluster.
struct Line {
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();    ///< [m], scan frame
  Eigen::Vector2d direction = Eigen::Vector2d::UnitX();  ///< unit vector along the line
  Eigen::Vector2d a = Eigen::Vector2d::Zero();           ///< end points: extreme projections of the points [m]
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  double rms_m = 0.0;  ///< RMS orthogonal residual [m]
  std::size_t num_points = 0;
  int cluster = -1;  ///< index of the cluster it belongs to
  double length() const { return (b - a).norm(); }
};

/// What the geometric detector found.
struct GeometricResult {
  Verdict verdict = Verdict::kCannotDecide;
  double score = std::numeric_limits<double>::quiet_NaN();          ///< constraint along the weakest direction per
                                                                    ///< clustered point, [0, 0.5]; NaN if undecided
  double direction_rad = std::numeric_limits<double>::quiet_NaN();  ///< weakest direction, (-pi/2, pi/2]
  std::vector<int> cluster_of_point;  ///< per input point: its cluster (that of the kept point it was merged
                                      ///< into), or -1 (noise, non-finite, or in a cluster smaller than
                                      ///< min_cluster_points)
  std::size_t num_clusters = 0;
  std::vector<Line> lines;                  ///< well-fitted lines of all clusters
  std::size_t num_clustered_points = 0;     ///< points (after thinning) in clusters of an accepted size
  std::size_t num_unstructured_points = 0;  ///< clustered points in no line
  double parallel_length_m = 0.0;           ///< total length of the lines parallel to the weakest direction [m]
  std::string reason;                       ///< why it cannot decide (empty otherwise)
};

/// Runs the geometric detector on a scan's points (scan frame [m]; non-finite points are ignored).
GeometricResult analyzeGeometric(const Points2& points_scan, const GeometricOptions& options = {});

// ---------------------------------------------------------------------------------------------
// Information-matrix detector (Zhang, Kaess & Singh 2016)
// ---------------------------------------------------------------------------------------------

/// Options of the information-matrix detector.
struct InformationOptions {
  InputOptions input;
  double normal_radius_m = 0.2;          ///< neighbours within this radius fit each point's line [m], > 0
  double normal_radius_per_m = 0.03;     ///< ... grown with the point's range r to max(normal_radius_m, r *
                                         ///< this) [m per m], >= 0 (0 = a fixed radius)
  std::size_t normal_min_neighbors = 3;  ///< fewer neighbours (itself included): the point gets no normal, >= 2
  double max_flatness = 0.3;             ///< sqrt(smaller / larger eigenvalue) of the neighbourhood above this: no line
                                         ///< (a corner or clutter), the point gets no normal, in (0, 1]
  double threshold = 0.01;               ///< degenerate when the score (smallest translational eigenvalue of H per
                                         ///< point with a normal) is below this, in (0, 0.5]

  /// Empty when every field is in its domain, else a message naming the first bad field.
  std::string check() const;
};

/// What the information-matrix detector found.
struct InformationResult {
  Verdict verdict = Verdict::kCannotDecide;
  double score = std::numeric_limits<double>::quiet_NaN();          ///< lambda_min(H_tt) / num_normals, [0, 0.5]
  double direction_rad = std::numeric_limits<double>::quiet_NaN();  ///< eigenvector of lambda_min, (-pi/2, pi/2]
  /// Rotation information per point relative to its maximum, H_thth / sum |p_i|^2, in [0, 1] (0 for a
  /// robot at the centre of a round room: its rotation is unconstrained); NaN if undecided.
  double rotation_score = std::numeric_limits<double>::quiet_NaN();
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();  ///< H in the parameters (x, y, theta) of the scan's
                                                          ///< pose, unit weights (unnormalised)
  std::size_t num_normals = 0;  ///< points (after thinning) with a normal (the rows of the problem)
  std::string reason;           ///< why it cannot decide (empty otherwise)
};

/// Runs the information-matrix detector on a scan's points (scan frame [m]; non-finite ignored).
InformationResult analyzeInformation(const Points2& points_scan, const InformationOptions& options = {});

// ---------------------------------------------------------------------------------------------
// Combination: the call the matcher and SLAM use
// ---------------------------------------------------------------------------------------------

/// Options of the combined analysis. `analyze` checks the input once with the stricter of the two
/// detectors' input options (the larger min_points and min_spread_m, the smaller min_spacing_m).
struct Options {
  GeometricOptions geometric;
  InformationOptions information;
  /// A detector whose score is below `confirm_factor` times its own threshold confirms the other's
  /// "degenerate" (see `analyze`), >= 1.
  double confirm_factor = 2.0;

  std::string check() const;
};

/// The combined verdict of both detectors.
struct Result {
  Verdict verdict = Verdict::kCannotDecide;
  /// Weakest translation direction in the scan frame, (-pi/2, pi/2] [rad]: the corridor's axis when
  /// degenerate; the least constrained direction when well constrained; NaN when undecided.
  double direction_rad = std::numeric_limits<double>::quiet_NaN();
  /// The information detector's score (or the geometric one's where the information detector cannot
  /// decide): 0 = free along `direction_rad`, 0.5 = isotropic; NaN when undecided.
  double score = std::numeric_limits<double>::quiet_NaN();
  std::string reason;  ///< why it cannot decide (empty otherwise)
  GeometricResult geometric;
  InformationResult information;

  bool degenerate() const { return verdict == Verdict::kDegenerate; }
  /// Unit vector of `direction_rad` (NaN when undecided).
  Eigen::Vector2d direction() const;
};

/// Both detectors on one k-d tree, and their combination:
/// - cannot decide when the input checks fail or neither detector can decide;
/// - degenerate when both say degenerate, or when one says degenerate and the other's score is below
///   `confirm_factor` times its threshold (the detectors see the same weakness from two sides: the
///   information detector misses walls broken into short pieces, the geometric one a scan whose clusters
///   are too sparse); when only one detector can decide, its verdict;
/// - well constrained otherwise.
Result analyze(const Points2& points_scan, const Options& options = {});

// ---------------------------------------------------------------------------------------------
// Using the verdict: solution remapping and odometry along the degenerate direction
// ---------------------------------------------------------------------------------------------

/// The information detector's test on a matcher's result: the unit eigen-direction of a translational
/// information matrix per matched point (the top-left 2x2 of `registration::Result::information`
/// divided by its inliers; a corridor's axis) whose eigenvalue is the smallest, when that eigenvalue
/// is below `threshold` (infinity: always, the least constrained direction); nullopt otherwise, or
/// when the decomposition fails (a matrix that is not finite).
std::optional<Eigen::Vector2d> weakestDirection(const Eigen::Matrix2d& H_per_point, double threshold);

/// Zhang et al. 2016 solution remapping: the projector P = V diag(m) V^T onto the eigenvectors of the
/// symmetric information matrix `H` (3x3, parameters (x, y, theta)) whose eigenvalue is at least
/// `min_eigenvalue` (m_i = 1 there, 0 elsewhere). A Gauss-Newton increment dx then becomes P dx: the
/// solver moves only in the well-constrained directions. Mixed units (m, rad): scale `H` first if the
/// threshold should treat them differently. Non-finite `H` gives the zero projector. For a matcher's
/// `registration::Result::information` (a sum over its inliers with unit weights) use a few hundredths
/// of `num_inliers` (e.g. 0.05): the point-to-line matcher's normals (5 nearest neighbours) are noisier
/// than the information detector's, which leaves about 0.01 per inlier along a simulated corridor with
/// 1 cm range noise. Where a `Result` of `analyze` is at hand, `projectorRemovingDirection` is simpler.
Eigen::Matrix3d wellConstrainedProjector(const Eigen::Matrix3d& H, double min_eigenvalue);

/// The projector that removes translation along the axis `direction_rad` (in the frame of the
/// increment's translation) and keeps the rest: I - [d d^T 0; 0 0].
Eigen::Matrix3d projectorRemovingDirection(double direction_rad);

/// Remaps a finished estimate: `init` plus P times the parameter difference (x, y, theta) of
/// `estimate` from `init` (angle difference wrapped). With the projector of a degenerate scan, the
/// result keeps the initial guess (odometry) along the degenerate direction and the estimate across.
SE2 remapPose(const SE2& init, const SE2& estimate, const Eigen::Matrix3d& P);

/// The front end's call after matching a source scan against a target (scan or submap):
/// `T_match` and `T_prior` (odometry) both estimate T_target_source. When `source` (the analysis of
/// the source scan, in its own frame) is degenerate, returns `T_match` with its translation along the
/// degenerate direction (rotated into the target frame by `T_prior`'s angle) replaced by the prior's;
/// `T_match` unchanged when it is well constrained, and `T_prior` when it cannot be decided (never
/// trust a scan that could not be judged).
SE2 constrainMatch(const SE2& T_match, const SE2& T_prior, const Result& source);

}  // namespace lidar2d::degeneracy
