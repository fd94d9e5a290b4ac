#include "lidar2d/slam/slam.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <optional>
#include <stop_token>
#include <thread>
#include <utility>

#include "lidar2d/core/error.hpp"
#include "lidar2d/slam/state_file.hpp"
#include "src/slam/internal/descriptor_loops.hpp"
#include "src/slam/internal/front_end.hpp"
#include "src/slam/internal/graph.hpp"
#include "src/slam/internal/loop_closure.hpp"
#include "src/slam/internal/moving_objects.hpp"
#include "src/slam/internal/points.hpp"
#include "src/slam/internal/state.hpp"

namespace lidar2d::slam {

namespace internal {

MatcherSettings makeMatcherSettings(const SlamOptions& opt) {
  MatcherSettings m;
  m.icp.max_correspondence_dist_m = opt.icp_max_correspondence_m;
  m.icp.max_iterations = 30;
  // Convergence at 0.1 mm / 0.1 mrad, not point-to-line's default of 1 mm / 1 mrad
  // (IcpOptions::defaultTranslationEps): the front end chains thousands of matches.
  m.icp.translation_eps_m = 1e-4;
  m.icp.rotation_eps_rad = 1e-4;
  // No two-point lines (IcpOptions::two_point_lines): SLAM's target is a local map of several
  // scans, not one scan in beam order, and on the Intel log without odometry they cost the track.
  m.icp.two_point_lines = false;
  // SLAM thins its scans with its own voxel filter (scan_voxel_m); ICP's spacing filter on top of
  // it (IcpOptions::min_source_spacing_m) thins them too far: loops of the simulated office were lost.
  m.icp.min_source_spacing_m = 0.0;
  // Local maps and submaps stack several scans in a frame far from their sensors: the bearing
  // walk (made for one scan seen from its own origin) would visit many points per query there.
  m.icp.neighbor_search = registration::NeighborSearch::kKdTree;
  m.icp.normal_neighbors = opt.normal_neighbors;
  m.icp.max_line_flatness = opt.max_line_flatness;
  m.loop_icp = m.icp;
  // The local map's points are merged from several scans (not in beam order): no wall segments.
  m.local_lf.resolution_m = opt.map_voxel_m;
  m.local_lf.levels = 2;
  m.local_lf.truncation_m = 0.2;
  m.local_lf.connect_max_gap_m = 0.0;
  m.loop_icp.max_correspondence_dist_m = std::min(opt.icp_max_correspondence_m, 0.3);
  m.fallback.linear_window_m = opt.fallback_linear_window_m;
  m.fallback.angular_window_rad = opt.fallback_angular_window_rad;
  m.fallback.refine = false;
  m.fallback.min_score = 0.0;
  // A fixed 0.5 degree step: derived from the farthest point (Hess 2016, eq. 7) it would be ~0.1
  // degree for 30 m returns, five times the work; ICP refines the answer anyway.
  m.fallback.angular_step_rad = 0.5 * kDeg;
  m.loop_search = m.fallback;
  m.loop_search.linear_window_m = opt.loop_linear_window_m;
  m.loop_search.angular_window_rad = opt.loop_angular_window_rad;
  // A best under loop_min_score is discarded anyway: starting the search from it prunes every branch
  // that cannot reach it, with the same answers (registration::CorrelativeOptions::min_score).
  m.loop_search.min_score = opt.loop_min_score;
  m.descriptor_search = m.loop_search;
  m.descriptor_search.linear_window_m = opt.descriptor_linear_window_m;
  m.descriptor_search.angular_window_rad = opt.descriptor_angular_window_rad;
  // The localizer's query options (line extraction, key radius, vote bins) describe SLAM's scans
  // too: both sides of the lookup are real scans here.
  m.descriptor_query.max_query_lines = opt.descriptor_max_lines;
  m.descriptor_query.max_range_m = opt.max_range_m;
  m.descriptor_db.lines = m.descriptor_query.lines;
  m.descriptor_db.max_lines = std::min<std::size_t>(64, std::max<std::size_t>(2, opt.descriptor_max_lines));
  return m;
}

}  // namespace internal

using internal::Clock;
using internal::secondsSince;

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

namespace {

/// One long-lived worker thread running queued tasks in order: the SLAM back end's. A thread per
/// task (std::async) gave each node a new thread, and glibc a new malloc arena per thread: 50%
/// more peak memory on the Intel bag. (The standard library has no thread pool or task queue, and
/// one thread is all this needs.)
class Worker {
 public:
  /// At most `max_queued` tasks wait: a caller faster than the back end for long then waits too,
  /// so the queue's memory stays bounded.
  explicit Worker(std::size_t max_queued)
      : max_queued_(max_queued), thread_([this](std::stop_token stop) { run(stop); }) {}
  /// Drops the tasks not started (their results would go unread) and joins after the running one.
  ~Worker() {
    {
      std::lock_guard lock(mutex_);
      queue_.clear();
    }
    thread_.request_stop();
    cv_.notify_all();
  }
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  /// Queues `task` after the others; rethrows what an earlier task threw (the tasks after it were
  /// dropped).
  void start(std::function<void()> task) {
    std::unique_lock lock(mutex_);
    cv_.wait(lock, [&] { return queue_.size() < max_queued_ || error_; });
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
    queue_.push_back(std::move(task));
    cv_.notify_all();
  }
  /// Waits until every queued task has run; rethrows what one threw.
  void wait() {
    std::unique_lock lock(mutex_);
    cv_.wait(lock, [&] { return queue_.empty() && !busy_; });
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
  }

 private:
  void run(std::stop_token stop) {
    std::unique_lock lock(mutex_);
    while (true) {
      cv_.wait(lock, [&] { return stop.stop_requested() || !queue_.empty(); });
      if (queue_.empty()) return;  // stopped, nothing left to do
      std::function<void()> task = std::move(queue_.front());
      queue_.pop_front();
      busy_ = true;
      lock.unlock();
      std::exception_ptr error;
      try {
        task();
      } catch (...) {
        error = std::current_exception();
      }
      lock.lock();
      busy_ = false;
      if (error) {
        error_ = error;
        queue_.clear();  // they would build on a state the failed task left half done
      }
      cv_.notify_all();
    }
  }

  const std::size_t max_queued_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> queue_;
  bool busy_ = false;
  std::exception_ptr error_;
  std::jthread thread_;  // last: started once the members it uses exist, joined first
};

}  // namespace

/// The pipeline: each scan goes through the front end; the motion filter makes some of them nodes;
/// a node joins the local map and a submap, gets its sequential constraints, is searched for loop
/// closures (by proximity, then by descriptors), and the graph is optimised when due.
struct Slam::Impl {
  // Nodes the back end may be behind by before `add` waits for it: a bound on the queue's memory
  // (each holds a scan and its points, under 20 KB for 361 beams: at most about 20 MB). A log
  // replayed as fast as possible runs ahead of the back end; a scan that waits for it is not slower
  // to match, so the bound is set well above what such replays reach (Intel's 45 minutes in 8 s:
  // the back end 381 nodes behind at worst), and their scans' times are the front end's.
  static constexpr std::size_t kMaxQueuedNodes = 1024;

  Impl(const SlamOptions& o, std::string session)
      : state(o), front_end(state), loops(state), descriptors(state, loops) {
    state.sessions.push_back({std::move(session), 0});
  }
  Impl(State saved, std::string session) : Impl(saved.options, {}) {
    restore(std::move(saved));
    resumed_session = std::move(session);
  }

  internal::SlamState state;
  internal::FrontEnd front_end;
  internal::LoopClosure loops;
  internal::DescriptorLoops descriptors;
  internal::MovingObjectFilter moving_objects{state.opt};
  bool finished = false;
  // The name of the session a restored state continues with, until its first scan opens it (a state
  // saved again before that is the saved one, byte for byte).
  std::optional<std::string> resumed_session;
  // The front end's own record of the nodes (their count, the last one's time and pose: the motion
  // filter's reference) and of the newest scan's pose: while the back end runs, the graph is its own.
  std::size_t nodes_added = 0;
  double last_node_time = 0.0;
  SE2 last_node_T_local;
  SE2 last_T_local;
  // What the back end last published for the caller's thread (Slam::latest, Slam::statsSoFar):
  // state.T_world_local and the counters after its latest finished node.
  mutable std::mutex published_mutex;
  SE2 published_T_world_local;
  SlamStats published_stats;
  // Runs the nodes' graph work (graphNode) in order with back_end_thread. Declared last: destroyed
  // (joined) before the state it works on.
  std::unique_ptr<Worker> back_end = state.opt.back_end_thread ? std::make_unique<Worker>(kMaxQueuedNodes) : nullptr;

  /// Waits until the back end has worked through every node added and merges its events.
  /// Everything it touches (nodes, submaps, constraints, its counters) is the caller's afterwards.
  void sync() {
    if (back_end) back_end->wait();
    for (Event& e : state.back_end_events) state.events.push_back(std::move(e));
    state.back_end_events.clear();
  }

  /// Makes state.T_world_local and the back end's counters visible to the caller's thread (field by
  /// field: the front end's counters in the same struct are being written meanwhile).
  void publish() {
    const SlamStats& s = state.stats;
    std::lock_guard lock(published_mutex);
    published_T_world_local = state.T_world_local;
    SlamStats& p = published_stats;
    p.nodes = state.nodes.size();
    p.submaps = state.submaps.size();
    p.fragments = s.fragments;
    p.relocalizations = s.relocalizations;
    p.odometry_wins = s.odometry_wins;
    p.loop_searches = s.loop_searches;
    p.loop_accepted = s.loop_accepted;
    p.loop_rejected = s.loop_rejected;
    p.loop_downweighted = s.loop_downweighted;
    p.descriptor_queries = s.descriptor_queries;
    p.descriptor_hypotheses = s.descriptor_hypotheses;
    p.descriptor_accepted = s.descriptor_accepted;
    p.descriptor_seconds = s.descriptor_seconds;
    p.optimizations = s.optimizations;
    p.optimization_seconds = s.optimization_seconds;
  }

  /// The back end's work for the new node `n`: finishes and indexes the submap when `finish`,
  /// searches loop closures (by proximity, then by descriptors) and optimises when due. Reads
  /// only what the front end no longer changes (nodes, their points and lines, submaps), and
  /// records events in back_end_events, so it may run while the next scans are tracked; the next
  /// node waits for it, so the run is the same as with no thread.
  void backEnd(std::size_t n, bool finish) {
    if (finish) finishSubmap(state.submaps[state.nodes[n].submap]);
    ++state.nodes_since_optimization;
    if (const auto covered = loops.searchNear(n)) descriptors.search(n, *covered);
    loops.searchUntied(n);
    internal::optimizeIfDue(state);
  }

  /// Freezes the submap `sm` and indexes its descriptors: during a run when it is full (or the
  /// track is lost), and on restoring a saved state.
  void finishSubmap(internal::Submap& sm) {
    loops.finishSubmap(sm);
    if (state.opt.descriptor_loops) descriptors.indexSubmap(sm);
  }

  /// What the pipeline keeps of the newest node's scan `f`: its points `pts` (robot frame,
  /// voxel-filtered), the scan itself, its trusted `odometry`, its path length and the lines of
  /// `raw` (its points in scan order). During a run and on restoring a saved state.
  void appendNodeData(const Frame& f, Points2 pts, const Points2& raw, std::optional<SE2> odometry, double path_m) {
    state.node_points.push_back(std::move(pts));
    state.node_scans.emplace_back(f.scan, f.T_robot_laser);
    state.node_odometry.push_back(odometry);
    state.node_frame_index.push_back(f.index);
    state.node_path_m.push_back(path_m);
    descriptors.describeNode(raw);
  }

  /// Loads `saved` into the (empty) state: the saved records as they are; node points and lines,
  /// finished submaps' points, ICP targets and descriptor indexes rebuilt by the code that built them.
  void restore(State saved) {
    internal::SlamState& s = state;
    s.sessions = std::move(saved.sessions);
    std::size_t session = 0;
    for (std::size_t i = 0; i < saved.scans.size(); ++i) {
      while (session + 1 < s.sessions.size() && s.sessions[session + 1].first_scan <= i) ++session;
      s.scans.push_back({saved.scans[i], session});
    }
    for (State::NodeData& d : saved.nodes) {
      Frame f;
      f.index = d.frame_index;
      f.time = d.node.time;
      f.scan = std::move(d.scan);
      f.T_robot_laser = d.T_robot_laser;
      const Points2 raw = internal::scanPoints(f, s.opt.max_range_m);
      s.nodes.push_back(d.node);
      appendNodeData(f, internal::voxelFilter(raw, s.opt.scan_voxel_m), raw, d.T_odom_robot, d.path_m);
    }
    for (const State::Submap& x : saved.submaps) {
      internal::Submap& sm = s.submaps.emplace_back();
      sm.anchor = x.anchor;
      sm.nodes = x.nodes;
      sm.last_link_node = x.last_link_node;
      sm.last_link_T_anchor_node = x.last_link_T_anchor_node;
      if (x.finished) finishSubmap(sm);
    }
    s.constraints = std::move(saved.constraints);
    s.edges = std::move(saved.edges);
    s.restarts = std::move(saved.restarts);
    s.events = std::move(saved.events);
    s.T_world_local = saved.T_world_local;
    s.last_loop_node = saved.last_loop_node;
    s.untied_since = saved.untied_since;
    s.restart_odometry = saved.restart_odometry;
    s.nodes_since_optimization = saved.nodes_since_optimization;
    s.loops_since_optimization = saved.loops_since_optimization;
    s.stats = saved.stats;  // last: rebuilding counted descriptor time
    nodes_added = s.nodes.size();
    if (!s.nodes.empty()) {
      last_node_time = s.nodes.back().time;
      last_node_T_local = s.nodes.back().T_local_robot;
    }
    publish();
  }

  /// The state's records (State), without what restore rebuilds.
  State save() const {
    const internal::SlamState& s = state;
    State out;
    out.options = s.opt;
    out.sessions = s.sessions;
    out.scans.reserve(s.scans.size());
    for (const internal::ScanRecord& r : s.scans) out.scans.push_back(r);
    out.nodes.reserve(s.nodes.size());
    for (std::size_t n = 0; n < s.nodes.size(); ++n)
      out.nodes.push_back({s.nodes[n], s.node_scans[n].first, s.node_scans[n].second, s.node_odometry[n],
                           s.node_frame_index[n], s.node_path_m[n]});
    for (const internal::Submap& sm : s.submaps)
      out.submaps.push_back({sm.anchor, sm.nodes, sm.finished, sm.last_link_node, sm.last_link_T_anchor_node});
    out.constraints = s.constraints;
    out.edges = s.edges;
    out.restarts = s.restarts;
    out.events = s.events;
    out.stats = s.stats;
    out.stats.nodes = s.nodes.size();
    out.stats.submaps = s.submaps.size();
    out.T_world_local = s.T_world_local;
    out.last_loop_node = s.last_loop_node;
    out.untied_since = s.untied_since;
    out.restart_odometry = s.restart_odometry;
    out.nodes_since_optimization = s.nodes_since_optimization;
    out.loops_since_optimization = s.loops_since_optimization;
    return out;
  }

  void add(const Frame& frame) {
    const auto t0 = Clock::now();
    if (finished) throw invalidArgument("add() after finish()", {"Slam", 0, "add"});
    const SlamOptions& opt = state.opt;
    // The scan without its moving objects from here on: matched, kept with its node for the
    // submaps and loop closures (a saved state holds it so).
    Frame filtered;
    std::size_t moving = 0;
    if (opt.drop_moving_objects) moving = moving_objects.filter(frame, filtered);
    const Frame& f = moving > 0 ? filtered : frame;
    if (moving > 0) {
      state.stats.moving_points += moving;
      ++state.stats.moving_scans;
    }
    if (resumed_session) state.sessions.push_back({*std::exchange(resumed_session, std::nullopt), state.scans.size()});
    const Points2 raw = internal::scanPoints(f, opt.max_range_m);
    Points2 pts = internal::voxelFilter(raw, opt.scan_voxel_m);
    internal::ScanRecord rec;
    rec.frame_index = f.index;
    rec.time = f.time;
    rec.session = state.sessions.size() - 1;
    const std::size_t scan_index = state.scans.size();
    const internal::FrontEnd::Prediction prediction = front_end.predict(f);

    if (!front_end.started() && !state.nodes.empty()) {
      // The first scan of a session resuming a saved map: where it is is unknown. It starts like a
      // lost track with no odometry link (the odometry of two logs shares no frame): a new fragment,
      // predicted where the saved run ended (the front end's local frame continues the saved one),
      // tied to the map by the relocalization of lost tracks.
      const SE2 T0 = last_node_T_local;
      rec.node = nodes_added;
      rec.is_node = true;
      state.scans.push_back(rec);
      state.restart_odometry.reset();
      state.event(f, fmt::format("session {} ('{}') starts at node {}: its place in the saved map is unknown until "
                                 "a verified loop closure ties it",
                                 state.sessions.size(), state.sessions.back().name, rec.node));
      addNode(f, scan_index, T0, std::move(pts), raw, false, Eigen::Vector2d::Zero(), true, std::nullopt);
      front_end.remember(f, prediction, T0, true);
      last_T_local = T0;
    } else if (!front_end.started()) {
      // The first scan anchors everything.
      const SE2 T0 = front_end.firstPose(f);
      state.T_world_local = SE2();
      rec.node = 0;
      rec.is_node = true;
      rec.matched = true;
      state.scans.push_back(rec);
      addNode(f, scan_index, T0, std::move(pts), raw, false, Eigen::Vector2d::Zero(), false, prediction.T_odom_scaled);
      front_end.remember(f, prediction, T0, true);
      last_T_local = T0;
    } else {
      const internal::FrontEnd::Tracked t = front_end.track(f, pts, prediction);
      rec.matched = t.matched();
      rec.degenerate = t.degenerate;
      // Motion filter: a scan that moved or turned enough since the last node, or after long
      // enough, becomes a node; the others hang off the last node.
      const SE2 rel = last_node_T_local.inverse() * t.T_local_robot;
      const bool moved = rel.translation().norm() >= opt.node_min_translation_m ||
                         std::abs(rel.theta()) >= opt.node_min_rotation_rad ||
                         f.time - last_node_time >= opt.node_max_interval_s;
      if (t.restart || (t.placement && moved && pts.size() >= opt.min_points)) {
        if (t.restart) rehangLostScans(t.lost_before, t.T_local_robot);
        rec.node = nodes_added;
        rec.is_node = true;
        state.scans.push_back(rec);
        addNode(f, scan_index, t.T_local_robot, std::move(pts), raw, t.degenerate, t.dir, t.restart,
                prediction.source == internal::PriorSource::kOdometry ? prediction.T_odom_scaled : std::nullopt,
                t.placement.value_or(internal::Placement::kMatched),  // a restart's link: `restart`
                {prediction.sigma_m, prediction.sigma_rad});
      } else {
        rec.node = nodes_added - 1;
        rec.T_node_scan = rel;
        state.scans.push_back(rec);
      }
      front_end.remember(f, prediction, t.T_local_robot, false, t.matched() && !t.degenerate);
      last_T_local = t.T_local_robot;
    }
    ++state.stats.scans;
    state.scans.back().seconds = secondsSince(t0);
    state.stats.total_seconds += state.scans.back().seconds;
  }

  /// The `count` scans a lost track left at the prediction just before its restart (at
  /// `T_local_restart`, about to become node `nodes_added`) hang off the restart's node instead of
  /// the node before them, at the same place in the local frame (the odometry's steps between them
  /// and the restart). None of them matched the map before the restart: after a kidnapping they were
  /// taken where the new fragment is, and the restart's fragment is what the relocalization places
  /// (the node before them lies where the robot had been). Without a kidnapping the odometry across
  /// the lost track links both nodes the same way.
  void rehangLostScans(std::size_t count, const SE2& T_local_restart) {
    const SE2 T_restart_local = T_local_restart.inverse();
    for (auto it = state.scans.rbegin(); count > 0 && it != state.scans.rend(); ++it, --count) {
      if (it->is_node || it->matched) break;  // (never: the front end's failures are neither)
      const SE2 T_local_scan = last_node_T_local * it->T_node_scan;
      it->node = nodes_added;
      it->T_node_scan = T_restart_local * T_local_scan;
    }
  }

  /// Scan `scan_index` (frame `f`, at `T_local`, with its points `pts` and `raw`, and its trusted
  /// `odometry` pose on the scaled chain, MotionPrediction::T_odom_scaled) becomes a node:
  /// the front end's local map takes it at once, the graph work (graphNode) is queued for the back
  /// end. The front end never reads what the back end computes, so the back end may be several
  /// nodes behind and the run is the same as without its thread.
  void addNode(const Frame& f, std::size_t scan_index, const SE2& T_local, Points2 pts, const Points2& raw,
               bool degenerate, const Eigen::Vector2d& dir_local, bool restart, std::optional<SE2> odometry,
               internal::Placement placement = internal::Placement::kMatched, internal::StepSigmas prior = {}) {
    ++nodes_added;
    last_node_time = f.time;
    last_node_T_local = T_local;
    front_end.addNode(T_local, pts, restart);
    auto work = [this, f, scan_index, T_local, pts = std::move(pts), raw, degenerate, dir_local, restart, odometry,
                 placement, prior]() mutable {
      graphNode(f, scan_index, T_local, std::move(pts), raw, degenerate, dir_local, restart, odometry, placement,
                prior);
      publish();
    };
    if (back_end)
      back_end->start(std::move(work));
    else
      work();
  }

  /// The graph's part of a new node: the node, its submap, its data, its sequential constraints,
  /// then the back end's searches and optimisation (backEnd).
  void graphNode(const Frame& f, std::size_t scan_index, const SE2& T_local, Points2 pts, const Points2& raw,
                 bool degenerate, const Eigen::Vector2d& dir_local, bool restart, const std::optional<SE2>& odometry,
                 internal::Placement placement, internal::StepSigmas prior) {
    const SlamOptions& opt = state.opt;
    const std::size_t n = state.nodes.size();
    Node node;
    node.scan = scan_index;
    node.time = f.time;
    node.T_local_robot = T_local;
    node.T_world_robot = state.T_world_local * T_local;
    node.degenerate = degenerate;
    if (degenerate) {
      const Eigen::Vector2d d = T_local.rotation().transpose() * dir_local;
      node.degenerate_dir_rad = std::atan2(d.y(), d.x());
    }
    if (restart && !state.submaps.empty() && !state.submaps.back().finished) {
      // The nodes before a lost track and after it do not share a frame: one submap cannot hold both.
      finishSubmap(state.submaps.back());
    }
    if (state.submaps.empty() || state.submaps.back().finished) {
      state.submaps.emplace_back();
      state.submaps.back().anchor = n;
    }
    node.submap = state.submaps.size() - 1;
    state.submaps.back().nodes.push_back(n);
    state.nodes.push_back(node);
    appendNodeData(f, std::move(pts), raw, odometry,
                   n == 0 ? 0.0
                          : state.node_path_m[n - 1] +
                                (state.nodes[n - 1].T_local_robot.translation() - T_local.translation()).norm());
    if (restart) {
      state.restarts.push_back(n);
      state.untied_since = n;
    }
    if (n > 0) internal::addSequentialConstraints(state, n, restart, placement, degenerate, dir_local);
    // A scan the front end placed by the odometry, unmatched (never with `restart`): how
    // far the chain drifted there is less certain, so the nodes after it search for closures at
    // every node (as a lost track's fragment does), not every loop_search_every_nodes.
    if (placement != internal::Placement::kMatched)
      state.search_every_node_until = n + internal::SlamState::kSearchEveryNodeAfterPlaced;
    internal::propagatePlacedCovariance(state, n, restart, placement, prior);
    backEnd(n, static_cast<int>(state.submaps.back().nodes.size()) >= opt.submap_nodes);
  }
};

Slam::Slam(const SlamOptions& options, std::string session)
    : impl_(std::make_unique<Impl>(options, std::move(session))) {}
Slam::Slam(State saved, std::string session) : impl_(std::make_unique<Impl>(std::move(saved), std::move(session))) {}
Slam::~Slam() = default;

void Slam::add(const Frame& frame) { impl_->add(frame); }

void Slam::finish() {
  if (impl_->finished) return;
  const auto t0 = Clock::now();
  impl_->sync();
  internal::SlamState& s = impl_->state;
  // The back end's events were merged a node late: in frame order again.
  std::stable_sort(s.events.begin(), s.events.end(),
                   [](const Event& a, const Event& b) { return a.frame_index < b.frame_index; });
  impl_->loops.confirmPendingAtEnd();
  impl_->loops.expirePending();
  internal::calibrateFromCycles(s);
  internal::optimize(s, s.opt.graph.max_iterations);
  // A resumed map carries the fragment verdicts of the run that saved it; the new session may have
  // tied those fragments: checkAtEnd states them again for the whole graph.
  std::erase_if(s.events, [](const Event& e) { return e.what.starts_with(internal::kFragmentEvent); });
  internal::checkAtEnd(s);
  internal::reportDownweighted(s);
  impl_->finished = true;
  s.stats.nodes = s.nodes.size();
  s.stats.submaps = s.submaps.size();
  s.stats.total_seconds += secondsSince(t0);
}

namespace {
/// Scan `r`'s estimate, at `T_world_robot`.
ScanEstimate estimateOf(const internal::ScanRecord& r, const SE2& T_world_robot) {
  ScanEstimate e;
  e.frame_index = r.frame_index;
  e.time = r.time;
  e.node = r.node;
  e.session = r.session;
  e.is_node = r.is_node;
  e.matched = r.matched;
  e.degenerate = r.degenerate;
  e.seconds = r.seconds;
  e.T_world_robot = T_world_robot;
  return e;
}
}  // namespace

std::vector<ScanEstimate> Slam::trajectory() const {
  impl_->sync();
  const internal::SlamState& s = impl_->state;
  std::vector<ScanEstimate> out;
  out.reserve(s.scans.size());
  for (const internal::ScanRecord& r : s.scans) out.push_back(estimateOf(r, s.nodes[r.node].T_world_robot * r.T_node_scan));
  return out;
}

ScanEstimate Slam::latest() const {
  const internal::SlamState& s = impl_->state;
  if (s.scans.empty()) throw invalidArgument("no scan added yet", {"Slam", 0, "latest"});
  // Without waiting for the back end: the front-end pose of the scan (never changed once set) in
  // the world frame as of the back end's last finished work (the newest node's world pose is
  // derived the same way).
  std::lock_guard lock(impl_->published_mutex);
  return estimateOf(s.scans.back(), impl_->published_T_world_local * impl_->last_T_local);
}

const std::vector<Node>& Slam::nodes() const {
  impl_->sync();
  return impl_->state.nodes;
}
const std::vector<Constraint>& Slam::constraints() const {
  impl_->sync();
  return impl_->state.constraints;
}
const std::vector<Event>& Slam::events() const {
  impl_->sync();
  return impl_->state.events;
}
const SlamStats& Slam::stats() const {
  impl_->sync();
  internal::SlamState& s = impl_->state;
  s.stats.nodes = s.nodes.size();
  s.stats.submaps = s.submaps.size();
  return s.stats;
}
SlamStats Slam::statsSoFar() const {
  const internal::SlamState& s = impl_->state;
  std::lock_guard lock(impl_->published_mutex);
  SlamStats out = impl_->published_stats;
  // The front end's counters are the caller's own; the back end's as it last published them.
  out.scans = s.stats.scans;
  out.matched = s.stats.matched;
  out.unmatched = s.stats.unmatched;
  out.degenerate = s.stats.degenerate;
  out.correlative_fallbacks = s.stats.correlative_fallbacks;
  out.prior_overridden = s.stats.prior_overridden;
  out.prior_kept = s.stats.prior_kept;
  out.odometry_scale = s.stats.odometry_scale;
  out.odometry_scale_evidence_m = s.stats.odometry_scale_evidence_m;
  out.total_seconds = s.stats.total_seconds;
  out.nodes = std::max(out.nodes, impl_->nodes_added);
  return out;
}

const SlamOptions& Slam::options() const { return impl_->state.opt; }

State Slam::state() const {
  impl_->sync();
  return impl_->save();
}

}  // namespace lidar2d::slam
