// Global localization: the descriptor database of a map (build, save, load) and the localizer of
// single scans.
#include <fmt/format.h>

#include <cmath>
#include <memory>
#include <optional>

#include "bindings.hpp"
#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/io/localization_db.hpp"
#include "lidar2d/localization/localizer.hpp"

namespace lidar2d::python {

namespace {
// A database owned by Python until a Localizer takes it (the library's database is move-only).
struct PyDatabase {
  std::optional<localization::Database> db;
  const localization::Database& get() const {
    if (!db) throw py::value_error("LocalizationDatabase: already given to a Localizer (load or build it again)");
    return *db;
  }
};

py::object poseOrNone(const SE2& T) { return T.isFinite() ? py::cast(T) : py::none(); }

py::dict resultDict(const localization::LocalizationResult& r) {
  py::dict d;
  d["declined"] = r.declined;
  d["reason"] = r.reason;
  d["pose"] = poseOrNone(r.T_world_robot);
  d["score"] = r.score;
  py::list alternatives;
  for (const auto& c : r.alternatives) alternatives.append(py::make_tuple(poseOrNone(c.T_world_robot), c.score));
  d["alternatives"] = alternatives;
  d["num_points"] = r.num_points;
  d["num_lines"] = r.num_lines;
  d["num_candidates"] = r.num_candidates;
  d["seconds"] = r.total_ms / 1e3;
  return d;
}
}  // namespace

void bindLocalization(py::module_& m) {
  py::class_<PyDatabase>(m, "LocalizationDatabase",
                         "Descriptors (line pairs, range profiles) of virtual scans over a map's free space.")
      .def_property_readonly("positions", [](const PyDatabase& d) { return d.get().positions().size(); })
      .def_property_readonly("pairs", [](const PyDatabase& d) { return d.get().numPairs(); })
      .def_property_readonly("map_checksum", [](const PyDatabase& d) { return d.get().mapChecksum(); })
      .def("save", [](const PyDatabase& d, const py::object& path) {
            const std::string p = py::str(path).cast<std::string>();
            const auto& db = d.get();
            py::gil_scoped_release release;
            io::writeLocalizationDatabase(p, db);
          }, py::arg("path"), "Writes the database file (versioned, checksummed) atomically.");
  m.def("build_localization_db", [](const OccupancyImage& map, double step, unsigned threads) {
        localization::DatabaseOptions o;
        o.step_m = step;
        py::gil_scoped_release release;
        return PyDatabase{localization::Database::build(map, o, threads)};
      }, py::arg("map"), py::arg("step") = 0.2, py::arg("threads") = 0,
      "Builds the database of a MapImage (positions every `step` m; threads 0 = all cores).");
  m.def("load_localization_db", [](const py::object& path) {
        const std::string p = py::str(path).cast<std::string>();
        py::gil_scoped_release release;
        return PyDatabase{io::readLocalizationDatabase(p)};
      }, py::arg("path"), "Reads a database file written by save() or `lidar2d localize-index`.");

  py::class_<localization::Localizer>(m, "Localizer",
                                      "Global localization of single scans in a map, no initial pose.")
      .def(py::init([](const OccupancyImage& map, const py::handle& database) {
             if (database.is_none()) {
               py::gil_scoped_release release;
               return std::make_unique<localization::Localizer>(map);
             }
             localization::Database db = py::isinstance<PyDatabase>(database)
                                             ? [&] {
                                                 auto& d = database.cast<PyDatabase&>();
                                                 d.get();
                                                 localization::Database out = std::move(*d.db);
                                                 d.db.reset();
                                                 return out;
                                               }()
                                             : io::readLocalizationDatabase(py::str(database).cast<std::string>());
             py::gil_scoped_release release;
             return std::make_unique<localization::Localizer>(map, std::move(db));
           }),
           py::arg("map"), py::arg("database") = py::none(),
           "map: a MapImage; database: None (built here), a LocalizationDatabase (which the localizer\n"
           "takes over) or a database file path. A database of another map raises lidar2d.Error.")
      .def("localize", [](const localization::Localizer& self, const py::handle& scan) {
            localization::LocalizationResult r;
            if (py::isinstance<Frame>(scan)) {
              const Frame& f = scan.cast<const Frame&>();
              py::gil_scoped_release release;
              r = self.localize(f.scan, f.T_robot_laser);
            } else {
              const Points2 p = toPoints(scan, "Localizer.localize points");
              py::gil_scoped_release release;
              r = self.localize(p);
            }
            return resultDict(r);
          }, py::arg("scan"),
          "Localizes one scan (a Frame, or (N, 2) points in the robot frame) on its own. Returns a dict:\n"
          "declined, reason, pose (SE2 T_world_robot or None), score in [0, 1], alternatives [(SE2, score)],\n"
          "num_points, num_lines, num_candidates, seconds.");
}

}  // namespace lidar2d::python
