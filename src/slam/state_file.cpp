#include "lidar2d/slam/state_file.hpp"

#include <fmt/format.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <type_traits>
#include <utility>
#include <variant>

#include "lidar2d/core/error.hpp"

#ifndef LIDAR2D_VERSION
#define LIDAR2D_VERSION "unknown"
#endif

namespace lidar2d::slam {

static_assert(std::endian::native == std::endian::little, "the state file format is little-endian");

namespace {

// A state file of a very long run holds a few hundred MB: beyond this a length field is corrupt.
constexpr std::uint64_t kMaxBytes = std::uint64_t{8} << 30;
// Deflate expands at most 1032-fold (a 258-byte match in 2 bits): a payload length beyond this many
// times the compressed length is corrupt, and is refused before it is allocated.
constexpr std::uint64_t kMaxInflation = 1032;
// Positions in the state (x and y of every pose, absolute or relative) lie within this of the
// origin [m]: 10,000 km, beyond a continent's map and an odometry frame's offset (UTM, ECEF); a
// coordinate beyond it is corrupt (and would overflow the grids SLAM and the map build from it).
constexpr double kMaxCoordinateM = 1e7;

enum class OptionType : std::uint8_t { kBool = 0, kInt = 1, kSize = 2, kDouble = 3 };

class Writer {
 public:
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    buf.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void size(std::size_t n) { put(static_cast<std::uint64_t>(n)); }
  void flag(bool b) { put(static_cast<std::uint8_t>(b ? 1 : 0)); }
  void str(std::string_view s) {
    size(s.size());
    buf.append(s.data(), s.size());
  }
  void pose(const SE2& T) {
    put(T.x());
    put(T.y());
    put(T.theta());
  }
  void optPose(const std::optional<SE2>& T) {
    flag(T.has_value());
    if (T) pose(*T);
  }
  void optSize(const std::optional<std::size_t>& n) {
    flag(n.has_value());
    if (n) size(*n);
  }
  std::string buf;
};

class Reader {
 public:
  Reader(std::string_view data, const std::string& source, const char* what)
      : data_(data), source_(source), what_(what) {}
  template <class T>
  T get(const char* field) {
    T v;
    if (pos_ + sizeof(T) > data_.size())
      throw badInput(fmt::format("truncated {} (ends inside '{}')", what_, field), ErrorLocation(source_, 0, field));
    std::memcpy(&v, data_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::size_t size(const char* field) {
    const auto n = get<std::uint64_t>(field);
    if (n > kMaxBytes) throw bad(fmt::format("'{}' is {}: the file is corrupt", field, n), field);
    return static_cast<std::size_t>(n);
  }
  /// A count of items of at least `item_bytes` each: no more than the bytes left can hold.
  std::size_t count(const char* field, std::size_t item_bytes) {
    const std::size_t n = size(field);
    if (n > (data_.size() - pos_) / std::max<std::size_t>(1, item_bytes))
      throw bad(fmt::format("'{}' is {}, more than the rest of the file holds", field, n), field);
    return n;
  }
  bool flag(const char* field) {
    const auto b = get<std::uint8_t>(field);
    if (b > 1) throw bad(fmt::format("'{}' is {}, expected 0 or 1", field, b), field);
    return b == 1;
  }
  double real(const char* field) {
    const double v = get<double>(field);
    if (!std::isfinite(v)) throw bad(fmt::format("'{}' is not finite", field), field);
    return v;
  }
  std::string str(const char* field) {
    const std::size_t n = count(field, 1);
    std::string s(data_.substr(pos_, n));
    pos_ += n;
    return s;
  }
  /// A pose: finite, its position within kMaxCoordinateM of the origin.
  SE2 pose(const char* field) {
    const double x = real(field), y = real(field), t = real(field);
    if (std::abs(x) > kMaxCoordinateM || std::abs(y) > kMaxCoordinateM)
      throw bad(
          fmt::format("'{}' is at ({:g}, {:g}) m, farther than {:g} m from the origin", field, x, y, kMaxCoordinateM),
          field);
    return SE2(x, y, t);
  }
  std::optional<SE2> optPose(const char* field) {
    if (!flag(field)) return std::nullopt;
    return pose(field);
  }
  /// An optional index below `limit`.
  std::optional<std::size_t> optIndex(const char* field, std::size_t limit) {
    if (!flag(field)) return std::nullopt;
    return index(field, limit);
  }
  /// An index below `limit`.
  std::size_t index(const char* field, std::size_t limit) {
    const std::size_t i = size(field);
    if (i >= limit) throw bad(fmt::format("'{}' is {}, out of range (< {})", field, i, limit), field);
    return i;
  }
  bool done() const { return pos_ == data_.size(); }
  std::size_t pos() const { return pos_; }
  Error bad(const std::string& message, const char* field) const {
    return badInput(fmt::format("{}: {}", what_, message), ErrorLocation(source_, 0, field));
  }

 private:
  std::string_view data_;
  const std::string& source_;
  const char* what_;
  std::size_t pos_ = 0;
};

// ---- options: by name, so a field renamed or added in a later version is reported, not misread ----

void putOptions(Writer& w, const SlamOptions& options) {
  SlamOptions o = options;  // the table's accessors take a mutable SlamOptions
  w.size(std::size(kSlamOptionTable));
  for (const SlamOption& row : kSlamOptionTable) {
    w.str(row.field);
    std::visit(
        [&](auto ref) {
          const auto v = ref(o);
          using V = std::decay_t<decltype(v)>;
          if constexpr (std::is_same_v<V, bool>) {
            w.put(OptionType::kBool);
            w.flag(v);
          } else if constexpr (std::is_same_v<V, int>) {
            w.put(OptionType::kInt);
            w.put(static_cast<std::int64_t>(v));
          } else if constexpr (std::is_same_v<V, std::size_t>) {
            w.put(OptionType::kSize);
            w.put(static_cast<std::uint64_t>(v));
          } else {
            w.put(OptionType::kDouble);
            w.put(v);
          }
        },
        row.ref);
  }
}

SlamOptions getOptions(Reader& r) {
  SlamOptions o;
  const std::size_t n = r.count("options", 10);
  for (std::size_t i = 0; i < n; ++i) {
    const std::string name = r.str("options.name");
    const SlamOption* row = nullptr;
    for (const SlamOption& x : kSlamOptionTable)
      if (x.field == name) row = &x;
    if (!row) throw r.bad(fmt::format("unknown SLAM option '{}'", name), "options");
    const auto type = r.get<OptionType>("options.type");
    std::visit(
        [&](auto ref) {
          auto& v = ref(o);
          using V = std::decay_t<decltype(v)>;
          const OptionType want = std::is_same_v<V, bool>          ? OptionType::kBool
                                  : std::is_same_v<V, int>         ? OptionType::kInt
                                  : std::is_same_v<V, std::size_t> ? OptionType::kSize
                                                                   : OptionType::kDouble;
          if (type != want) throw r.bad(fmt::format("option '{}' has the wrong type", name), "options");
          if constexpr (std::is_same_v<V, bool>) {
            v = r.flag("options.value");
          } else if constexpr (std::is_same_v<V, int>) {
            const auto x = r.get<std::int64_t>("options.value");
            if (x < std::numeric_limits<int>::min() || x > std::numeric_limits<int>::max())
              throw r.bad(fmt::format("option '{}' is out of range", name), "options");
            v = static_cast<int>(x);
          } else if constexpr (std::is_same_v<V, std::size_t>) {
            v = static_cast<std::size_t>(r.get<std::uint64_t>("options.value"));
          } else {
            v = r.get<double>("options.value");
          }
        },
        row->ref);
  }
  try {
    o.validate();
  } catch (const Error& e) {
    throw r.bad(fmt::format("invalid options: {}", e.what()), "options");
  }
  return o;
}

// ---- the parts of the state ----

void putScan(Writer& w, const LaserScan& s) {
  w.put(s.time());
  w.put(s.angleMin());
  w.put(s.angleIncrement());
  w.put(s.rangeMin());
  w.put(s.rangeMax());
  w.size(s.size());
  for (double r : s.ranges()) w.put(static_cast<float>(r));
}

LaserScan getScan(Reader& r) {
  LaserScanFields f;
  f.time = r.real("node.scan.time");
  f.angle_min = r.real("node.scan.angle_min");
  f.angle_increment = r.real("node.scan.angle_increment");
  f.range_min = r.real("node.scan.range_min");
  f.range_max = r.real("node.scan.range_max");
  const std::size_t n = r.count("node.scan.beams", sizeof(float));
  f.ranges.resize(n);
  for (double& x : f.ranges) x = r.get<float>("node.scan.ranges");
  try {
    return LaserScan::create(std::move(f));
  } catch (const Error& e) {
    throw r.bad(fmt::format("invalid node scan: {}", e.what()), "node.scan");
  }
}

void putConstraint(Writer& w, const Constraint& c) {
  w.put(static_cast<std::uint8_t>(c.kind));
  w.size(c.from);
  w.size(c.to);
  w.pose(c.T_from_to);
  w.flag(c.accepted);
  w.flag(c.searched);
  w.flag(c.descriptor);
  w.put(c.score);
  w.put(c.explained);
  w.str(c.reason);
}

Constraint getConstraint(Reader& r, std::size_t nodes) {
  Constraint c;
  const auto kind = r.get<std::uint8_t>("constraint.kind");
  if (kind > static_cast<std::uint8_t>(Constraint::Kind::kLoop))
    throw r.bad(fmt::format("constraint kind {} is unknown", kind), "constraint.kind");
  c.kind = static_cast<Constraint::Kind>(kind);
  c.from = r.index("constraint.from", nodes);
  c.to = r.index("constraint.to", nodes);
  c.T_from_to = r.pose("constraint.T_from_to");
  c.accepted = r.flag("constraint.accepted");
  c.searched = r.flag("constraint.searched");
  c.descriptor = r.flag("constraint.descriptor");
  c.score = r.get<double>("constraint.score");
  c.explained = r.get<double>("constraint.explained");
  c.reason = r.str("constraint.reason");
  return c;
}

void putStats(Writer& w, const SlamStats& s) {
  for (std::size_t v : {s.scans, s.nodes, s.submaps, s.matched, s.correlative_fallbacks, s.unmatched, s.degenerate,
                        s.prior_overridden, s.prior_kept, s.fragments, s.relocalizations, s.odometry_wins,
                        s.loop_searches, s.loop_accepted, s.loop_rejected, s.loop_downweighted, s.descriptor_queries,
                        s.descriptor_hypotheses, s.descriptor_accepted, s.optimizations})
    w.size(v);
  for (double v : {s.descriptor_seconds, s.optimization_seconds, s.total_seconds}) w.put(v);
}

SlamStats getStats(Reader& r) {
  SlamStats s;
  for (std::size_t* v : {&s.scans, &s.nodes, &s.submaps, &s.matched, &s.correlative_fallbacks, &s.unmatched,
                         &s.degenerate, &s.prior_overridden, &s.prior_kept, &s.fragments, &s.relocalizations,
                         &s.odometry_wins, &s.loop_searches, &s.loop_accepted, &s.loop_rejected,
                         &s.loop_downweighted, &s.descriptor_queries, &s.descriptor_hypotheses, &s.descriptor_accepted, &s.optimizations})
    *v = r.size("stats");
  for (double* v : {&s.descriptor_seconds, &s.optimization_seconds, &s.total_seconds}) *v = r.real("stats");
  return s;
}

std::string encodePayload(const State& s) {
  Writer w;
  putOptions(w, s.options);
  w.size(s.sessions.size());
  for (const auto& x : s.sessions) {
    w.str(x.name);
    w.size(x.first_scan);
  }
  w.size(s.nodes.size());
  for (const auto& d : s.nodes) {
    const Node& n = d.node;
    w.size(n.scan);
    w.put(n.time);
    w.pose(n.T_local_robot);
    w.pose(n.T_world_robot);
    w.size(n.submap);
    w.flag(n.degenerate);
    w.put(n.degenerate_dir_rad);
    putScan(w, d.scan);
    w.pose(d.T_robot_laser);
    w.optPose(d.T_odom_robot);
    w.size(d.frame_index);
    w.put(d.path_m);
  }
  w.size(s.scans.size());
  for (const auto& x : s.scans) {
    w.size(x.frame_index);
    w.put(x.time);
    w.size(x.node);
    w.pose(x.T_node_scan);
    w.flag(x.is_node);
    w.flag(x.matched);
    w.flag(x.degenerate);
    w.put(x.seconds);
  }
  w.size(s.submaps.size());
  for (const auto& sm : s.submaps) {
    w.size(sm.anchor);
    w.size(sm.nodes.size());
    for (std::size_t n : sm.nodes) w.size(n);
    w.flag(sm.finished);
    w.optSize(sm.last_link_node);
    w.pose(sm.last_link_T_anchor_node);
  }
  w.size(s.constraints.size());
  for (const auto& c : s.constraints) putConstraint(w, c);
  w.size(s.edges.size());
  for (const auto& e : s.edges) {
    w.size(e.from);
    w.size(e.to);
    w.pose(e.T_from_to);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) w.put(e.sqrt_information(i, j));
    w.put(e.huber_scale);
    w.flag(e.scalable);
  }
  w.size(s.restarts.size());
  for (std::size_t n : s.restarts) w.size(n);
  w.size(s.events.size());
  for (const auto& e : s.events) {
    w.size(e.frame_index);
    w.put(e.time);
    w.str(e.what);
  }
  putStats(w, s.stats);
  w.pose(s.T_world_local);
  w.optSize(s.last_loop_node);
  w.optSize(s.untied_since);
  w.flag(s.restart_odometry.has_value());
  if (s.restart_odometry) {
    w.size(s.restart_odometry->edge);
    w.size(s.restart_odometry->constraint);
    w.size(s.restart_odometry->node);
  }
  w.size(s.nodes_since_optimization);
  w.size(s.loops_since_optimization);
  return std::move(w.buf);
}

State decodePayload(Reader& r) {
  State s;
  s.options = getOptions(r);
  s.sessions.resize(r.count("sessions", 16));
  for (auto& x : s.sessions) {
    x.name = r.str("session.name");
    x.first_scan = r.size("session.first_scan");
  }
  s.nodes.resize(r.count("nodes", 100));
  const std::size_t N = s.nodes.size();
  for (auto& d : s.nodes) {
    Node& n = d.node;
    n.scan = r.size("node.scan_index");
    n.time = r.real("node.time");
    n.T_local_robot = r.pose("node.T_local_robot");
    n.T_world_robot = r.pose("node.T_world_robot");
    n.submap = r.size("node.submap");
    n.degenerate = r.flag("node.degenerate");
    n.degenerate_dir_rad = r.real("node.degenerate_dir_rad");
    d.scan = getScan(r);
    d.T_robot_laser = r.pose("node.T_robot_laser");
    d.T_odom_robot = r.optPose("node.T_odom_robot");
    d.frame_index = r.size("node.frame_index");
    d.path_m = r.real("node.path_m");
  }
  s.scans.resize(r.count("scans", 40));
  for (auto& x : s.scans) {
    x.frame_index = r.size("scan.frame_index");
    x.time = r.real("scan.time");
    x.node = r.index("scan.node", N);
    x.T_node_scan = r.pose("scan.T_node_scan");
    x.is_node = r.flag("scan.is_node");
    x.matched = r.flag("scan.matched");
    x.degenerate = r.flag("scan.degenerate");
    x.seconds = r.real("scan.seconds");
  }
  s.submaps.resize(r.count("submaps", 20));
  for (auto& sm : s.submaps) {
    sm.anchor = r.index("submap.anchor", N);
    sm.nodes.resize(r.count("submap.nodes", 8));
    for (std::size_t& n : sm.nodes) n = r.index("submap.node", N);
    if (sm.nodes.empty() || sm.nodes.front() != sm.anchor)
      throw r.bad("a submap's first node is not its anchor", "submap.nodes");
    sm.finished = r.flag("submap.finished");
    sm.last_link_node = r.optIndex("submap.last_link_node", N);
    sm.last_link_T_anchor_node = r.pose("submap.last_link_T_anchor_node");
  }
  s.constraints.resize(r.count("constraints", 40));
  for (auto& c : s.constraints) c = getConstraint(r, N);
  s.edges.resize(r.count("edges", 120));
  for (auto& e : s.edges) {
    e.from = r.index("edge.from", N);
    e.to = r.index("edge.to", N);
    if (e.from == e.to) throw r.bad(fmt::format("an edge joins node {} to itself", e.from), "edge.to");
    e.T_from_to = r.pose("edge.T_from_to");
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) e.sqrt_information(i, j) = r.real("edge.sqrt_information");
    e.huber_scale = r.real("edge.huber_scale");
    if (e.huber_scale < 0.0) throw r.bad(fmt::format("an edge's Huber scale is {}", e.huber_scale), "edge.huber_scale");
    e.scalable = r.flag("edge.scalable");
  }
  s.restarts.resize(r.count("restarts", 8));
  for (std::size_t& n : s.restarts) n = r.index("restart", N);
  s.events.resize(r.count("events", 24));
  for (auto& e : s.events) {
    e.frame_index = r.size("event.frame_index");
    e.time = r.real("event.time");
    e.what = r.str("event.what");
  }
  s.stats = getStats(r);
  s.T_world_local = r.pose("T_world_local");
  s.last_loop_node = r.optIndex("last_loop_node", N);
  s.untied_since = r.optIndex("untied_since", N);
  if (r.flag("restart_odometry")) {
    State::RestartOdometry ro;
    ro.edge = r.index("restart_odometry.edge", s.edges.size());
    ro.constraint = r.index("restart_odometry.constraint", s.constraints.size());
    ro.node = r.index("restart_odometry.node", N);
    s.restart_odometry = ro;
  }
  s.nodes_since_optimization = r.size("nodes_since_optimization");
  s.loops_since_optimization = r.size("loops_since_optimization");
  if (!r.done()) throw r.bad("bytes left after the last field", "payload");

  // What the pipeline indexes by must hold together.
  for (std::size_t i = 0; i < N; ++i) {
    const Node& n = s.nodes[i].node;
    if (n.scan >= s.scans.size() || s.scans[n.scan].node != i || !s.scans[n.scan].is_node)
      throw r.bad(fmt::format("node {} and its scan do not match", i), "node.scan_index");
    if (n.submap >= s.submaps.size()) throw r.bad(fmt::format("node {} names no submap", i), "node.submap");
  }
  for (std::size_t k = 0; k < s.scans.size(); ++k)
    if (s.scans[k].is_node && s.nodes[s.scans[k].node].node.scan != k)
      throw r.bad(fmt::format("scan {} is a node that names another scan", k), "scan.is_node");
  // The submaps partition the nodes: each lists its nodes in increasing order, each node is in the
  // one it names, and the lists hold N nodes in all (so none twice, none missing).
  std::size_t members = 0;
  for (std::size_t j = 0; j < s.submaps.size(); ++j) {
    const auto& nodes = s.submaps[j].nodes;
    for (std::size_t k = 0; k < nodes.size(); ++k) {
      if (k > 0 && nodes[k] <= nodes[k - 1])
        throw r.bad(fmt::format("submap {}'s nodes are not in increasing order", j), "submap.node");
      if (s.nodes[nodes[k]].node.submap != j)
        throw r.bad(
            fmt::format("submap {} lists node {}, which names submap {}", j, nodes[k], s.nodes[nodes[k]].node.submap),
            "submap.node");
    }
    members += nodes.size();
  }
  if (members != N) throw r.bad(fmt::format("the submaps list {} nodes of {}", members, N), "submap.nodes");
  // Edges are the accepted constraints', in the same order (the loop closure walks both together).
  std::size_t accepted = 0;
  for (const Constraint& c : s.constraints) {
    if (!c.accepted) continue;
    if (accepted >= s.edges.size() || s.edges[accepted].from != c.from || s.edges[accepted].to != c.to)
      throw r.bad(fmt::format("edge {} is not the accepted constraint's (from node {} to {})", accepted, c.from, c.to),
                  "edges");
    ++accepted;
  }
  if (accepted != s.edges.size())
    throw r.bad(fmt::format("{} edges for {} accepted constraints", s.edges.size(), accepted), "edges");
  for (std::size_t k = 1; k < s.restarts.size(); ++k)
    if (s.restarts[k] <= s.restarts[k - 1]) throw r.bad("the restarts are not in increasing order", "restart");
  // The odometry constraint across the latest lost track: from the node before it to `node`,
  // accepted, and `edge` its edge.
  if (const auto& ro = s.restart_odometry) {
    const Constraint& c = s.constraints[ro->constraint];
    const auto edge_of = static_cast<std::size_t>(
        std::count_if(s.constraints.begin(), s.constraints.begin() + static_cast<std::ptrdiff_t>(ro->constraint),
                      [](const Constraint& x) { return x.accepted; }));
    if (ro->node == 0 || c.kind != Constraint::Kind::kOdometry || !c.accepted || c.from != ro->node - 1 ||
        c.to != ro->node || ro->edge != edge_of)
      throw r.bad(fmt::format("the odometry across the lost track at node {} is not constraint {} and edge {}",
                              ro->node, ro->constraint, ro->edge),
                  "restart_odometry");
  }
  for (std::size_t i = 0; i < s.sessions.size(); ++i)
    if (s.sessions[i].first_scan > s.scans.size() || (i > 0 && s.sessions[i].first_scan < s.sessions[i - 1].first_scan))
      throw r.bad("the sessions' first scans are out of order", "session.first_scan");
  if (N == 0 || s.sessions.empty()) throw r.bad("no node", "nodes");
  return s;
}

}  // namespace

std::string encodeState(const State& state) {
  const std::string payload = encodePayload(state);
  uLongf bound = compressBound(static_cast<uLong>(payload.size()));
  std::string packed(bound, '\0');
  if (compress2(reinterpret_cast<Bytef*>(packed.data()), &bound, reinterpret_cast<const Bytef*>(payload.data()),
                static_cast<uLong>(payload.size()), Z_BEST_SPEED) != Z_OK)
    throw Error(ErrorKind::kIo, "cannot compress the SLAM state");
  packed.resize(bound);
  Writer w;
  w.buf.append(kStateMagic);
  w.put(kStateFormatVersion);
  w.str(LIDAR2D_VERSION);
  w.put(static_cast<std::uint64_t>(payload.size()));
  w.put(static_cast<std::uint32_t>(
      crc32(0L, reinterpret_cast<const Bytef*>(packed.data()), static_cast<uInt>(packed.size()))));
  w.put(static_cast<std::uint64_t>(packed.size()));
  w.buf += packed;
  return std::move(w.buf);
}

State decodeState(std::string_view bytes, const std::string& source) {
  constexpr const char* kWhat = "SLAM state file";
  if (!bytes.starts_with(kStateMagic))
    throw badInput("not a lidar2d SLAM state file (bad magic)", ErrorLocation(source, 0, "magic"));
  Reader h(bytes.substr(kStateMagic.size()), source, kWhat);
  const auto version = h.get<std::uint32_t>("version");
  if (version != kStateFormatVersion)
    throw Error(ErrorKind::kUnsupported,
                fmt::format("SLAM state format version {} is not supported (this lidar2d reads version {}); "
                            "map the logs again with 'lidar2d slam'",
                            version, kStateFormatVersion),
                ErrorLocation(source, 0, "version"));
  const std::string written_by = h.str("lidar2d_version");
  const auto payload_size = h.get<std::uint64_t>("payload_length");
  const auto crc = h.get<std::uint32_t>("checksum");
  const auto packed_size = h.get<std::uint64_t>("compressed_length");
  const std::string_view packed = bytes.substr(kStateMagic.size() + h.pos());
  if (packed.size() < packed_size)
    throw badInput(fmt::format("truncated SLAM state file: {} of its {} payload bytes", packed.size(), packed_size),
                   ErrorLocation(source, 0, "payload"));
  if (packed.size() > packed_size)
    throw badInput(fmt::format("SLAM state file has {} bytes after its payload", packed.size() - packed_size),
                   ErrorLocation(source, 0, "payload"));
  if (payload_size > kMaxBytes || payload_size / kMaxInflation > packed_size)
    throw badInput(fmt::format("SLAM state file: payload length {} is absurd for {} compressed bytes (corrupt header)",
                               payload_size, packed_size),
                   ErrorLocation(source, 0, "payload_length"));
  const auto actual =
      static_cast<std::uint32_t>(crc32(0L, reinterpret_cast<const Bytef*>(packed.data()), static_cast<uInt>(packed.size())));
  if (actual != crc)
    throw badInput(fmt::format("SLAM state file is corrupt (checksum {:08x}, expected {:08x})", actual, crc),
                   ErrorLocation(source, 0, "checksum"));
  std::string payload(payload_size, '\0');
  uLongf out = static_cast<uLongf>(payload_size);
  uLong in = static_cast<uLong>(packed.size());
  if (uncompress2(reinterpret_cast<Bytef*>(payload.data()), &out, reinterpret_cast<const Bytef*>(packed.data()), &in) !=
          Z_OK ||
      out != payload_size || in != packed.size())
    throw badInput(fmt::format("SLAM state file (written by lidar2d {}): the payload does not decompress to its "
                               "length, or not all of it",
                               written_by),
                   ErrorLocation(source, 0, "payload"));
  Reader r(payload, source, kWhat);
  return decodePayload(r);
}

void insertNodeScans(const State& state, mapping::OccupancyMap& map, std::size_t sessions) {
  const std::size_t end_scan =
      sessions < state.sessions.size() ? state.sessions[sessions].first_scan : state.scans.size();
  for (const State::NodeData& d : state.nodes)
    if (d.node.scan < end_scan) map.insert(d.scan, d.node.T_world_robot * d.T_robot_laser);
}

State readStateFile(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw ioError("no such file", ErrorLocation(path));
  if (!fs::is_regular_file(path, ec)) throw ioError("not a regular file (expected a SLAM state file)", ErrorLocation(path));
  const auto size = fs::file_size(path, ec);
  if (ec) throw ioError("cannot read: " + ec.message(), ErrorLocation(path));
  if (size > kMaxBytes) throw badInput(fmt::format("{} bytes: too large for a SLAM state file", size), ErrorLocation(path));
  std::ifstream in(path, std::ios::binary);
  std::string bytes(static_cast<std::size_t>(size), '\0');
  if (!in || !in.read(bytes.data(), static_cast<std::streamsize>(bytes.size())))
    throw ioError("cannot read", ErrorLocation(path));
  return decodeState(bytes, path);
}

}  // namespace lidar2d::slam
