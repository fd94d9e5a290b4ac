// Logs (read_log: any supported format, as an iterator of Frames), trajectory and relations files,
// the simulator and the CARMEN writer.
#include <fmt/format.h>

#include <memory>

#include "bindings.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/laser_mount.hpp"
#include "lidar2d/io/carmen_writer.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/prefetch.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace lidar2d::python {

namespace {
// The iterator read_log returns: the frames of one log, read (and parsed ahead on a second thread)
// as Python asks for them.
class LogReader {
 public:
  LogReader(const std::string& path, const io::ReaderOptions& options, bool read_ahead)
      : path_(path), source_(io::openLog(path, options)) {
    format_ = io::toString(source_->format());
    if (read_ahead) source_ = io::prefetch(std::move(source_));
  }
  std::optional<Frame> next() {
    if (!source_) return std::nullopt;
    std::optional<Frame> f;
    {
      py::gil_scoped_release release;
      f = source_->next();
    }
    if (!f) {
      notes_ = source_->notes();
      source_.reset();  // ends the read-ahead thread and closes the file
    }
    return f;
  }
  const std::string& path() const { return path_; }
  const std::string& format() const { return format_; }
  io::SourceNotes notes() const { return source_ ? source_->notes() : notes_; }

 private:
  std::string path_;
  std::string format_;
  std::unique_ptr<io::FrameSource> source_;
  io::SourceNotes notes_;
};

io::ReaderOptions readerOptions(const std::string& scan_topic, const std::string& odom_topic,
                                const std::string& carmen_laser, const std::optional<SE2>& laser_pose,
                                std::optional<double> laser_range_max) {
  io::ReaderOptions o;
  o.laser_range_max = laser_range_max;
  o.scan_topic = scan_topic;
  o.odom_topic = odom_topic;
  o.carmen_laser = carmen_laser;
  if (laser_pose) o.laser_mount = LaserMount::planar(*laser_pose);
  return o;
}
}  // namespace

void bindIo(py::module_& m) {
  py::class_<LogReader>(m, "LogReader", "Iterator over the frames of a log (returned by read_log).")
      .def("__iter__", [](LogReader& r) -> LogReader& { return r; })
      .def("__next__", [](LogReader& r) {
        auto f = r.next();
        if (!f) throw py::stop_iteration();
        return std::move(*f);
      })
      .def_property_readonly("path", &LogReader::path)
      .def_property_readonly("format", &LogReader::format, "'carmen', 'rosbag1', 'rosbag2' or 'range-table'")
      .def("notes", [](const LogReader& r) {
        const io::SourceNotes n = r.notes();
        py::dict d;
        d["scan_source"] = n.scan_source;
        d["odom_source"] = n.odom_source;
        d["truth_source"] = n.truth_source;
        d["container"] = n.container;
        d["warnings"] = n.warnings;
        d["lasers"] = n.lasers;
        d["beams_beyond_range_max"] = n.beams_beyond_range_max;
        return d;
      }, "what the reader learned about the log (complete once the iteration has ended): scan_source,\n"
         "odom_source, truth_source, container, warnings (as `lidar2d info` gives them: repeated timestamps,\n"
         "returns beyond a declared range max, ...), lasers, beams_beyond_range_max.");

  m.def("read_log",
        [](const py::object& path, const std::string& scan_topic, const std::string& odom_topic,
           const std::string& carmen_laser, std::optional<SE2> laser_pose, std::optional<double> laser_range_max,
           bool read_ahead) {
          const std::string p = py::str(path).cast<std::string>();
          const io::ReaderOptions o = readerOptions(scan_topic, odom_topic, carmen_laser, laser_pose, laser_range_max);
          py::gil_scoped_release release;
          return std::make_unique<LogReader>(p, o, read_ahead);
        },
        py::arg("path"), py::arg("scan_topic") = "", py::arg("odom_topic") = "", py::arg("carmen_laser") = "",
        py::arg("laser_pose") = py::none(), py::arg("laser_range_max") = py::none(), py::arg("read_ahead") = true,
        "Opens any supported log (CARMEN, ROS1 bag, ROS2 bag, range table) and returns an iterator of\n"
        "Frame in file order. Errors (missing file, malformed content) raise lidar2d.Error naming the\n"
        "file, line and field: at open, or at the frame where they occur. laser_pose replaces the log's\n"
        "laser mounting; laser_range_max [m] the log's range max (readings at or beyond it are no return);\n"
        "read_ahead parses the next frames on a second thread.");

  m.def("read_trajectory", [](const py::object& path) {
        const std::string p = py::str(path).cast<std::string>();
        return fromTrajectory(io::readTrajectory(p));
      }, py::arg("path"), "Reads a trajectory file (plain `t x y theta` or TUM) as an (N, 4) array t, x, y, theta.");
  m.def("write_trajectory",
        [](const py::object& path, const py::handle& trajectory, const std::string& format) {
          const std::string p = py::str(path).cast<std::string>();
          io::TrajectoryFormat f;
          if (format == "plain") f = io::TrajectoryFormat::kPlain;
          else if (format == "tum") f = io::TrajectoryFormat::kTum;
          else throw py::value_error("write_trajectory: format must be 'plain' or 'tum'");
          const Trajectory t = toTrajectory(trajectory, "write_trajectory");
          io::writeTrajectory(p, t, f);
        },
        py::arg("path"), py::arg("trajectory"), py::arg("format") = "plain",
        "Writes a trajectory ((N, 4) array of t x y theta, or (t, SE2) pairs) atomically.");
  m.def("read_relations", [](const py::object& path) {
        const Relations rel = io::readRelations(py::str(path).cast<std::string>());
        py::array_t<double> a({static_cast<py::ssize_t>(rel.size()), py::ssize_t{5}});
        for (std::size_t i = 0; i < rel.size(); ++i) {
          const Relation& r = rel[i];
          const double row[5] = {r.t1, r.t2, r.T_1_2.x(), r.T_1_2.y(), r.T_1_2.theta()};
          for (int c = 0; c < 5; ++c) a.mutable_at(i, c) = row[c];
        }
        return a;
      }, py::arg("path"), "Reads a relations file as an (N, 5) array t1, t2, dx, dy, dyaw.");

  m.def("list_worlds", &sim::listWorlds, "Names of the simulator's built-in worlds.");
  m.def(
      "simulate",
      [](const std::string& world, std::size_t scans, std::uint64_t seed, double rate_hz, bool noise_free,
         std::size_t people) {
        py::gil_scoped_release release;
        sim::Scenario s = sim::builtinScenario(world);
        sim::PathOptions po;
        po.rate_hz = rate_hz;
        sim::SimulatorOptions o;
        o.seed = seed;
        if (noise_free) o = o.noiseFree();
        o.crowd.people = people;
        sim::Simulator simulator(s.world, sim::samplePath(s.waypoints, po, scans), o);
        std::vector<Frame> frames;
        while (auto f = simulator.next()) frames.push_back(std::move(*f));
        return frames;
      },
      py::arg("world") = "office", py::arg("scans") = 0, py::arg("seed") = 1, py::arg("rate_hz") = 10.0,
      py::arg("noise_free") = false, py::arg("people") = 0,
      "Frames (scan, noisy odometry, truth) of a robot driving a built-in world's route; scans=0\n"
      "drives the route once; people: that many people walking the route 2-20 s ahead of or behind\n"
      "the robot (moving obstacles, `lidar2d simulate --people`). Deterministic per seed.");
  m.def("write_log",
        [](const py::object& path, const std::vector<Frame>& frames, const std::string& comment) {
          const std::string p = py::str(path).cast<std::string>();
          py::gil_scoped_release release;
          io::CarmenWriter w(p);
          if (!comment.empty()) w.comment(comment);
          for (const Frame& f : frames) w.write(f);
          w.commit();
        },
        py::arg("path"), py::arg("frames"), py::arg("comment") = "",
        "Writes frames as a CARMEN log (ROBOTLASER1, ODOM, TRUEPOS lines), atomically.");
}

}  // namespace lidar2d::python
