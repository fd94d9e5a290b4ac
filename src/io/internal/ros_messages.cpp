#include "src/io/internal/ros_messages.hpp"

#include <fmt/format.h>

#include <bit>
#include <cstring>
#include <type_traits>

#include "lidar2d/core/error.hpp"

namespace lidar2d::io::internal {

double rosSeconds(RosNanos t) {
  // Split like ROS's Time(sec, nsec).toSec() so the double matches what rospy prints.
  RosNanos sec = t / 1000000000;
  RosNanos nsec = t % 1000000000;
  if (nsec < 0) {
    nsec += 1000000000;
    sec -= 1;
  }
  return static_cast<double>(sec) + static_cast<double>(nsec) * 1e-9;
}

std::string normalizeFrameId(std::string frame) {
  const auto first = frame.find_first_not_of('/');
  if (first == std::string::npos) return {};
  frame.erase(0, first);
  return frame;
}

namespace {

/// Bounds-checked reader of one serialized message. For CDR, primitives are aligned to their size
/// relative to the end of the 4-byte encapsulation header (OMG CDR, as used by ROS2's Fast-CDR).
class Cursor {
 public:
  Cursor(std::span<const std::uint8_t> bytes, RosWire wire, const RosMessageRef& ref, const char* type)
      : b_(bytes), wire_(wire), ref_(ref), type_(type) {
    if (wire_ == RosWire::kCdr) {
      field_ = "encapsulation header";
      need(4);
      // Byte 1 is the representation: 0 = CDR big-endian, 1 = CDR little-endian; 2/3 are the
      // parameter-list variants, which ROS2 never uses for plain messages.
      if (b_[0] != 0 || b_[1] > 1)
        throw Error(ErrorKind::kUnsupported,
                    fmt::format("{}: unsupported CDR encapsulation {:02x} {:02x} (only plain CDR is read)",
                                ref_.message, b_[0], b_[1]),
                    {ref_.file, 0, fieldName()});
      big_endian_ = b_[1] == 0;
      pos_ = origin_ = 4;
    }
  }

  /// Names the field the following reads belong to (for error messages).
  void field(const char* name) { field_ = name; }

  /// Reads field `name`, a number of type T (errors name the field).
  template <typename T>
  T read(const char* name) {
    field(name);
    return read<T>();
  }

  template <typename T>
  T read() {
    static_assert(std::is_arithmetic_v<T>);
    align(sizeof(T));
    need(sizeof(T));
    T v;
    std::memcpy(&v, b_.data() + pos_, sizeof(T));
    if (big_endian_) v = swapped(v);
    pos_ += sizeof(T);
    return v;
  }

  std::string readString() {
    const auto n = read<std::uint32_t>();
    need(n);
    const char* p = reinterpret_cast<const char*>(b_.data() + pos_);
    std::size_t len = n;
    if (wire_ == RosWire::kCdr && len > 0) {
      // CDR strings carry their terminating NUL in the length.
      if (p[len - 1] != '\0') fail("string is not NUL-terminated");
      --len;
    }
    pos_ += n;
    return std::string(p, len);
  }

  /// Header: ROS1 {uint32 seq, uint32 sec, uint32 nsec, string frame_id};
  /// ROS2 {int32 sec, uint32 nanosec, string frame_id}.
  RosNanos readHeader(std::string& frame_id) {
    field("header.stamp");
    RosNanos stamp = 0;
    if (wire_ == RosWire::kRos1) {
      (void)read<std::uint32_t>();  // seq
      const auto sec = read<std::uint32_t>();
      const auto nsec = read<std::uint32_t>();
      stamp = static_cast<RosNanos>(sec) * 1000000000 + nsec;
    } else {
      const auto sec = read<std::int32_t>();
      const auto nsec = read<std::uint32_t>();
      stamp = static_cast<RosNanos>(sec) * 1000000000 + nsec;
    }
    field("header.frame_id");
    frame_id = normalizeFrameId(readString());
    return stamp;
  }

  std::vector<float> readFloatSequence() {
    const auto n = read<std::uint32_t>();
    align(sizeof(float));
    // Check the stated length against the bytes left before allocating anything.
    if (n > (b_.size() - pos_) / sizeof(float))
      fail(fmt::format("states {} elements but only {} bytes are left", n, b_.size() - pos_));
    std::vector<float> v(n);
    for (auto& x : v) x = read<float>();
    return v;
  }

  RosTransform3 readPose() {  // geometry_msgs/Pose or Transform: 3 + 4 float64
    RosTransform3 t;
    t.tx = read<double>();
    t.ty = read<double>();
    t.tz = read<double>();
    t.qx = read<double>();
    t.qy = read<double>();
    t.qz = read<double>();
    t.qw = read<double>();
    return t;
  }

  std::size_t remaining() const { return b_.size() - pos_; }

  [[noreturn]] void fail(const std::string& what) const {
    throw badInput(fmt::format("{}: {}", ref_.message, what), {ref_.file, 0, fieldName()});
  }

 private:
  std::string fieldName() const { return fmt::format("{}.{}", type_, field_); }

  void align(std::size_t n) {
    if (wire_ != RosWire::kCdr) return;
    const std::size_t rel = (pos_ - origin_) % n;
    if (rel != 0) {
      need(n - rel);
      pos_ += n - rel;
    }
  }

  void need(std::size_t n) const {
    if (n > b_.size() - pos_)
      fail(fmt::format("truncated: needs {} bytes at offset {}, the message has {}", n, pos_, b_.size()));
  }

  template <typename T>
  static T swapped(T v) {
    unsigned char c[sizeof(T)];
    std::memcpy(c, &v, sizeof(T));
    for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(c[i], c[sizeof(T) - 1 - i]);
    std::memcpy(&v, c, sizeof(T));
    return v;
  }

  std::span<const std::uint8_t> b_;
  RosWire wire_;
  const RosMessageRef& ref_;
  const char* type_;
  const char* field_ = "";
  std::size_t pos_ = 0;
  std::size_t origin_ = 0;
  bool big_endian_ = false;
};

static_assert(std::endian::native == std::endian::little, "the decoders assume a little-endian host");

}  // namespace

RosLaserScanMsg decodeLaserScan(std::span<const std::uint8_t> bytes, RosWire wire, const RosMessageRef& ref) {
  Cursor c(bytes, wire, ref, "LaserScan");
  RosLaserScanMsg m;
  m.stamp = c.readHeader(m.frame_id);
  m.angle_min = c.read<float>("angle_min");
  m.angle_max = c.read<float>("angle_max");
  m.angle_increment = c.read<float>("angle_increment");
  m.time_increment = c.read<float>("time_increment");
  m.scan_time = c.read<float>("scan_time");
  m.range_min = c.read<float>("range_min");
  m.range_max = c.read<float>("range_max");
  c.field("ranges");
  m.ranges = c.readFloatSequence();
  c.field("intensities");
  m.intensities = c.readFloatSequence();
  return m;
}

RosOdometryMsg decodeOdometry(std::span<const std::uint8_t> bytes, RosWire wire, const RosMessageRef& ref) {
  Cursor c(bytes, wire, ref, "Odometry");
  RosOdometryMsg m;
  m.stamp = c.readHeader(m.frame_id);
  c.field("child_frame_id");
  m.child_frame_id = normalizeFrameId(c.readString());
  c.field("pose.pose");
  m.pose = c.readPose();
  // The covariances and the twist that follow are not used; still require them to be present so
  // that a truncated message is reported rather than silently accepted.
  c.field("pose.covariance");
  for (int i = 0; i < 36; ++i) (void)c.read<double>();
  c.field("twist");
  for (int i = 0; i < 6 + 36; ++i) (void)c.read<double>();
  return m;
}

std::vector<RosTransformStamped> decodeTfMessage(std::span<const std::uint8_t> bytes, RosWire wire,
                                                 const RosMessageRef& ref) {
  Cursor c(bytes, wire, ref, "TFMessage");
  c.field("transforms");
  const auto n = c.read<std::uint32_t>();
  // Each TransformStamped takes at least 4 + 4 + 4 + 4 + 56 bytes: a cheap sanity bound before
  // reserving memory.
  if (n > c.remaining() / 72) c.fail(fmt::format("states {} transforms but only {} bytes are left", n, c.remaining()));
  std::vector<RosTransformStamped> out;
  out.reserve(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    RosTransformStamped t;
    t.stamp = c.readHeader(t.parent);
    c.field("transforms.child_frame_id");
    t.child = normalizeFrameId(c.readString());
    c.field("transforms.transform");
    t.transform = c.readPose();
    out.push_back(std::move(t));
  }
  return out;
}

}  // namespace lidar2d::io::internal
