// SLAM online (add one frame, get its pose) and offline (a whole log, then its map), with the
// options named as in `lidar2d slam --dump-config` (the library's option table).
#include <fmt/format.h>

#include <type_traits>

#include "bindings.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/core/frame.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/io/prefetch.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/map_builder.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/slam/slam.hpp"
#include "lidar2d/slam/slam_options.hpp"
#include "lidar2d/slam/state_file.hpp"

namespace lidar2d::python {

namespace {
// SlamOptions from keyword arguments named as in the YAML config (angles in degrees). A value of
// the wrong type raises TypeError, one out of range or an unknown name ValueError.
slam::SlamOptions slamOptions(const py::kwargs& kwargs) {
  slam::SlamOptions o;
  for (const auto& [key, value] : kwargs) {
    const std::string name = py::str(key).cast<std::string>();
    const slam::SlamOption* opt = slam::findSlamOption(name);
    if (!opt) throw py::value_error(fmt::format("Slam option '{}': unknown (lidar2d slam --dump-config lists them)", name));
    std::visit(
        [&](auto current) {
          using T = decltype(current);
          const bool is_bool = py::isinstance<py::bool_>(value);
          if constexpr (std::is_same_v<T, bool>) {
            if (!is_bool) throw py::type_error(fmt::format("Slam option '{}': expected a bool", name));
          } else if constexpr (std::is_integral_v<T>) {
            if (is_bool || !py::isinstance<py::int_>(value))
              throw py::type_error(fmt::format("Slam option '{}': expected an int", name));
            if constexpr (std::is_unsigned_v<T>) {
              if (value.cast<long long>() < 0) throw py::value_error(fmt::format("Slam option '{}': must be >= 0", name));
            }
          } else {
            if (is_bool || !(py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value)))
              throw py::type_error(fmt::format("Slam option '{}': expected a number", name));
          }
          opt->set(o, value.cast<T>());
        },
        opt->get(o));
    if (auto why = opt->rangeError(o)) throw py::value_error(fmt::format("Slam option '{}': {}", name, *why));
  }
  return o;
}

py::dict statsDict(const slam::SlamStats& s) {
  py::dict d;
  d["scans"] = s.scans;
  d["nodes"] = s.nodes;
  d["submaps"] = s.submaps;
  d["matched"] = s.matched;
  d["unmatched"] = s.unmatched;
  d["degenerate"] = s.degenerate;
  d["moving_points"] = s.moving_points;
  d["moving_scans"] = s.moving_scans;
  d["fragments"] = s.fragments;
  d["odometry_scale"] = s.odometry_scale;
  d["odometry_scale_evidence_m"] = s.odometry_scale_evidence_m;
  d["loop_searches"] = s.loop_searches;
  d["loop_accepted"] = s.loop_accepted;
  d["loop_rejected"] = s.loop_rejected;
  d["loop_downweighted"] = s.loop_downweighted;
  d["loop_cycles"] = s.loop_cycles;
  d["cycle_odometry_deg"] = s.cycle_odometry_deg;
  d["cycle_front_end_deg"] = s.cycle_front_end_deg;
  d["cycle_odometry_m"] = s.cycle_odometry_m;
  d["cycle_front_end_m"] = s.cycle_front_end_m;
  d["odometry_weighted_by_cycles"] = s.odometry_weighted_by_cycles;
  d["descriptor_accepted"] = s.descriptor_accepted;
  d["optimizations"] = s.optimizations;
  d["total_seconds"] = s.total_seconds;
  return d;
}

Trajectory trajectoryOf(const slam::Slam& s) {
  Trajectory t;
  for (const auto& e : s.trajectory()) t.push_back({e.time, e.T_world_robot});
  return t;
}

// Adds every frame of `path` (parsed ahead on a second thread, as the CLI does); returns the
// number of scans. Call without the GIL.
std::size_t addLog(slam::Slam& s, const std::string& path) {
  auto source = io::prefetch(io::openLog(path));
  std::size_t n = 0;
  while (auto f = source->next()) {
    s.add(*f);
    ++n;
  }
  if (n == 0) throw badInput("log has no scans", ErrorLocation(path));
  return n;
}
}  // namespace

void bindSlam(py::module_& m) {
  py::class_<slam::Slam>(m, "Slam",
                         "2D SLAM (front end scan-to-map matching, submaps, loop closure, pose graph).\n"
                         "Options are keyword arguments named as in `lidar2d slam --dump-config` (angles in\n"
                         "degrees), e.g. Slam(use_odometry=False, submap_nodes=20).")
      .def(py::init([](const py::kwargs& kwargs) { return std::make_unique<slam::Slam>(slamOptions(kwargs)); }))
      .def("add", [](slam::Slam& s, const Frame& frame) {
            py::gil_scoped_release release;
            s.add(frame);
            return s.latest().T_world_robot;
          }, py::arg("frame"), "Adds the next frame (online); returns its current pose estimate T_world_robot.")
      .def("finish", &slam::Slam::finish, py::call_guard<py::gil_scoped_release>(),
           "Final pose-graph optimisation (idempotent); add() raises afterwards.")
      .def("run", [](slam::Slam& s, const py::object& path) {
            const std::string p = py::str(path).cast<std::string>();
            {
              py::gil_scoped_release release;
              addLog(s, p);
              s.finish();
            }
            return fromTrajectory(trajectoryOf(s));
          }, py::arg("path"), "Offline: adds every frame of a log, finishes, returns the trajectory (N, 4).")
      .def("save_state", [](const slam::Slam& s, const py::object& path) {
            const std::string p = py::str(path).cast<std::string>();
            py::gil_scoped_release release;
            io::writeFileAtomically(p, slam::encodeState(s.state()));
          }, py::arg("path"),
           "Writes the SLAM state (state.l2d, as `lidar2d slam` does; after finish() it is complete), which\n"
           "Slam.resume and `lidar2d slam --resume` continue and `lidar2d track` localizes in.")
      .def_static("resume", [](const py::object& path, const std::string& session) {
            const std::string p = py::str(path).cast<std::string>();
            py::gil_scoped_release release;
            return std::make_unique<slam::Slam>(slam::readStateFile(p), session);
          }, py::arg("path"), py::arg("session") = "",
           "A Slam continuing a saved state with a new session (its first pose unknown: placed by global\n"
           "localization in the saved submaps), with the saved options; as `lidar2d slam --resume`.")
      .def("trajectory", [](const slam::Slam& s) { return fromTrajectory(trajectoryOf(s)); },
           "Every scan's current estimate as an (N, 4) array t, x, y, theta (T_world_robot).")
      .def("stats", [](const slam::Slam& s) { return statsDict(s.stats()); }, "counters and timings as a dict")
      .def("options", [](const slam::Slam& s) {
            py::dict d;
            for (const slam::SlamOption& opt : slam::slamOptionTable())
              std::visit([&](auto v) { d[py::str(opt.name())] = v; }, opt.get(s.options()));
            return d;
          }, "every option with its value, as in `lidar2d slam --dump-config`");

  m.def("run_slam",
        [](const py::object& log, const py::object& out_dir, double resolution, const py::kwargs& kwargs) {
          const std::string path = py::str(log).cast<std::string>();
          const slam::SlamOptions options = slamOptions(kwargs);
          if (!(resolution > 0.0) || resolution > 10.0) throw py::value_error("resolution: must be in (0, 10] m");
          const std::string dir = out_dir.is_none() ? std::string() : py::str(out_dir).cast<std::string>();
          Trajectory trajectory;
          OccupancyImage image;
          slam::SlamStats stats;
          {
            py::gil_scoped_release release;
            slam::Slam s(options);
            const std::size_t n = addLog(s, path);
            s.finish();
            trajectory = trajectoryOf(s);
            stats = s.stats();
            // The map of every scan read again at its optimised pose (same index, same time).
            mapping::MapOptions mo;
            mo.resolution_m = resolution;
            mo.insert.max_range_m = options.max_range_m;
            auto map = mapping::makeMap(mapping::MapModel::kLogOdds, mo);
            mapping::MapBuilder builder(*map, mapping::FramePoses::fromTrajectory(trajectory, 0.0, path),
                                        {.source_name = path});
            auto again = io::openLog(path);
            if (builder.insert([&] { return again->next(); }) != n)
              throw ioError("the log changed while it was being read", ErrorLocation(path));
            image = mapping::toOccupancyImage(*map);
            if (!dir.empty()) {
              io::writeTrajectory(dir + "/trajectory.txt", trajectory);
              io::writeMap(dir + "/map.yaml", image);
            }
          }
          py::dict d;
          d["trajectory"] = fromTrajectory(trajectory);
          d["map"] = std::move(image);
          d["stats"] = statsDict(stats);
          return d;
        },
        py::arg("log"), py::arg("out_dir") = py::none(), py::arg("resolution") = 0.05,
        "Offline SLAM on a log with the CLI's defaults (keyword arguments override options), then the\n"
        "map of every scan at its optimised pose. Returns a dict: trajectory (N, 4), map (MapImage),\n"
        "stats. With out_dir (an existing folder): also writes out_dir/trajectory.txt and map.{yaml,pgm}.");
}

}  // namespace lidar2d::python
