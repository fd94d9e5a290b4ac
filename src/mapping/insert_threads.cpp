// Two-thread insertion (InsertOptions::threads). The scan's cells are split by a line on a tile
// border (so each tile, and each cell, belongs to one thread and lazy tile allocation cannot race);
// each thread runs the model's insertion restricted to its side. A cell's updates thus happen on
// one thread and in the single-threaded order (hits phase, then beams in order), so the map is
// bit-identical.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <exception>
#include <limits>
#include <system_error>
#include <thread>
#include <utility>

#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/mapping/ray_trace.hpp"

namespace lidar2d::mapping {

namespace {

void cpuRelax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

// Waits until `a` differs from `old`: busy for up to `spin` first (the other side is normally only
// microseconds away) - pausing for the first microseconds, then yielding the core so that a thread
// it is shared with (the other half of the scan, the log reader) runs - and then sleeps in the
// kernel (futex), so an idle worker costs no CPU.
std::uint32_t waitChange(const std::atomic<std::uint32_t>& a, std::uint32_t old, std::chrono::microseconds spin) {
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0;; ++i) {
    const std::uint32_t v = a.load(std::memory_order_acquire);
    if (v != old) return v;
    if ((i & 15) == 15) {
      const auto waited = std::chrono::steady_clock::now() - t0;
      if (waited > spin) break;
      if (waited > std::chrono::microseconds(2)) std::this_thread::yield();
    }
    cpuRelax();
  }
  for (;;) {
    a.wait(old, std::memory_order_acquire);
    const std::uint32_t v = a.load(std::memory_order_acquire);
    if (v != old) return v;
  }
}

// Handshake spin times: long enough to cover the gap between consecutive scans when the log reader
// keeps up, short enough not to starve it.
constexpr std::chrono::microseconds kWorkerSpin{50};
constexpr std::chrono::microseconds kCallerSpin{200};

}  // namespace

struct OccupancyMap::Worker {
  explicit Worker(OccupancyMap* map) : thread([this, map] { run(map); }) {}
  ~Worker() {
    stop = true;
    job.fetch_add(1, std::memory_order_release);
    job.notify_one();
    thread.join();
  }
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  void run(OccupancyMap* map) {
    std::uint32_t seen = 0;
    for (;;) {
      seen = waitChange(job, seen, kWorkerSpin);
      if (stop) return;
      try {
        updates = map->insertBeams(*origin, map->beams_, slab, 1);
      } catch (...) {
        error = std::current_exception();
      }
      done.store(seen, std::memory_order_release);
      done.notify_one();
    }
  }
  // Runs the worker's part of a scan; returns the job number to pass to `wait`.
  std::uint32_t start(const Eigen::Vector2d& o, const Slab& s) {
    origin = &o;
    slab = s;
    updates = 0;
    error = nullptr;
    const std::uint32_t n = job.fetch_add(1, std::memory_order_release) + 1;
    job.notify_one();
    return n;
  }
  void wait(std::uint32_t n) {
    std::uint32_t d = done.load(std::memory_order_acquire);
    while (d != n) d = waitChange(done, d, kCallerSpin);
  }

  // The job, written by the caller before `job` is bumped, read by the worker after.
  const Eigen::Vector2d* origin = nullptr;
  Slab slab;
  bool stop = false;
  // The result, written by the worker before `done` is set.
  std::uint64_t updates = 0;
  std::exception_ptr error;
  alignas(64) std::atomic<std::uint32_t> job{0};  // number of the last job posted (own cache line:
  alignas(64) std::atomic<std::uint32_t> done{0};  // number of the last job finished  each side spins on one)
  std::thread thread;                  // last member: starts once the others exist
};

// (The constructor and destructor are defined here, where the worker's type is complete.)
OccupancyMap::OccupancyMap(const MapOptions& options) : options_(options), geometry_(options.resolution_m) {}

OccupancyMap::~OccupancyMap() = default;

std::optional<std::pair<OccupancyMap::Slab, OccupancyMap::Slab>> OccupancyMap::chooseSplit(const Eigen::Vector2d& origin,
                                                                                             const CellBox& box) {
  // The work is estimated as if every walk started at the laser (log-odds and count start most of
  // them farther out, see `prepare`: the near part's share is overestimated).
  // Below this much work (cells traversed) the handshake (a few microseconds) does not pay.
  constexpr double kMinWork = 3000;
  // Walking a far part's cells before the split line without touching them costs about this
  // fraction of visiting a cell.
  constexpr double kSkipCost = 0.25;
  // Split only when the smaller part has at least this share of the work.
  constexpr double kMinShare = 0.2;
  constexpr int kBits = TiledGrid<int>::kTileBits;
  double total = 0;
  for (const Beam& b : beams_) total += std::abs(b.end.x() - origin.x()) + std::abs(b.end.y() - origin.y());
  if (total < kMinWork) return std::nullopt;
  // For a line at coordinate X on axis a, a beam ending beyond it has the share |end - X| / |end -
  // origin| of its cells beyond. Per tile column (row) of the beam ends, sums of w/|d| and
  // w/|d| * end give the far work at every tile border in one sweep.
  double best_cost = total;
  Slab best_near, best_far;
  for (int axis = 0; axis < 2; ++axis) {
    const double o = origin[axis];
    const std::int32_t lo_tile = (axis == 0 ? box.min.x : box.min.y) >> kBits;
    const std::int32_t hi_tile = (axis == 0 ? box.max.x : box.max.y) >> kBits;
    const std::int32_t o_tile = floorToInt32(o) >> kBits;
    const auto n = static_cast<std::size_t>(hi_tile - lo_tile + 1);
    split_sums_.assign(2 * n, 0.0);
    for (const Beam& b : beams_) {
      const double d = std::abs(b.end[axis] - o);
      if (d == 0) continue;
      const double a = (std::abs(b.end.x() - origin.x()) + std::abs(b.end.y() - origin.y())) / d;
      const auto k = static_cast<std::size_t>((floorToInt32(b.end[axis]) >> kBits) - lo_tile);
      split_sums_[2 * k] += a;
      split_sums_[2 * k + 1] += a * b.end[axis];
    }
    auto consider = [&](std::int32_t tile, double s0, double s1, bool upper) {
      const double X = static_cast<double>(tile) * (1 << kBits);
      const double far = (upper ? s1 - X * s0 : X * s0 - s1) + kSkipCost * std::abs(X - o) * s0;
      const double cost = std::max(far, total - far);
      if (cost >= best_cost) return;
      best_cost = cost;
      const std::int32_t line = tile * (1 << kBits);
      constexpr std::int32_t kMin = std::numeric_limits<std::int32_t>::min(), kMax = std::numeric_limits<std::int32_t>::max();
      best_far = upper ? Slab{axis, line, kMax} : Slab{axis, kMin, line};
      best_near = upper ? Slab{axis, kMin, line} : Slab{axis, line, kMax};
    };
    // Lines above the origin's cell: the far side is tiles >= t.
    double s0 = 0, s1 = 0;
    for (std::int32_t t = hi_tile; t > o_tile; --t) {
      s0 += split_sums_[2 * static_cast<std::size_t>(t - lo_tile)];
      s1 += split_sums_[2 * static_cast<std::size_t>(t - lo_tile) + 1];
      consider(t, s0, s1, true);
    }
    // Lines at or below the origin's cell: the far side is tiles < t.
    s0 = s1 = 0;
    for (std::int32_t t = lo_tile + 1; t <= o_tile; ++t) {
      s0 += split_sums_[2 * static_cast<std::size_t>(t - 1 - lo_tile)];
      s1 += split_sums_[2 * static_cast<std::size_t>(t - 1 - lo_tile) + 1];
      consider(t, s0, s1, false);
    }
  }
  if (best_cost > (1 - kMinShare) * total) return std::nullopt;
  return std::make_pair(best_near, best_far);
}

std::uint64_t OccupancyMap::insertParallel(const Eigen::Vector2d& origin, const Slab& mine, const Slab& theirs) {
  if (!worker_) {
    try {
      worker_ = std::make_unique<Worker>(this);
    } catch (const std::system_error&) {  // no thread to be had: stay single-threaded
      return insertBeams(origin, beams_, Slab{}, 0);
    }
  }
  ++parallel_scans_;
  const auto t0 = std::chrono::steady_clock::now();
  const std::uint32_t job = worker_->start(origin, theirs);
  std::uint64_t updates = 0;
  std::exception_ptr error;
  try {
    updates = insertBeams(origin, beams_, mine, 0);
  } catch (...) {
    error = std::current_exception();
  }
  const auto t1 = std::chrono::steady_clock::now();
  worker_->wait(job);  // always: the worker reads beams_
  // When the cores are busy with other work the worker may get its time slice late and the scan
  // takes longer than on one thread (waiting longer than the own part took). Then insert the next
  // scans on one thread, doubling the pause while it keeps happening.
  if (options_.insert.adaptive_threads && std::chrono::steady_clock::now() - t1 > t1 - t0) {
    backoff_ = std::min<std::uint32_t>(std::max<std::uint32_t>(2 * backoff_, 8), 1024);
    single_left_ = backoff_;
  } else {
    backoff_ /= 2;
  }
  if (error) std::rethrow_exception(error);
  if (worker_->error) std::rethrow_exception(std::exchange(worker_->error, nullptr));
  return updates + worker_->updates;
}

}  // namespace lidar2d::mapping
