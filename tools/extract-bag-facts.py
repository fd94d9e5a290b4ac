#!/usr/bin/python3
"""Extracts the expected values of tests/test_rosbag1_reader.cpp and tests/test_rosbag2_reader.cpp
from the bags in ../shared/data, independently of lidar2d's readers:

- ROS1 bags with Debian's python3-rosbag (run with /usr/bin/python3, not a pyenv python);
- the ROS2 bag with python's sqlite3 + struct (a small CDR decoder below).

Printed as C++ initializers (BagFacts in the tests). Conventions, the same as the readers':
- scans in bag order (the order rosbag / the messages table's timestamp gives);
- frame time = header stamp in seconds (sec + nsec * 1e-9), the bag time when the stamp is zero;
- odometry sorted (stably) by header stamp; at scan time t, with o0 the last message at or before t
  and o1 the first at or after t: a = (t - t0) / (t1 - t0), x, y linear in a,
  yaw = yaw0 + a * wrap(yaw1 - yaw0); before the first / after the last message the nearest one;
  yaw = atan2(2(wz + xy), 1 - 2(y^2 + z^2));
- mounting = /tf_static transform from the odometry child frame (or base_link) to the scan frame
  (a single edge in all these bags; checked below);
- a beam is valid when finite and range_min < r < range_max.

Usage: /usr/bin/python3 tools/extract-bag-facts.py [DATA_DIR]
"""

import bisect
import math
import sqlite3
import struct
import sys

DATA = sys.argv[1] if len(sys.argv) > 1 else "../shared/data"


def yaw_of(q):
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def wrap(a):
    a = math.remainder(a, 2.0 * math.pi)
    if a <= -math.pi:
        a += 2.0 * math.pi
    return a


def interpolate(odom, t):
    """odom: list of (t, x, y, yaw) sorted by t."""
    times = [o[0] for o in odom]
    i = bisect.bisect_left(times, t)
    if i == 0:
        return odom[0][1:]
    if i == len(odom):
        return odom[-1][1:]
    o1 = odom[i]
    o0 = odom[i - 1]
    if o1[0] == t:
        return o1[1:]
    a = (t - o0[0]) / (o1[0] - o0[0])
    return (o0[1] + a * (o1[1] - o0[1]), o0[2] + a * (o1[2] - o0[2]), wrap(o0[3] + a * wrap(o1[3] - o0[3])))


def cpp(v):
    if math.isnan(v):
        return "kNaN"
    if math.isinf(v):
        return "kInf" if v > 0 else "-kInf"
    return repr(float(v))


def emit(name, scans, odom, mount, fields):
    """scans: list of (time, ranges, range_min, range_max, angle_min, angle_increment)."""
    n = len(scans)
    beams = len(scans[0][1])
    valid = sum(1 for s in scans for r in s[1] if math.isfinite(r) and s[2] < r < s[3])
    negative = sum(1 for s in scans for r in s[1] if math.isfinite(r) and r < 0)
    print(f"// {name}: {n} scans, {valid} valid beams in total, {negative} negative ranges")
    print("{")
    print(f'  "{name}", {n}, {beams}, {scans[0][0]!r}, {scans[-1][0]!r},')
    print(f"  {cpp(fields[0])}, {cpp(fields[1])}, {cpp(fields[2])}, {cpp(fields[3])},  // angle_min, increment, range_min, range_max")
    print(f"  {valid}u, SE2({mount[0]!r}, {mount[1]!r}, {mount[2]!r}),")
    picks = sorted({0, 1, n // 2, n - 1})
    rng = []
    for si in picks:
        nb = len(scans[si][1])
        for bi in sorted({0, nb // 3, nb // 2, nb - 1}):
            rng.append(f"{{{si}, {bi}, {cpp(scans[si][1][bi])}}}")
    print("  {" + ", ".join(rng) + "},")
    if odom:
        od = []
        for si in sorted({0, 1, n // 4, n // 2, (3 * n) // 4, n - 1}):
            x, y, th = interpolate(odom, scans[si][0])
            od.append(f"{{{si}, {x!r}, {y!r}, {th!r}}}")
        print("  {" + ",\n   ".join(od) + "},")
    else:
        print("  {},")
    print("},")


def ros1(name):
    import rosbag

    bag = rosbag.Bag(f"{DATA}/{name}")
    if bag.version == 102:  # python3-rosbag's v1.2 reader rejects the topics= argument
        it = bag._reader.read_messages(None, None, None, None, False)
    else:
        it = bag.read_messages()
    scans, odom, tf_static = [], [], {}
    odom_child = None
    for rec in it:
        topic, msg, t = rec[0], rec[1], rec[2]
        if msg._type == "sensor_msgs/LaserScan":
            stamp = msg.header.stamp if msg.header.stamp.to_nsec() != 0 else t
            scans.append((stamp.to_sec(), list(msg.ranges), msg.range_min, msg.range_max, msg.angle_min,
                          msg.angle_increment, msg.header.frame_id.lstrip("/")))
        elif msg._type == "nav_msgs/Odometry":
            stamp = msg.header.stamp if msg.header.stamp.to_nsec() != 0 else t
            p = msg.pose.pose
            odom.append((stamp.to_sec(), p.position.x, p.position.y,
                         yaw_of((p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w))))
            odom_child = odom_child or msg.child_frame_id.lstrip("/")
        elif topic == "/tf_static":
            for tr in msg.transforms:
                tf_static[(tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"))] = tr.transform
    odom.sort(key=lambda o: o[0])  # stable
    emit_bag(name, scans, odom, tf_static, odom_child)


def emit_bag(name, scans, odom, tf_static, odom_child):
    robot = odom_child or "base_link"
    laser = scans[0][6]
    mount = (0.0, 0.0, 0.0)
    tr = tf_static.get((robot, laser))
    if tr is not None:
        mount = (tr.translation.x, tr.translation.y,
                 yaw_of((tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w)))
    print(f"// mounting: {robot} -> {laser}: {'from /tf_static' if tr is not None else 'not found (identity)'}")
    s0 = scans[0]
    emit(name, [s[:6] for s in scans], odom, mount, (s0[4], s0[5], s0[2], s0[3]))


class Cdr:
    def __init__(self, b):
        assert b[0] == 0 and b[1] == 1, "little-endian CDR expected"
        self.b, self.o = b, 4

    def align(self, n):
        r = (self.o - 4) % n
        if r:
            self.o += n - r

    def get(self, fmt):
        n = struct.calcsize(fmt)
        self.align(n)
        v = struct.unpack_from("<" + fmt, self.b, self.o)[0]
        self.o += n
        return v

    def string(self):
        n = self.get("I")
        s = self.b[self.o:self.o + n - 1].decode()
        self.o += n
        return s

    def header(self):
        sec = self.get("i")
        nsec = self.get("I")
        return sec * 1000000000 + nsec, self.string().lstrip("/")

    def floats(self):
        n = self.get("I")
        return [self.get("f") for _ in range(n)]

    def pose(self):
        return [self.get("d") for _ in range(7)]


class Tr:  # duck-types geometry_msgs/Transform for emit_bag
    class V:
        pass

    def __init__(self, p):
        self.translation, self.rotation = Tr.V(), Tr.V()
        self.translation.x, self.translation.y, self.translation.z = p[:3]
        self.rotation.x, self.rotation.y, self.rotation.z, self.rotation.w = p[3:]


def sec(ns):
    return ns // 1000000000 + (ns % 1000000000) * 1e-9


def ros2(name):
    import glob

    db = glob.glob(f"{DATA}/{name}/*.db3")[0]
    con = sqlite3.connect(f"file:{db}?immutable=1", uri=True)
    topics = {i: (n, t) for i, n, t in con.execute("SELECT id, name, type FROM topics")}
    scans, odom, tf_static = [], [], {}
    odom_child = None
    for _, tid, ts, data in con.execute("SELECT id, topic_id, timestamp, data FROM messages ORDER BY timestamp, id"):
        tname, ttype = topics[tid]
        c = Cdr(data)
        if ttype == "sensor_msgs/msg/LaserScan":
            stamp, frame = c.header()
            amin, amax, ainc, tinc, stime, rmin, rmax = [c.get("f") for _ in range(7)]
            ranges = c.floats()
            scans.append((sec(stamp or ts), ranges, rmin, rmax, amin, ainc, frame))
        elif ttype == "nav_msgs/msg/Odometry":
            stamp, frame = c.header()
            child = c.string().lstrip("/")
            p = c.pose()
            odom.append((sec(stamp or ts), p[0], p[1], yaw_of(p[3:])))
            odom_child = odom_child or child
        elif tname == "/tf_static":
            for _ in range(c.get("I")):
                _, parent = c.header()
                child = c.string().lstrip("/")
                tf_static[(parent, child)] = Tr(c.pose())  # later messages override, as tf2 does
    odom.sort(key=lambda o: o[0])
    emit_bag(name, scans, odom, tf_static, odom_child)


def relation_check(name, rel):
    """First t1 of a relations file, to check frame times equal the relation timestamps."""
    with open(f"{DATA}/{rel}") as f:
        for line in f:
            if line.strip() and not line.startswith("#"):
                print(f"// {rel}: first t1 = {line.split()[0]}")
                return


if __name__ == "__main__":
    for bag in ["raw/intel.orig.bag", "raw/fr079.orig.bag", "raw/mit-csail.orig.bag",
                "bags/laser_scan_matcher_demo.bag", "bags/laser_scan_sparsifier_demo.bag"]:
        ros1(bag)
    for rel in ["raw/intel.relations", "raw/fr079.relations", "raw/mit-csail.relations"]:
        relation_check(rel, rel)
    ros2("ros2/macfirst_floor_take_2")
