#include "src/io/internal/ros_frames.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/readers.hpp"

namespace lidar2d::io::internal {

namespace {

std::string listTopics(const std::vector<const RosTopicInfo*>& topics) {
  if (topics.empty()) return "none";
  std::string out;
  for (const auto* t : topics) {
    if (!out.empty()) out += ", ";
    out += fmt::format("{} ({} messages)", t->name, t->count);
  }
  return out;
}

}  // namespace

std::optional<RosTopicInfo> chooseRosTopic(const std::vector<RosTopicInfo>& topics,
                                           const std::vector<std::string>& types, const std::string& requested,
                                           bool allow_none, const std::string& what, const std::string& option,
                                           const std::string& path, std::vector<std::string>& warnings) {
  std::vector<const RosTopicInfo*> candidates;
  for (const auto& t : topics)
    if (std::find(types.begin(), types.end(), t.type) != types.end()) candidates.push_back(&t);
  // Most messages first; stable, so ties keep the bag's order.
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const RosTopicInfo* a, const RosTopicInfo* b) { return a->count > b->count; });
  if (allow_none && requested == "none") return std::nullopt;
  if (!requested.empty()) {
    for (const auto* c : candidates)
      if (c->name == requested) return *c;
    std::string other;
    for (const auto& t : topics)
      if (t.name == requested) other = fmt::format(" (it has type {})", t.type);
    const std::string msg = other.empty() ? fmt::format("no {} topic named '{}'", what, requested)
                                          : fmt::format("topic '{}' is not a {} topic{}", requested, what, other);
    throw badInput(fmt::format("{}; {} topics: {}", msg, what, listTopics(candidates)), {path, 0, option});
  }
  if (candidates.empty()) return std::nullopt;
  if (candidates.size() > 1)
    warnings.push_back(fmt::format("several {} topics: {}; reading {}, the one with the most messages (choose with {})",
                                   what, listTopics(candidates), candidates.front()->name, option));
  return *candidates.front();
}

SE2 projectToPlane(const RosTransform3& t) {
  // Yaw of the ZYX (yaw-pitch-roll) decomposition of the unit quaternion.
  const double yaw = std::atan2(2.0 * (t.qw * t.qz + t.qx * t.qy), 1.0 - 2.0 * (t.qy * t.qy + t.qz * t.qz));
  return SE2(t.tx, t.ty, yaw);
}

void RosTfTree::add(const RosTransformStamped& t) {
  if (t.child.empty() || t.parent.empty() || t.child == t.parent) return;
  parent_of_[t.child] = Edge{t.parent, t.transform};
}

bool RosTfTree::hasFrame(const std::string& frame) const {
  if (parent_of_.count(frame)) return true;
  return std::any_of(parent_of_.begin(), parent_of_.end(), [&](const auto& kv) { return kv.second.parent == frame; });
}

Eigen::Isometry3d RosTfTree::checked(const std::string& child, const Edge& e) const {
  const RosTransform3& t = e.T_parent_child;
  const Eigen::Quaterniond q(t.qw, t.qx, t.qy, t.qz);
  const Eigen::Vector3d p(t.tx, t.ty, t.tz);
  const ErrorLocation where(file_, 0, fmt::format("tf {} -> {}", e.parent, child));
  if (!p.allFinite() || !q.coeffs().allFinite()) throw badInput("transform has a non-finite value", where);
  // tf2 (BufferCore::setTransform) refuses quaternions whose squared norm is off by more than 0.01.
  if (std::abs(q.squaredNorm() - 1.0) > 0.01)
    throw badInput(fmt::format("rotation quaternion ({:g}, {:g}, {:g}, {:g}) is not of unit length", t.qx, t.qy, t.qz,
                               t.qw),
                   where);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = p;
  return T;
}

std::optional<RosTfTree::Lookup> RosTfTree::lookup(const std::string& from, const std::string& to) const {
  struct Up {
    std::string frame;
    const Edge* edge;  // to the parent; nullptr at the root
  };
  // Ancestors of a frame, itself first; stops at the root or on a cycle.
  auto climb = [this](const std::string& start) {
    std::vector<Up> ups{{start, nullptr}};
    std::set<std::string> seen{start};
    for (;;) {
      const auto it = parent_of_.find(ups.back().frame);
      if (it == parent_of_.end() || seen.count(it->second.parent)) break;
      ups.back().edge = &it->second;
      ups.push_back({it->second.parent, nullptr});
      seen.insert(it->second.parent);
    }
    return ups;
  };
  // The start frame of `ups` in its k-th ancestor, composed in 3D.
  auto inAncestor = [this](const std::vector<Up>& ups, std::size_t k) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    for (std::size_t m = 0; m < k; ++m) T = checked(ups[m].frame, *ups[m].edge) * T;
    return T;
  };
  const auto from_up = climb(from);
  const auto to_up = climb(to);
  for (std::size_t j = 0; j < to_up.size(); ++j) {
    for (std::size_t i = 0; i < from_up.size(); ++i) {
      if (from_up[i].frame != to_up[j].frame) continue;
      Lookup l;
      // T_from_to = T_anc_from^-1 * T_anc_to
      l.T_from_to = inAncestor(from_up, i).inverse() * inAncestor(to_up, j);
      for (std::size_t k = 0; k <= i; ++k) l.chain.push_back(from_up[k].frame);
      for (std::size_t k = j; k-- > 0;) l.chain.push_back(to_up[k].frame);
      return l;
    }
  }
  return std::nullopt;
}

RosMount findRosMount(const RosTfTree& tree, const std::vector<std::string>& robot_frames,
                      const std::string& laser_frame) {
  RosMount m;
  if (laser_frame.empty()) return m;
  for (const auto& robot : robot_frames) {
    if (robot.empty()) continue;
    if (robot == laser_frame) {
      m.found = true;
      m.robot_frame = robot;
      m.description = fmt::format("the scans' frame {} is the robot frame", laser_frame);
      return m;
    }
    if (const auto l = tree.lookup(robot, laser_frame)) {
      m.found = true;
      m.robot_frame = robot;
      // Normalized by `lookup`'s checks; composing keeps it a rotation to rounding.
      m.mount = LaserMount::fromTransform(l->T_from_to.translation(), Eigen::Quaterniond(l->T_from_to.rotation()));
      for (const auto& f : l->chain) {
        if (!m.description.empty()) m.description += " -> ";
        m.description += f;
      }
      return m;
    }
  }
  return m;
}

LaserMount rosFrameMount(const RosMount& mount, const ReaderOptions& options, const std::string& path,
                         std::vector<std::string>& warnings) {
  if (!options.laser_mount && !mount.found && options.require_laser_mount)
  {
    std::string why = warnings.empty() ? std::string("no laser mounting in tf") : warnings.back();
    if (const auto k = why.find(": laser mounting unknown"); k != std::string::npos) why.resize(k);
    throw badInput(fmt::format("{}; merging lasers needs each one's mounting: give --laser-mount once per laser", why),
                   {path, 0, "tf"});
  }
  if (options.laser_mount || !mount.found) return LaserMount();
  return applyTiltRule(mount.mount, options, {path, 0, "tf " + mount.description}, mount.description, warnings);
}

void noteRosMount(RosMount& mount, const std::string& source, const std::vector<std::string>& robot_frames,
                  const std::string& laser_frame, std::vector<std::string>& warnings) {
  if (mount.found) {
    if (mount.description.find("->") != std::string::npos) mount.description += fmt::format(" from {}", source);
    if (mount.mount.upsideDown()) mount.description += ", upside down";
    return;
  }
  std::string robots;
  for (const auto& r : robot_frames) robots += fmt::format("{}'{}'", robots.empty() ? "" : " or ", r);
  warnings.push_back(laser_frame.empty()
                         ? std::string("the scans have no frame_id: laser mounting unknown, identity used")
                         : fmt::format("no transform from {} to the scans' frame '{}' in /tf_static or /tf: laser "
                                       "mounting unknown, identity used",
                                       robots, laser_frame));
}

LaserScan toLaserScan(const RosLaserScanMsg& m, double time, const RosMessageRef& ref, std::size_t& negative_ranges) {
  LaserScanFields f;
  f.time = time;
  f.angle_min = m.angle_min;
  f.angle_increment = m.angle_increment;
  f.range_min = m.range_min;
  f.range_max = m.range_max;
  f.ranges.assign(m.ranges.begin(), m.ranges.end());
  for (const float r : m.ranges)
    if (std::isfinite(r) && r < 0.0f) ++negative_ranges;
  f.intensities.assign(m.intensities.begin(), m.intensities.end());
  try {
    return LaserScan::create(std::move(f));
  } catch (const Error& e) {
    throw Error(e.kind(), fmt::format("{}: {}", ref.message, e.message()),
                {ref.file, 0, fmt::format("LaserScan.{}", e.where().field)});
  }
}

RosFrameAssembler::RosFrameAssembler(LaserMount mount, bool use_odometry)
    : mount_(std::move(mount)), use_odometry_(use_odometry) {}

void RosFrameAssembler::pushScan(LaserScan scan, double time) { pending_.push_back({std::move(scan), time}); }

void RosFrameAssembler::pushOdometry(double time, const SE2& T_odom_robot) {
  if (!use_odometry_) return;
  if (odom_.empty() || time >= odom_.back().time) {
    odom_.push_back({time, T_odom_robot});
  } else {
    ++odom_out_of_order_;
    const auto it = std::upper_bound(odom_.begin(), odom_.end(), time,
                                     [](double t, const Odom& o) { return t < o.time; });
    odom_.insert(it, {time, T_odom_robot});
  }
  newest_odom_time_ = std::max(newest_odom_time_, time);
  prune();
}

std::optional<Frame> RosFrameAssembler::pop() {
  if (pending_.empty()) return std::nullopt;
  const double t = pending_.front().time;
  const bool bracketed = !odom_.empty() && newest_odom_time_ >= t;
  const bool overflow = pending_.size() > kMaxPendingScans;
  if (!(finished_ || !use_odometry_ || bracketed || overflow)) return std::nullopt;
  if (use_odometry_ && !finished_ && !bracketed) ++forced_;
  Frame f;
  f.index = next_index_++;
  f.time = t;
  f.scan = std::move(pending_.front().scan);
  mountFrame(f, mount_);
  if (use_odometry_) f.T_odom_robot = interpolate(t);
  pending_.pop_front();
  prune();
  return f;
}

std::optional<SE2> RosFrameAssembler::interpolate(double t) {
  if (odom_.empty()) return std::nullopt;
  const auto it = std::lower_bound(odom_.begin(), odom_.end(), t, [](const Odom& o, double v) { return o.time < v; });
  double gap = 0.0;
  SE2 pose;
  if (it == odom_.begin()) {
    pose = it->pose;
    gap = it->time - t;
  } else if (it == odom_.end()) {
    pose = odom_.back().pose;
    gap = t - odom_.back().time;
  } else {
    const Odom& o1 = *it;
    const Odom& o0 = *(it - 1);
    if (o1.time == t) return o1.pose;
    const double a = (t - o0.time) / (o1.time - o0.time);
    const Eigen::Vector2d p = o0.pose.translation() + a * (o1.pose.translation() - o0.pose.translation());
    return SE2(p, o0.pose.theta() + a * angleDiff(o1.pose.theta(), o0.pose.theta()));
  }
  if (gap > kMaxOdomGapS) {
    ++gap_scans_;
    max_gap_ = std::max(max_gap_, gap);
  }
  return pose;
}

void RosFrameAssembler::prune() {
  // Keep the odometry that can still bracket a scan: everything from the last message at or
  // before (oldest waiting scan - 1 s); with no scan waiting, the last 10 s of odometry (the next
  // scan's stamp is near the newest odometry unless the clocks disagree).
  const double t_ref = pending_.empty() ? newest_odom_time_ - 10.0 : pending_.front().time - 1.0;
  while (odom_.size() >= 2 && odom_[1].time <= t_ref) odom_.pop_front();
}

std::vector<std::string> RosFrameAssembler::warnings() const {
  std::vector<std::string> w;
  if (gap_scans_)
    w.push_back(fmt::format(
        "{} scans are more than {} s (up to {:.3f} s) before the first or after the last odometry message; "
        "they use that message's pose",
        gap_scans_, kMaxOdomGapS, max_gap_));
  if (odom_out_of_order_)
    w.push_back(fmt::format("{} odometry messages have a stamp earlier than a previous one (sorted by stamp)",
                            odom_out_of_order_));
  if (forced_)
    w.push_back(fmt::format("{} scans were completed before any later odometry message arrived (look-ahead limit "
                            "of {} scans)",
                            forced_, kMaxPendingScans));
  return w;
}

RosTopicChoice chooseScanAndOdometry(const std::vector<RosTopicInfo>& topics, const std::string& scan_type,
                                     const std::string& odom_type, const ReaderOptions& options,
                                     const std::string& path, std::vector<std::string>& warnings) {
  const auto scan =
      chooseRosTopic(topics, {scan_type}, options.scan_topic, false, "LaserScan", "--scan-topic", path, warnings);
  if (!scan) {
    std::string all;
    for (const auto& t : topics) all += fmt::format("{}{} ({})", all.empty() ? "" : ", ", t.name, t.type);
    throw badInput(fmt::format("no {} topic in the bag (topics: {})", scan_type, all.empty() ? "none" : all),
                   ErrorLocation(path));
  }
  return {*scan, chooseRosTopic(topics, {odom_type}, options.odom_topic, true, "Odometry", "--odom-topic", path, warnings)};
}

SourceNotes rosNotes(SourceNotes base, std::vector<std::string> assembler_warnings, std::size_t negative_ranges,
                     std::size_t zero_stamps) {
  for (auto& w : assembler_warnings) base.warnings.push_back(std::move(w));
  if (negative_ranges)
    base.warnings.push_back(fmt::format("{} negative ranges (treated as invalid beams)", negative_ranges));
  if (zero_stamps)
    base.warnings.push_back(fmt::format("{} messages have a zero header stamp; their bag time is used", zero_stamps));
  return base;
}

void describeRosSources(SourceNotes& notes, const std::string& scan_topic, const std::string& scan_type,
                        const std::string& laser_frame, const RosMount& mount, const std::string& odom_topic,
                        const std::string& odom_type, const std::string& robot_frame) {
  notes.scan_source = fmt::format("{} ({}, frame '{}'{})", scan_topic, scan_type, laser_frame,
                                  mount.found ? fmt::format(", mounting {}", mount.description) : std::string());
  if (!odom_topic.empty())
    notes.odom_source =
        fmt::format("{} ({} to '{}', interpolated at scan stamps)", odom_topic, odom_type, robot_frame);
}

std::optional<Frame> RosMessageSource::next() {
  for (;;) {
    if (auto f = assembler_.pop()) return f;
    if (done_) return std::nullopt;
    if (!feed()) {
      assembler_.finish();
      done_ = true;
    }
  }
}

SourceNotes RosMessageSource::notes() const {
  return rosNotes(notes_, assembler_.warnings(), negative_ranges_, zero_stamps_);
}

RosNanos RosMessageSource::stampOr(RosNanos stamp, RosNanos bag_time) {
  if (stamp != 0) return stamp;
  ++zero_stamps_;
  return bag_time;
}

void RosMessageSource::pushScan(std::span<const std::uint8_t> bytes, RosWire wire, const RosMessageRef& ref,
                                RosNanos bag_time) {
  const RosLaserScanMsg msg = decodeLaserScan(bytes, wire, ref);
  const double t = rosSeconds(stampOr(msg.stamp, bag_time));
  assembler_.pushScan(toLaserScan(msg, t, ref, negative_ranges_), t);
}

void RosMessageSource::pushOdometry(std::span<const std::uint8_t> bytes, RosWire wire, const RosMessageRef& ref,
                                    RosNanos bag_time) {
  const RosOdometryMsg msg = decodeOdometry(bytes, wire, ref);
  assembler_.pushOdometry(rosSeconds(stampOr(msg.stamp, bag_time)), projectToPlane(msg.pose));
}

}  // namespace lidar2d::io::internal
