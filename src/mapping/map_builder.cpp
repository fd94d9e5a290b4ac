#include "lidar2d/mapping/map_builder.hpp"

#include <fmt/format.h>

#include <cmath>
#include <mutex>
#include <utility>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/read_ahead.hpp"

namespace lidar2d::mapping {

FramePoses FramePoses::fromFrames(PoseSource source, std::string hint) {
  FramePoses p;
  p.source_ = source;
  p.hint_ = std::move(hint);
  return p;
}

FramePoses FramePoses::fromTrajectory(Trajectory trajectory, double max_dt_s, std::string name) {
  FramePoses p;
  auto traj = std::make_shared<const Trajectory>(std::move(trajectory));
  p.index_ = std::make_shared<const TimeIndex>(*traj);
  p.trajectory_ = std::move(traj);
  p.max_dt_s_ = max_dt_s;
  p.name_ = std::move(name);
  return p;
}

SE2 FramePoses::T_world_robot(const Frame& f) const {
  if (trajectory_) {
    const Trajectory& traj = *trajectory_;
    if (f.index < traj.size() && std::abs(traj[f.index].time - f.time) <= max_dt_s_) return traj[f.index].pose;
    if (auto i = index_->nearest(f.time, max_dt_s_)) return traj[*i].pose;
    throw badInput(fmt::format("has no pose within {} s of scan {} (time {:.6f})", max_dt_s_, f.index, f.time),
                   ErrorLocation(name_, 0, "timestamp"));
  }
  const bool use_truth = source_ == PoseSource::kTruth || (source_ == PoseSource::kAuto && f.T_world_robot);
  const std::optional<SE2>& pose = use_truth ? f.T_world_robot : f.T_odom_robot;
  if (!pose)
    throw badInput(fmt::format("scan {} (time {:.6f}) has no {} pose{}", f.index, f.time,
                               use_truth ? "truth" : "odometry", hint_.empty() ? std::string() : " (" + hint_ + ")"));
  return *pose;
}

MapBuilder::MapBuilder(OccupancyMap& map, FramePoses poses, MapBuilderOptions options)
    : map_(map), poses_(std::move(poses)), options_(std::move(options)) {}

MapBuilder::~MapBuilder() = default;

std::size_t MapBuilder::insert(const FrameStream& frames, const Progress& progress) {
  using Prepared = OccupancyMap::PreparedScan;
  const std::string& source = options_.source_name;
  // A scan the map rejects is named in the error.
  auto atScan = [&source](const Error& e, std::size_t index, double time) {
    return Error(e.kind(), e.message(),
                 ErrorLocation(source, 0, fmt::format("scan {} (time {:.6f}) {}", index, time, e.where().field)));
  };
  struct Item {
    std::unique_ptr<Prepared> prepared;
    std::size_t index = 0;
    double time = 0.0;
  };
  // Inserted scans' PreparedScans go back to the preparing thread, which prepares into them again.
  std::mutex spare_mutex;
  auto takeSpare = [&] {
    std::lock_guard lock(spare_mutex);
    if (spare_.empty()) return std::make_unique<Prepared>();
    std::unique_ptr<Prepared> p = std::move(spare_.back());
    spare_.pop_back();
    return p;
  };
  // On the second thread: reading a scan, finding its pose and preparing it read no map state.
  auto produce = [&]() -> std::optional<Item> {
    const std::optional<Frame> f = frames();
    if (!f) return std::nullopt;
    SE2 T_world_robot;
    try {
      T_world_robot = poses_.T_world_robot(*f);
    } catch (const Error& e) {
      if (!e.where().file.empty()) throw;
      throw Error(e.kind(), e.message(), ErrorLocation(source, e.where().line, e.where().field));
    }
    Item item{takeSpare(), f->index, f->time};
    try {
      map_.prepare(f->scan, T_world_robot * f->T_robot_laser, *item.prepared);
    } catch (const Error& e) {
      throw atScan(e, f->index, f->time);
    }
    return item;
  };
  std::size_t scans = 0;
  ReadAhead<Item> ahead(produce, options_.read_ahead);  // (stops and joins its thread on an exception here)
  while (std::optional<Item> item = ahead.next()) {
    try {
      map_.insert(*item->prepared);
    } catch (const Error& e) {
      throw atScan(e, item->index, item->time);
    }
    {
      std::lock_guard lock(spare_mutex);
      spare_.push_back(std::move(item->prepared));
    }
    ++scans;
    if (progress) progress(scans);
  }
  return scans;
}

}  // namespace lidar2d::mapping
