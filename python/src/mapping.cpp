// Occupancy maps (insert scans, export to NumPy and map_server files, build from a log) and the
// degeneracy analysis of a scan.
#include <fmt/format.h>

#include <memory>

#include "bindings.hpp"
#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/degeneracy/degeneracy.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/map_builder.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"

namespace lidar2d::python {

namespace {
mapping::MapModel parseModel(const std::string& name) {
  if (name == "logodds") return mapping::MapModel::kLogOdds;
  if (name == "count") return mapping::MapModel::kCount;
  if (name == "tsdf") return mapping::MapModel::kTsdf;
  throw py::value_error(fmt::format("model: unknown '{}' (logodds, count, tsdf)", name));
}

mapping::MapOptions mapOptions(double resolution_m, double max_range_m) {
  if (!(resolution_m > 0.0) || resolution_m > 10.0) throw py::value_error("resolution: must be in (0, 10] m");
  if (!(max_range_m > 0.0) || !std::isfinite(max_range_m)) throw py::value_error("max_range: must be a finite value > 0");
  mapping::MapOptions o;
  o.resolution_m = resolution_m;
  o.insert.max_range_m = max_range_m;
  return o;
}

// A Python-owned occupancy map (the library's maps are abstract and non-copyable).
struct PyOccupancyMap {
  std::unique_ptr<mapping::OccupancyMap> map;
  std::size_t scans = 0;
};

py::dict degeneracyDict(const degeneracy::Result& r) {
  py::dict d;
  d["verdict"] = degeneracy::toString(r.verdict);
  d["degenerate"] = r.degenerate();
  d["score"] = r.score;
  d["direction_rad"] = r.direction_rad;
  d["reason"] = r.reason;
  d["information"] = fromMatrix3(r.information.information);
  d["num_lines"] = r.geometric.lines.size();
  return d;
}
}  // namespace

void bindMapping(py::module_& m) {
  py::class_<OccupancyImage>(m, "MapImage",
                             "A classified occupancy grid: cells -1 unknown, 0 free, 100 occupied (int8), shape\n"
                             "(height, width), row 0 at the bottom (the map's y grows with the row); origin is\n"
                             "the pose of cell (0, 0)'s lower-left corner, resolution the cell side [m].")
      .def_property_readonly("width", &OccupancyImage::width)
      .def_property_readonly("height", &OccupancyImage::height)
      .def_property_readonly("resolution", &OccupancyImage::resolution)
      .def_property_readonly("origin", &OccupancyImage::origin)
      .def_property_readonly("cells", [](py::object self) {
            const OccupancyImage& im = self.cast<const OccupancyImage&>();
            py::array_t<std::int8_t> a({static_cast<py::ssize_t>(im.height()), static_cast<py::ssize_t>(im.width())},
                                       im.cells().data(), self);
            a.attr("flags").attr("writeable") = false;
            return a;
          }, "the cells as a read-only (height, width) int8 view (no copy)")
      .def(py::init([](const py::array& cells, double resolution, const py::handle& origin) {
             if (cells.dtype().kind() != 'i' || cells.itemsize() != 1 || cells.ndim() != 2)
               throw py::type_error("MapImage: cells must be a 2-D int8 array (height, width)");
             const auto c = py::array_t<std::int8_t, py::array::c_style>::ensure(cells);
             std::vector<std::int8_t> v(c.data(), c.data() + c.size());
             return OccupancyImage::create(static_cast<int>(c.shape(1)), static_cast<int>(c.shape(0)), resolution,
                                           toPose(origin, "MapImage origin"), std::move(v));
           }),
           py::arg("cells"), py::arg("resolution"), py::arg("origin") = SE2())
      .def("save", [](const OccupancyImage& im, const py::object& yaml_path) {
            const std::string p = py::str(yaml_path).cast<std::string>();
            py::gil_scoped_release release;
            io::writeMap(p, im);
          }, py::arg("yaml_path"), "Writes a map_server map: YAML_PATH and the PGM beside it (atomically).")
      .def("__repr__", [](const OccupancyImage& im) {
            return fmt::format("MapImage({}x{}, resolution={})", im.width(), im.height(), im.resolution());
          });
  m.def("load_map", [](const py::object& yaml_path) {
        const std::string p = py::str(yaml_path).cast<std::string>();
        py::gil_scoped_release release;
        return io::readMap(p).map;
      }, py::arg("yaml_path"), "Reads a map_server map (YAML + image) as a MapImage.");

  py::class_<PyOccupancyMap>(m, "OccupancyMap", "An occupancy map that grows as scans are inserted.")
      .def(py::init([](const std::string& model, double resolution, double max_range) {
             return PyOccupancyMap{mapping::makeMap(parseModel(model), mapOptions(resolution, max_range)), 0};
           }),
           py::arg("model") = "logodds", py::arg("resolution") = 0.05, py::arg("max_range") = 30.0,
           "model: 'logodds', 'count' or 'tsdf'; resolution [m]; returns beyond max_range [m] are no return.")
      .def("insert", [](PyOccupancyMap& self, const Frame& frame, const py::handle& pose) {
            SE2 T_world_robot;
            if (!pose.is_none()) T_world_robot = toPose(pose, "OccupancyMap.insert pose");
            else if (frame.T_world_robot) T_world_robot = *frame.T_world_robot;
            else if (frame.T_odom_robot) T_world_robot = *frame.T_odom_robot;
            else throw py::value_error("OccupancyMap.insert: the frame has no truth or odometry; give pose");
            py::gil_scoped_release release;
            self.map->insert(frame.scan, T_world_robot * frame.T_robot_laser);
            ++self.scans;
          }, py::arg("frame"), py::arg("pose") = py::none(),
          "Inserts the frame's scan at T_world_robot = pose (default: its truth, else its odometry).")
      .def_property_readonly("scans", [](const PyOccupancyMap& self) { return self.scans; }, "scans inserted")
      .def("to_image", [](const PyOccupancyMap& self, int pad) {
            if (pad < 0) throw py::value_error("pad: must be >= 0");
            return mapping::toOccupancyImage(*self.map, pad);
          }, py::arg("pad") = 1, "The classified map over its bounds (padded by pad cells) as a MapImage.")
      .def("to_numpy", [](const PyOccupancyMap& self) {
            const OccupancyImage im = mapping::toOccupancyImage(*self.map);
            py::array_t<std::int8_t> a({static_cast<py::ssize_t>(im.height()), static_cast<py::ssize_t>(im.width())});
            std::copy(im.cells().begin(), im.cells().end(), a.mutable_data());
            return a;
          }, "The classified cells as a (height, width) int8 array (see MapImage).")
      .def("save", [](const PyOccupancyMap& self, const py::object& yaml_path) {
            const OccupancyImage im = mapping::toOccupancyImage(*self.map);
            const std::string p = py::str(yaml_path).cast<std::string>();
            py::gil_scoped_release release;
            io::writeMap(p, im);
          }, py::arg("yaml_path"), "Writes the map as a map_server map (YAML + PGM).");

  m.def("build_map",
        [](const py::object& log, const std::string& model, double resolution, double max_range,
           const py::handle& poses) {
          const std::string path = py::str(log).cast<std::string>();
          const auto options = mapOptions(resolution, max_range);
          const auto source_poses = poses.is_none()
                                        ? mapping::FramePoses::fromFrames(mapping::PoseSource::kAuto)
                                        : mapping::FramePoses::fromTrajectory(toTrajectory(poses, "build_map poses"),
                                                                              0.1, "poses");
          py::gil_scoped_release release;
          auto map = mapping::makeMap(parseModel(model), options);
          mapping::MapBuilder builder(*map, source_poses, {.source_name = path});
          auto source = io::openLog(path);
          builder.insert([&] { return source->next(); });
          return mapping::toOccupancyImage(*map);
        },
        py::arg("log"), py::arg("model") = "logodds", py::arg("resolution") = 0.05, py::arg("max_range") = 30.0,
        py::arg("poses") = py::none(),
        "The map of every scan of a log at its truth pose (else odometry), or at the poses of a\n"
        "trajectory (path, (N, 4) array) matched by time within 0.1 s: what `lidar2d map` builds.");

  m.def("analyze_degeneracy", [](const py::handle& points) {
        Points2 p;
        if (py::isinstance<Frame>(points)) {
          const Frame& f = points.cast<const Frame&>();
          p = f.scan.toPoints(f.T_robot_laser);
        } else {
          p = toPoints(points, "analyze_degeneracy points");
        }
        degeneracy::Result r;
        {
          py::gil_scoped_release release;
          r = degeneracy::analyze(p);
        }
        return degeneracyDict(r);
      }, py::arg("points"),
      "Is the translation along some direction unconstrained by this scan (a corridor)? points: a Frame\n"
      "or (N, 2) points [m]. Returns a dict: verdict ('well_constrained', 'degenerate', 'cannot_decide'),\n"
      "degenerate, score, direction_rad (robot frame), reason, information (3x3), num_lines.");
}

}  // namespace lidar2d::python
