// Global localization: the descriptor database of a map (build, save, load), the localizer of
// single scans, and the tracker (localization scan by scan without an initial pose).
#include <fmt/format.h>

#include <cmath>
#include <memory>
#include <optional>

#include "bindings.hpp"
#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/io/localization_db.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/localization/tracker.hpp"

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

// The database a Localizer or Tracker is built with: None (built from the map), a
// LocalizationDatabase (taken over: it cannot be used again) or a database file path.
std::optional<localization::Database> takeDatabase(const py::handle& database) {
  if (database.is_none()) return std::nullopt;
  if (py::isinstance<PyDatabase>(database)) {
    auto& d = database.cast<PyDatabase&>();
    d.get();
    localization::Database out = std::move(*d.db);
    d.db.reset();
    return out;
  }
  return io::readLocalizationDatabase(py::str(database).cast<std::string>());
}

py::dict resultDict(const localization::LocalizationResult& r) {
  py::dict d;
  d["declined"] = r.declined;
  d["reason"] = r.reason;
  d["pose"] = poseOrNone(r.T_world_robot);
  d["score"] = r.score;
  py::list alternatives;
  for (const auto& c : r.alternatives) alternatives.append(py::make_tuple(poseOrNone(c.T_world_robot), c.score));
  d["alternatives"] = alternatives;
  py::list candidates;
  for (const auto& c : r.candidates) candidates.append(py::make_tuple(poseOrNone(c.T_world_robot), c.score, c.fit));
  d["candidates"] = candidates;
  d["num_points"] = r.num_points;
  d["num_lines"] = r.num_lines;
  d["num_candidates"] = r.num_candidates;
  d["num_regions"] = r.num_regions;
  d["used_fallback"] = r.used_fallback;
  d["seconds"] = r.total_ms / 1e3;
  return d;
}
}  // namespace

void bindLocalization(py::module_& m) {
  const localization::LocalizerOptions loc_defaults;
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

  py::class_<localization::Localizer>(m, "Localizer", "Global localization of single scans in a map, no initial pose.")
      .def(py::init([](const OccupancyImage& map, const py::handle& database, double min_score, double ambiguity_ratio,
                       double ambiguity_nats_per_point, double unconfident_nats_per_point, double budget_ms,
                       std::size_t max_regions, std::size_t profile_candidates, std::size_t max_candidates,
                       bool fallback_branch_and_bound, std::size_t threads) {
             localization::LocalizerOptions o;
             o.min_score = min_score;
             o.ambiguity_ratio = ambiguity_ratio;
             o.ambiguity_nats_per_point = ambiguity_nats_per_point;
             o.unconfident_nats_per_point = unconfident_nats_per_point;
             o.budget_ms = budget_ms;
             o.max_regions = max_regions;
             o.profile_candidates = profile_candidates;
             o.max_candidates = max_candidates;
             o.fallback_branch_and_bound = fallback_branch_and_bound;
             o.threads = threads;
             o.validate();  // before the database is taken over, so a bad option leaves it usable
             std::optional<localization::Database> db = takeDatabase(database);
             py::gil_scoped_release release;
             return db ? std::make_unique<localization::Localizer>(map, std::move(*db), o)
                       : std::make_unique<localization::Localizer>(map, o);
           }),
           py::arg("map"), py::arg("database") = py::none(), py::kw_only(),
           py::arg("min_score") = loc_defaults.min_score, py::arg("ambiguity_ratio") = loc_defaults.ambiguity_ratio,
           py::arg("ambiguity_nats_per_point") = loc_defaults.ambiguity_nats_per_point,
           py::arg("unconfident_nats_per_point") = loc_defaults.unconfident_nats_per_point,
           py::arg("budget_ms") = loc_defaults.budget_ms, py::arg("max_regions") = loc_defaults.max_regions,
           py::arg("profile_candidates") = loc_defaults.profile_candidates,
           py::arg("max_candidates") = loc_defaults.max_candidates,
           py::arg("fallback_branch_and_bound") = loc_defaults.fallback_branch_and_bound,
           py::arg("threads") = loc_defaults.threads,
           "map: a MapImage; database: None (built here), a LocalizationDatabase (which the localizer\n"
           "takes over) or a database file path. A database of another map raises lidar2d.Error.\n"
           "Options as `lidar2d localize` (docs/localization.md): min_score (--min-score), ambiguity_ratio\n"
           "(--ambiguity), ambiguity_nats_per_point (--ambiguity-nats), unconfident_nats_per_point\n"
           "(--unconfident-nats), budget_ms (--budget-ms), max_regions\n"
           "(--regions), profile_candidates (--profile-candidates), max_candidates (--prescored),\n"
           "fallback_branch_and_bound (--fallback), threads (1: all on the calling thread); a bad one raises\n"
           "lidar2d.Error naming it.")
      .def(
          "localize",
          [](const localization::Localizer& self, const py::handle& scan) {
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
          },
          py::arg("scan"),
          "Localizes one scan (a Frame, or (N, 2) points in the robot frame) on its own. Returns a dict:\n"
          "declined, reason, pose (SE2 T_world_robot or None), score in [0, 1], alternatives [(SE2, score)]\n"
          "(distinct poses scoring at least min_score), candidates [(SE2, score, fit)] (every verified distinct\n"
          "pose, ranked by fit, whatever its score: `localize --candidates`), num_points, num_lines,\n"
          "num_candidates, num_regions, used_fallback, seconds.");

  const localization::TrackerOptions defaults;
  py::class_<localization::Tracker>(
      m, "Tracker",
      "Localization in a known map scan by scan, without an initial pose (`lidar2d track`): global\n"
      "localization places the first scans, then each scan is tracked from the odometry's step (or\n"
      "constant velocity) and checked against the map; a robot carried elsewhere is found again.")
      .def(py::init([](const OccupancyImage& map, const py::handle& database, double min_track_score,
                       double min_global_score, std::size_t confirm_fixes, double sure_fix_score,
                       std::size_t max_lost_scans, std::size_t confirm_fixes_against_odometry,
                       double correction_score_slope, double slide_score_margin, double prior_score_margin,
                       std::size_t recent_scans, double max_beyond_map_m, double max_degenerate_path_m,
                       double max_speed_m_per_s, bool learn_odometry_scale) {
             localization::TrackerOptions o;
             o.min_track_score = min_track_score;
             o.min_global_score = min_global_score;
             o.confirm_fixes = confirm_fixes;
             o.sure_fix_score = sure_fix_score;
             o.max_lost_scans = max_lost_scans;
             o.confirm_fixes_against_odometry = confirm_fixes_against_odometry;
             o.correction_score_slope = correction_score_slope;
             o.slide_score_margin = slide_score_margin;
             o.prior_score_margin = prior_score_margin;
             o.recent_scans = recent_scans;
             o.max_beyond_map_m = max_beyond_map_m;
             o.max_degenerate_path_m = max_degenerate_path_m;
             o.max_speed_m_per_s = max_speed_m_per_s;
             o.learn_odometry_scale = learn_odometry_scale;
             o.validate();  // before the database is taken over, so a bad option leaves it usable
             std::optional<localization::Database> db = takeDatabase(database);
             py::gil_scoped_release release;
             return std::make_unique<localization::Tracker>(map, std::move(db), o);
           }),
           py::arg("map"), py::arg("database") = py::none(), py::kw_only(),
           py::arg("min_track_score") = defaults.min_track_score,
           py::arg("min_global_score") = defaults.min_global_score, py::arg("confirm_fixes") = defaults.confirm_fixes,
           py::arg("sure_fix_score") = defaults.sure_fix_score, py::arg("max_lost_scans") = defaults.max_lost_scans,
           py::arg("confirm_fixes_against_odometry") = defaults.confirm_fixes_against_odometry,
           py::arg("correction_score_slope") = defaults.correction_score_slope,
           py::arg("slide_score_margin") = defaults.slide_score_margin,
           py::arg("prior_score_margin") = defaults.prior_score_margin, py::arg("recent_scans") = defaults.recent_scans,
           py::arg("max_beyond_map_m") = defaults.max_beyond_map_m,
           py::arg("max_degenerate_path_m") = defaults.max_degenerate_path_m,
           py::arg("max_speed_m_per_s") = defaults.max_speed_m_per_s,
           py::arg("learn_odometry_scale") = defaults.learn_odometry_scale,
           "map: a MapImage; database as for Localizer. Options as `lidar2d track` (docs/localization.md;\n"
           "recent_scans: --recent-scans, max_beyond_map_m: --max-beyond-map,\n"
           "max_degenerate_path_m: --max-degenerate-path, max_speed_m_per_s: --max-speed,\n"
           "learn_odometry_scale=False: --no-odometry-scale);\n"
           "bad options or a database of another map raise lidar2d.Error.")
      .def(
          "add",
          [](localization::Tracker& self, const Frame& frame) {
            localization::TrackResult r;
            {
              py::gil_scoped_release release;
              r = self.add(frame);
            }
            py::dict d;
            d["status"] = localization::toString(r.status);
            d["pose"] = r.status == localization::TrackStatus::kLost ? py::none() : poseOrNone(r.T_world_robot);
            d["score"] = r.score;
            d["relocalized"] = r.relocalized;
            d["beyond_map"] = r.beyond_map;
            d["odometry_frozen"] = r.odometry_frozen;
            d["reason"] = r.reason;
            d["iterations"] = r.iterations;
            d["track_seconds"] = r.track_ms / 1e3;
            d["global_seconds"] = r.global_ms / 1e3;
            return d;
          },
          py::arg("frame"),
          "Places the next scan (its odometry, when this and the previous frame have it, gives the\n"
          "prior's step; its truth is ignored). Returns a dict: status ('global', 'tracking' or 'lost'),\n"
          "pose (SE2 T_world_robot, None when lost), score in [0, 1], relocalized (a global fix after an\n"
          "earlier one), beyond_map (tracked on the recent scans where the map explains too little),\n"
          "odometry_frozen (the odometry reads one pose while the robot moves: not used), reason (why a "
          "scan was not tracked), iterations, track_seconds, global_seconds.")
      .def("reset", &localization::Tracker::reset, "Forgets the pose: the next scan is placed by global localization.")
      .def_property_readonly("odometry_scale", &localization::Tracker::odometryScale,
                             "the factor the odometry's distances are scaled by (1 until 5 m of chords between "
                             "scans the map pins are measured, or with learn_odometry_scale=False)");
}

}  // namespace lidar2d::python
