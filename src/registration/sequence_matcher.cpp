#include "lidar2d/registration/sequence_matcher.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <utility>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "src/core/parallel_for.hpp"

namespace lidar2d::registration {

SE2 odometryGuess(const Frame& prev, const Frame& cur) {
  for (const Frame* f : {&prev, &cur})
    if (!f->T_odom_robot) throw badInput(fmt::format("scan {} (time {:.6f}) has no odometry", f->index, f->time));
  return prev.T_odom_robot->inverse() * *cur.T_odom_robot;
}

SE2 identityGuess(const Frame& /*prev*/, const Frame& /*cur*/) { return SE2(); }

namespace {

// Wall and CPU time of the calling thread since construction [s].
class Stopwatch {
 public:
  Stopwatch() : wall0_(std::chrono::steady_clock::now()), cpu0_(threadCpuSeconds()) {}
  double wall() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0_).count(); }
  double cpu() const { return threadCpuSeconds() - cpu0_; }

 private:
  static double threadCpuSeconds() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  }
  std::chrono::steady_clock::time_point wall0_;
  double cpu0_;
};

const SequenceOptions& checked(const SequenceOptions& o) {
  if (const std::string bad = o.matcher.icp.check(); !bad.empty())
    throw invalidArgument(fmt::format("invalid matcher option: {}", bad));
  if (o.then && *o.then != Method::kP2P && *o.then != Method::kP2L)
    throw invalidArgument("the refine stage must be an ICP method (p2p or p2l)", ErrorLocation({}, 0, "then"));
  if (!o.init) throw invalidArgument("no initial guess", ErrorLocation({}, 0, "init"));
  if (o.chunk_frames == 0) throw invalidArgument("must be >= 1", ErrorLocation({}, 0, "chunk_frames"));
  return o;
}

MatcherOptions firstStage(const SequenceOptions& o) {
  MatcherOptions first = o.matcher;
  if (o.then && o.matcher.method == Method::kCorrelative) first.corr.refine = false;
  return first;
}

std::optional<MatcherOptions> refineStage(const SequenceOptions& o) {
  if (!o.then) return std::nullopt;
  MatcherOptions second = firstStage(o);
  second.method = *o.then;
  return second;
}

}  // namespace

SequenceMatcher::SequenceMatcher(SequenceOptions options)
    : options_(checked(options)), first_(firstStage(options_)), second_(refineStage(options_)) {}

Result SequenceMatcher::matchStages(const PreparedTarget& first, const PreparedTarget* second, const Points2& source,
                                    const SE2& init_T_target_source, bool* refined) const {
  Result r = matchScans(first, source, init_T_target_source, first_);
  const bool refine = second_ && r.status != Status::kInvalidInput;
  if (refine) r = matchScans(*second, source, r.T_target_source, *second_);
  if (refined) *refined = refine;
  return r;
}

Result SequenceMatcher::matchPair(const Points2& points_target, const Points2& points_source,
                                  const SE2& init_T_target_source, bool* refined) const {
  const PreparedTarget first(points_target, first_);
  std::optional<PreparedTarget> second;
  if (second_) second.emplace(points_target, *second_);
  return matchStages(first, second ? &*second : nullptr, points_source, init_T_target_source, refined);
}

SequenceSummary SequenceMatcher::run(const FrameProducer& next_frame, const PairSink& on_pair,
                                     const Progress& progress) const {
  const unsigned threads = std::max(1u, std::min(options_.threads, 64u));
  const std::size_t chunk_frames = options_.chunk_frames;
  SequenceSummary summary;
  // The last frame of the previous chunk and its targets: the target of the chunk's first pair.
  std::optional<Frame> prev_frame;
  std::optional<PreparedTarget> prev, prev_second;
  std::vector<Frame> chunk;
  chunk.reserve(chunk_frames);
  for (bool more = true; more;) {
    chunk.clear();
    while (chunk.size() < chunk_frames) {
      std::optional<Frame> f = next_frame();
      if (!f) {
        more = false;
        break;
      }
      chunk.push_back(std::move(*f));
    }
    const std::size_t n = chunk.size();
    if (n == 0) break;
    summary.frames += n;
    std::vector<std::optional<PreparedTarget>> targets(n), targets_second(n);
    std::vector<std::optional<SequencePair>> pairs(n);
    std::vector<double> wall(n, 0.0), cpu(n, 0.0);
    parallelFor(n, threads, [&](std::size_t i) {
      const Stopwatch watch;
      targets[i].emplace(chunk[i].scan.toPoints(chunk[i].T_robot_laser), first_);
      if (second_) targets_second[i].emplace(targets[i]->points(), *second_);
      wall[i] += watch.wall();
      cpu[i] += watch.cpu();
    });
    parallelFor(n, threads, [&](std::size_t i) {
      const Frame* before = i > 0 ? &chunk[i - 1] : (prev_frame ? &*prev_frame : nullptr);
      if (!before) return;  // the stream's first frame
      const PreparedTarget& target = i > 0 ? *targets[i - 1] : *prev;
      const Stopwatch watch;
      SequencePair& pair = pairs[i].emplace();
      pair.index_prev = before->index;
      pair.index_cur = chunk[i].index;
      pair.t_prev = before->time;
      pair.t_cur = chunk[i].time;
      const PreparedTarget* target_second = !second_ ? nullptr : i > 0 ? &*targets_second[i - 1] : &*prev_second;
      pair.result =
          matchStages(target, target_second, targets[i]->points(), options_.init(*before, chunk[i]), &pair.refined);
      wall[i] += watch.wall();
      cpu[i] += watch.cpu();
    });
    for (std::size_t i = 0; i < n; ++i) {
      summary.wall_s += wall[i];
      if (!pairs[i]) continue;
      pairs[i]->wall_s = wall[i];
      pairs[i]->cpu_s = cpu[i];
      ++summary.pairs;
      summary.converged += pairs[i]->result.converged;
      if (on_pair) on_pair(*pairs[i]);
    }
    if (progress) progress(summary.pairs);
    prev = std::move(targets[n - 1]);
    prev_second = std::move(targets_second[n - 1]);
    prev_frame = std::move(chunk[n - 1]);
  }
  return summary;
}

SequenceSummary SequenceMatcher::run(const std::vector<Frame>& frames, const PairSink& on_pair,
                                     const Progress& progress) const {
  std::size_t next = 0;
  const FrameProducer produce = [&]() -> std::optional<Frame> {
    if (next == frames.size()) return std::nullopt;
    return frames[next++];
  };
  return run(produce, on_pair, progress);
}

}  // namespace lidar2d::registration
