#!/usr/bin/python3
"""Writes the small ROS1 fixture bags (used by tests/test_rosbag1_reader.cpp and
tests/test_bad_input_bags.cpp) into the folder given as the first argument, with Debian's
python3-rosbag. The build runs it (tests/CMakeLists.txt), so no bag file is tracked in git. Messages are serialized here by hand
(ROS1 wire format: packed little-endian; strings are uint32 length + bytes) and written raw, so no
message packages are needed. By hand: /usr/bin/python3 tools/make-test-bags.py OUT_DIR

Fixtures:
- tf_chain.bag (lz4 chunks): two LaserScan topics (/scan_front 10 messages, /scan_rear 4), /odom,
  and an old-style /tf (no /tf_static) carrying odom->base_link and the chain
  base_link -> laser_mount (x 0.10, y 0.05, yaw +90 deg) -> laser_front (x 0.20, z 0.10,
  yaw -30 deg), so T_base_link_laser_front = (0.10, 0.25, +60 deg). Scan frame ids have a leading
  '/'. Odometry: 11 messages at stamps 100.0 .. 101.0 s (step 0.1) with x = s, y = 2 s,
  yaw = wrap(3.0 + 0.5 s), s = stamp - 100 (yaw crosses +pi at s = 0.2832). Front scans: header stamp
  100.04 + 0.2 k (k = 0..9) except k = 3, whose stamp is zero (bag time 100.65 is used); beams
  (8, angle_min -pi/2, increment pi/8, range_min 0.1, range_max 10): 0.5 + k, -1.0 (negative),
  NaN, inf, 0.05 (below range_min), 10.0 (= range_max), 2.0, 3.0.
- no_scan.bag: /odom (3 messages) and /chatter (std_msgs/String), no LaserScan.
- corrupt_scan.bag: /scan with 2 messages; the second states 1000 ranges but holds 3.
- flipped.bag: three lasers at the same place (x 0.2, y 0.1, z 0.3) seeing the same room, in
  /tf_static: base_link -> laser_up (yaw 0.4), laser_roll (roll pi, yaw 0.4) and laser_pitch
  (pitch pi, yaw 0.4). Topics /scan_up, /scan_roll, /scan_pitch, 5 messages each at stamps
  20.0 + 0.1 k, 8 beams (increment pi/8, range_min 0.1, range_max 10). /scan_up: ranges
  1 + 0.5 j + 0.01 k (j = 0..7) at angles -7 pi/16 + j pi/8. The upside-down lasers see the same
  points with the ranges reversed: the rolled one's beam b points at 0.4 - b, so its beams start at
  -7 pi/16 as well; the pitched one's points at 0.4 + pi - b, so its beams start at 9 pi/16.
  No odometry.
- many_chunks.bag (bz2, one message per chunk): /odom, 60 messages at stamps 50.0 + 0.05 i with
  x = 0.1 i (so x = 2 (t - 50)), plus a repeat of the first at the same bag time; /scan, 30 messages at
  stamps 50.02 + 0.1 k with ranges 1 + 0.01 k + 0.1 j (j = 0..7). Written in a shuffled order
  (fixed seed), so time order must come from the index across chunks. (python3-rosbag makes one
  connection per topic; several on one topic are tested in test_rosbag1_container.cpp.)
- two_lasers.bag: a front and a rear laser (180 degrees each, 181 beams from -pi/2 in steps of
  pi/180, range_min 0.05, range_max 20) in a round room of radius 3 m centred on the world origin,
  the robot driving along +x at 1 m/s (x = t - 10, y = 0, heading 0). /tf_static: base_link ->
  laser_front (x 0.2) and base_link -> laser_rear (x -0.2, y 0.05, yaw pi). /scan_front at stamps
  10.0 + 0.1 k, /scan_rear at 10.03 + 0.1 k (k = 0..4), each with the exact ranges to the circle from
  the laser's pose at its stamp; /odom every 0.05 s from 9.9 to 10.6 s.
- two_lasers_no_tf.bag: the same without /tf_static.
"""

import math
import os
import struct

import genpy
import rosbag

MD5 = {
    "sensor_msgs/LaserScan": "90c7ef2dc6895d81024acba2ac42f369",
    "nav_msgs/Odometry": "cd5e73d190d741a2f92e81eda573aca7",
    "tf2_msgs/TFMessage": "94810edda583a504dfda3829e70d7eec",
    "std_msgs/String": "992ce8a1687cec8c8bd883ec73ca41d1",
}


class FakeType:
    def __init__(self, name):
        self._md5sum = MD5[name]
        self._full_text = "# lidar2d test fixture: " + name + "\n"


def s(text):
    b = text.encode()
    return struct.pack("<I", len(b)) + b


def header(seq, stamp, frame):
    sec, nsec = stamp
    return struct.pack("<III", seq, sec, nsec) + s(frame)


def stamp_of(t):
    ns = round(t * 1e9)
    return ns // 1000000000, ns % 1000000000


def quat_yaw(yaw):
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def laser_scan(seq, stamp, frame, ranges, count=None):
    b = header(seq, stamp, frame)
    b += struct.pack("<7f", -math.pi / 2, -math.pi / 2 + 7 * math.pi / 8, math.pi / 8, 0.0, 0.1, 0.1, 10.0)
    b += struct.pack("<I", len(ranges) if count is None else count) + struct.pack(f"<{len(ranges)}f", *ranges)
    if count is None:
        b += struct.pack("<I", 0)  # no intensities
    return b


def odometry(seq, stamp, x, y, yaw):
    b = header(seq, stamp, "odom") + s("base_link")
    b += struct.pack("<7d", x, y, 0.0, *quat_yaw(yaw)) + struct.pack("<36d", *([0.0] * 36))
    b += struct.pack("<6d", *([0.0] * 6)) + struct.pack("<36d", *([0.0] * 36))
    return b


def tf_message(transforms):
    b = struct.pack("<I", len(transforms))
    for stamp, parent, child, x, y, z, yaw in transforms:
        b += header(0, stamp, parent) + s(child) + struct.pack("<7d", x, y, z, *quat_yaw(yaw))
    return b


def write(bag, topic, typ, data, t):
    bag.write(topic, (typ, data, MD5[typ], FakeType(typ)), genpy.Time.from_sec(t), raw=True)


def wrap(a):
    return math.atan2(math.sin(a), math.cos(a))


def tf_chain(path):
    with rosbag.Bag(path, "w", compression="lz4") as bag:
        for i in range(11):
            t = 100.0 + 0.1 * i
            sd = 0.1 * i
            write(bag, "/odom", "nav_msgs/Odometry", odometry(i, stamp_of(t), sd, 2 * sd, wrap(3.0 + 0.5 * sd)), t + 0.001)
            write(bag, "/tf", "tf2_msgs/TFMessage",
                  tf_message([(stamp_of(t), "odom", "base_link", sd, 2 * sd, 0.0, 0.0),
                              (stamp_of(t), "base_link", "laser_mount", 0.10, 0.05, 0.0, math.pi / 2),
                              (stamp_of(t), "laser_mount", "laser_front", 0.20, 0.0, 0.10, -math.pi / 6)]),
                  t + 0.002)
        for k in range(10):
            bag_t = 100.05 + 0.2 * k
            stamp = (0, 0) if k == 3 else stamp_of(100.04 + 0.2 * k)
            ranges = [0.5 + k, -1.0, float("nan"), float("inf"), 0.05, 10.0, 2.0, 3.0]
            write(bag, "/scan_front", "sensor_msgs/LaserScan", laser_scan(k, stamp, "/laser_front", ranges), bag_t)
        for k in range(4):
            bag_t = 100.07 + 0.2 * k
            write(bag, "/scan_rear", "sensor_msgs/LaserScan",
                  laser_scan(k, stamp_of(bag_t), "laser_rear", [1.0] * 8), bag_t)


def quat_rpy(roll, pitch, yaw):
    """q = q_yaw * q_pitch * q_roll (tf's setRPY), as (x, y, z, w)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def flipped(path):
    with rosbag.Bag(path, "w") as bag:
        b = struct.pack("<I", 3)
        for child, roll, pitch, yaw in (("laser_up", 0.0, 0.0, 0.4), ("laser_roll", math.pi, 0.0, 0.4),
                                        ("laser_pitch", 0.0, math.pi, 0.4)):
            b += header(0, stamp_of(19.0), "base_link") + s(child)
            b += struct.pack("<7d", 0.2, 0.1, 0.3, *quat_rpy(roll, pitch, yaw))
        write(bag, "/tf_static", "tf2_msgs/TFMessage", b, 19.0)
        for k in range(5):
            t = 20.0 + 0.1 * k
            ranges = [1.0 + 0.5 * j + 0.01 * k for j in range(8)]
            for topic, frame, rs, a0 in (("/scan_up", "laser_up", ranges, -7 * math.pi / 16),
                                         ("/scan_roll", "laser_roll", ranges[::-1], -7 * math.pi / 16),
                                         ("/scan_pitch", "laser_pitch", ranges[::-1], 9 * math.pi / 16)):
                m = header(k, stamp_of(t), frame)
                m += struct.pack("<7f", a0, a0 + 7 * math.pi / 8, math.pi / 8, 0.0, 0.1, 0.1, 10.0)
                m += struct.pack("<I", 8) + struct.pack("<8f", *rs) + struct.pack("<I", 0)
                write(bag, topic, "sensor_msgs/LaserScan", m, t)


def no_scan(path):
    with rosbag.Bag(path, "w") as bag:
        for i in range(3):
            t = 10.0 + i
            write(bag, "/odom", "nav_msgs/Odometry", odometry(i, stamp_of(t), i, 0.0, 0.0), t)
        write(bag, "/chatter", "std_msgs/String", s("hello"), 10.5)


def corrupt_scan(path):
    with rosbag.Bag(path, "w") as bag:
        write(bag, "/scan", "sensor_msgs/LaserScan", laser_scan(0, stamp_of(5.0), "laser", [1.0] * 8), 5.0)
        write(bag, "/scan", "sensor_msgs/LaserScan",
              laser_scan(1, stamp_of(5.1), "laser", [1.0, 2.0, 3.0], count=1000), 5.1)


def many_chunks(path):
    import random
    events = []
    for i in range(60):
        t = 50.0 + 0.05 * i
        events.append((t + 0.001, "/odom", "nav_msgs/Odometry", odometry(i, stamp_of(t), 0.1 * i, 0.0, 0.0)))
    events.append((50.001, "/odom", "nav_msgs/Odometry", odometry(60, stamp_of(50.0), 0.0, 0.0, 0.0)))
    for k in range(30):
        t = 50.02 + 0.1 * k
        ranges = [1.0 + 0.01 * k + 0.1 * j for j in range(8)]
        events.append((t, "/scan", "sensor_msgs/LaserScan", laser_scan(k, stamp_of(t), "laser", ranges)))
    random.Random(7).shuffle(events)
    with rosbag.Bag(path, "w", compression="bz2", chunk_threshold=100) as bag:
        for t, topic, typ, data in events:
            write(bag, topic, typ, data, t)


def circle_ranges(lx, ly, heading):
    """Ranges of a 181-beam half-circle laser at (lx, ly) facing `heading` to the circle of radius 3."""
    out = []
    for j in range(181):
        a = heading - math.pi / 2 + j * math.pi / 180
        dx, dy = math.cos(a), math.sin(a)
        cd = lx * dx + ly * dy
        out.append(-cd + math.sqrt(cd * cd - (lx * lx + ly * ly) + 9.0))
    return out


def two_lasers(path, with_tf):
    with rosbag.Bag(path, "w") as bag:
        if with_tf:
            write(bag, "/tf_static", "tf2_msgs/TFMessage",
                  tf_message([(stamp_of(9.0), "base_link", "laser_front", 0.2, 0.0, 0.0, 0.0),
                              (stamp_of(9.0), "base_link", "laser_rear", -0.2, 0.05, 0.0, math.pi)]), 9.0)
        for i in range(15):
            t = 9.9 + 0.05 * i
            write(bag, "/odom", "nav_msgs/Odometry", odometry(i, stamp_of(t), t - 10.0, 0.0, 0.0), t)
        for k in range(5):
            for topic, frame, t, mx, my, yaw in (("/scan_front", "laser_front", 10.0 + 0.1 * k, 0.2, 0.0, 0.0),
                                                 ("/scan_rear", "laser_rear", 10.03 + 0.1 * k, -0.2, 0.05, math.pi)):
                m = header(k, stamp_of(t), frame)
                m += struct.pack("<7f", -math.pi / 2, math.pi / 2, math.pi / 180, 0.0, 0.1, 0.05, 20.0)
                rs = circle_ranges(t - 10.0 + mx, my, yaw)
                m += struct.pack("<I", len(rs)) + struct.pack(f"<{len(rs)}f", *rs) + struct.pack("<I", 0)
                write(bag, topic, "sensor_msgs/LaserScan", m, t)


if __name__ == "__main__":
    import sys
    out = sys.argv[1] if len(sys.argv) > 1 else "tests/data"
    os.makedirs(out, exist_ok=True)
    tf_chain(os.path.join(out, "tf_chain.bag"))
    no_scan(os.path.join(out, "no_scan.bag"))
    corrupt_scan(os.path.join(out, "corrupt_scan.bag"))
    many_chunks(os.path.join(out, "many_chunks.bag"))
    flipped(os.path.join(out, "flipped.bag"))
    two_lasers(os.path.join(out, "two_lasers.bag"), True)
    two_lasers(os.path.join(out, "two_lasers_no_tf.bag"), False)
