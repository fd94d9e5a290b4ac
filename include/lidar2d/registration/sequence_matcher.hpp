#pragma once
/// @file
/// Scan-to-scan matching over a stream of frames: every frame's scan is matched to the previous
/// frame's, optionally refined by ICP from that estimate, with the pairs spread over threads.
///
/// Frames: each scan becomes points in its robot frame (`LaserScan::toPoints(T_robot_laser)`); a
/// pair's estimate is `T_prev_cur`, the pose of the current frame's robot in the previous frame's
/// robot frame (`T_target_source` of matchScans with target = previous, source = current).
///
/// The results are those of matching the pairs one at a time with `matchScans` (prepared target of
/// the previous frame, source points of the current one, the initial guess of `SequenceOptions`),
/// whatever the thread count and chunk size: frames are read in chunks, each chunk's targets
/// prepared and its pairs matched on all threads, and the pairs reported in frame order.

#include <cstddef>
#include <functional>
#include <optional>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/registration/matcher.hpp"
#include "lidar2d/registration/result.hpp"

namespace lidar2d::registration {

/// The initial guess of a pair: T_prev_cur before matching. Called on the matching threads (it must
/// be safe to call concurrently); may throw `lidar2d::Error`, which `SequenceMatcher::run` rethrows.
using InitialGuess = std::function<SE2(const Frame& prev, const Frame& cur)>;

/// The odometry's relative motion `prev.T_odom_robot^-1 * cur.T_odom_robot`. Throws Error
/// (kBadInput) naming the frame when either frame has no odometry.
SE2 odometryGuess(const Frame& prev, const Frame& cur);
/// No motion: the identity.
SE2 identityGuess(const Frame& prev, const Frame& cur);

/// Options of a sequence match.
struct SequenceOptions {
  /// The first stage: every pair is matched with it.
  MatcherOptions matcher;
  /// The refine stage: ICP (kP2P or kP2L, with `matcher`'s other options) from the first stage's
  /// estimate; then a correlative first stage skips its own likelihood-field refinement
  /// (`CorrelativeOptions::refine`), which the ICP stage replaces. Not run after a first stage that
  /// reports kInvalidInput. std::nullopt: none.
  std::optional<Method> then;
  /// The initial guess of each pair.
  InitialGuess init = odometryGuess;
  /// Threads preparing targets and matching pairs (the caller's included), clamped to 1..64 (0
  /// counts as 1). The results do not depend on it.
  unsigned threads = 1;
  /// Frames read, prepared and matched together, >= 1: memory held against threads left idle at
  /// the end of each chunk. The results do not depend on it.
  std::size_t chunk_frames = 128;
};

/// One matched pair of consecutive frames.
struct SequencePair {
  std::size_t index_prev = 0;  ///< Frame::index of the previous (target) frame
  std::size_t index_cur = 0;   ///< Frame::index of the current (source) frame
  double t_prev = 0.0;         ///< Frame::time of the previous frame [s]
  double t_cur = 0.0;          ///< Frame::time of the current frame [s]
  Result result;               ///< T_target_source = T_prev_cur [m, rad]
  bool refined = false;        ///< `result` is the refine stage's (SequenceOptions::then)
  /// Preparing the current frame (its points and target, the next pair's) and matching this pair
  /// on one thread: wall time [s] and that thread's CPU time [s].
  double wall_s = 0.0;
  double cpu_s = 0.0;
};

/// What a run did.
struct SequenceSummary {
  std::size_t frames = 0;     ///< frames read
  std::size_t pairs = 0;      ///< pairs reported (frames - 1, or 0)
  std::size_t converged = 0;  ///< pairs whose result converged
  /// Preparing every frame and matching every pair, wall time summed over the threads [s] (the
  /// first frame's preparation included; reading frames excluded).
  double wall_s = 0.0;
};

/// Matches every frame of a stream to the previous one. Stateless between runs; `run` may be
/// called several times, also concurrently.
class SequenceMatcher {
 public:
  /// The next frame, or std::nullopt at the end. Called on the calling thread only.
  using FrameProducer = std::function<std::optional<Frame>()>;
  /// Receives the pairs in frame order, on the calling thread (may be empty).
  using PairSink = std::function<void(const SequencePair&)>;
  /// Receives the number of pairs reported so far, after each chunk, on the calling thread.
  using Progress = std::function<void(std::size_t pairs_done)>;

  /// Throws Error (kInvalidArgument) when `options.matcher.icp` is out of its domain
  /// (`IcpOptions::check`, for every method), `options.then` is not kP2P or kP2L, `options.init` is
  /// empty or `options.chunk_frames` is 0. Out-of-domain options of the other methods are reported
  /// per pair as kInvalidInput, as by matchScans.
  explicit SequenceMatcher(SequenceOptions options);

  /// Matches the frames of `next_frame` until it returns std::nullopt and hands each pair to
  /// `on_pair`. An exception from `next_frame`, the guess or `on_pair` stops the run and is
  /// rethrown (after the threads have finished); the pairs reported before it stand.
  SequenceSummary run(const FrameProducer& next_frame, const PairSink& on_pair, const Progress& progress = {}) const;
  /// The same over a vector of frames (copied one chunk at a time).
  SequenceSummary run(const std::vector<Frame>& frames, const PairSink& on_pair, const Progress& progress = {}) const;

  /// Matches one pair as `run` does, both stages (their targets prepared from `points_target`),
  /// from `init_T_target_source`; `refined` (optional) tells whether the refine stage ran. For
  /// pairs that are not consecutive frames (e.g. ground-truth relations).
  Result matchPair(const Points2& points_target, const Points2& points_source, const SE2& init_T_target_source,
                   bool* refined = nullptr) const;

  const SequenceOptions& options() const { return options_; }

 private:
  // Both stages against prepared targets (`second`: the refine stage's, when it runs).
  Result matchStages(const PreparedTarget& first, const PreparedTarget* second, const Points2& source,
                     const SE2& init_T_target_source, bool* refined) const;

  const SequenceOptions options_;
  const MatcherOptions first_;                  // the first stage's (no correlative refinement before ICP)
  const std::optional<MatcherOptions> second_;  // the refine stage's, with `then`
};

}  // namespace lidar2d::registration
