// Evaluation: ATE and RPE against a reference trajectory, and Kuemmerle relation errors, as dicts
// with the keys of `lidar2d eval`'s JSON.
#include <fmt/format.h>

#include <numbers>

#include "bindings.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/trajectory.hpp"

namespace lidar2d::python {

namespace {
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

// A reference trajectory: a trajectory file, a log's truth poses, an (N, 4) array or (t, SE2) pairs.
Trajectory reference(const py::handle& obj) {
  if (!(py::isinstance<py::str>(obj) || py::hasattr(obj, "__fspath__"))) return toTrajectory(obj, "reference");
  const std::string path = py::str(obj).cast<std::string>();
  py::gil_scoped_release release;
  switch (io::detectPoseFile(path)) {
    case io::PoseFileKind::kTrajectory: return io::readTrajectory(path);
    case io::PoseFileKind::kRelations:
      throw badInput("a relations file is no trajectory (use evaluate_relations)", ErrorLocation(path));
    case io::PoseFileKind::kLog: break;
  }
  Trajectory t;
  auto source = io::openLog(path);
  while (auto f = source->next()) {
    if (!f->T_world_robot)
      throw badInput(fmt::format("scan {} has no truth pose", f->index), ErrorLocation(path, 0, "truth"));
    t.push_back({f->time, *f->T_world_robot});
  }
  return t;
}

Relations relations(const py::handle& obj) {
  if (py::isinstance<py::str>(obj) || py::hasattr(obj, "__fspath__"))
    return io::readRelations(py::str(obj).cast<std::string>());
  const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(obj);
  if (!a || a.ndim() != 2 || a.shape(1) != 5)
    throw py::value_error("relations: expected a path or an (N, 5) array t1, t2, dx, dy, dyaw");
  Relations out;
  for (py::ssize_t i = 0; i < a.shape(0); ++i) {
    const double* r = a.data() + 5 * i;
    for (int c = 0; c < 5; ++c)
      if (!std::isfinite(r[c])) throw py::value_error(fmt::format("relations: row {}: not finite", i));
    out.push_back({r[0], r[1], SE2(r[2], r[3], r[4])});
  }
  return out;
}

eval::Options options(double max_dt, bool align, double rpe_distance) {
  if (!(max_dt >= 0.0) || !std::isfinite(max_dt)) throw py::value_error("max_dt: must be a finite value >= 0");
  if (!(rpe_distance > 0.0) || !std::isfinite(rpe_distance)) throw py::value_error("rpe_distance: must be > 0");
  eval::Options o;
  o.max_dt_s = max_dt;
  o.align = align;
  o.rpe_distance_m = rpe_distance;
  return o;
}
}  // namespace

void bindEval(py::module_& m) {
  m.def("evaluate_trajectory",
        [](const py::handle& estimate, const py::handle& ref, double max_dt, bool align, double rpe_distance) {
          const auto o = options(max_dt, align, rpe_distance);
          const Trajectory est = toTrajectory(estimate, "estimate");
          const Trajectory truth = reference(ref);
          eval::TrajectoryResult r;
          {
            py::gil_scoped_release release;
            r = eval::evaluateTrajectory(est, truth, o);
          }
          const auto& ate = r.ate;
          const auto& rpe = r.rpe;
          py::dict d;
          d["association"] = eval::toString(r.association.mode);
          d["matched"] = r.association.matches.size();
          d["unmatched"] = r.association.unmatched_reference;
          d["unmatched_estimate"] = r.association.unmatched_estimate;
          d["ate_rmse_m"] = ate.trans_m.rmse;
          d["ate_mean_m"] = ate.trans_m.mean;
          d["ate_median_m"] = ate.trans_m.median;
          d["ate_std_m"] = ate.trans_m.stddev;
          d["ate_max_m"] = ate.trans_m.max;
          d["ate_rot_rmse_deg"] = ate.rot_rad.rmse * kRadToDeg;
          d["ate_unaligned_rmse_m"] = ate.unaligned_trans_m.rmse;
          d["alignment"] = ate.T_ref_est;
          d["rpe_pairs"] = rpe.trans_m.count;
          d["rpe_trans_rmse_m"] = rpe.trans_m.rmse;
          d["rpe_trans_mean_m"] = rpe.trans_m.mean;
          d["rpe_rot_rmse_deg"] = rpe.rot_rad.rmse * kRadToDeg;
          d["rpe_rot_mean_deg"] = rpe.rot_rad.mean * kRadToDeg;
          d["rpe_per_m_trans_mean"] = rpe.trans_per_m.mean;
          d["rpe_per_m_rot_mean_deg"] = rpe.rot_rad_per_m.mean * kRadToDeg;
          return d;
        },
        py::arg("estimate"), py::arg("reference"), py::arg("max_dt") = 0.1, py::arg("align") = true,
        py::arg("rpe_distance") = 1.0,
        "ATE (after the least-squares SE(2) alignment unless align=False) and RPE of an estimate against\n"
        "a reference. estimate: a trajectory file, an (N, 4) array t x y theta, or (t, SE2) pairs;\n"
        "reference: the same, or a log with truth poses. Poses are associated by index when the times\n"
        "agree, else by nearest time within max_dt [s]. Keys as in `lidar2d eval`'s JSON.");
  m.def("evaluate_relations",
        [](const py::handle& estimate, const py::handle& rel, double max_dt) {
          const auto o = options(max_dt, true, 1.0);
          const Trajectory est = toTrajectory(estimate, "estimate");
          const Relations relations_ = relations(rel);
          eval::RelationsResult r;
          {
            py::gil_scoped_release release;
            r = eval::evaluateRelations(est, relations_, o);
          }
          py::dict d;
          d["trans_mean_m"] = r.trans_m.mean;
          d["trans_std_m"] = r.trans_m.stddev;
          d["rot_mean_deg"] = r.rot_rad.mean * kRadToDeg;
          d["rot_std_deg"] = r.rot_rad.stddev * kRadToDeg;
          d["count"] = r.count;
          d["skipped"] = r.skipped;
          return d;
        },
        py::arg("estimate"), py::arg("relations"), py::arg("max_dt") = 0.1,
        "Relation errors (Kuemmerle et al. 2009) of an estimate: relations is a .relations file or an\n"
        "(N, 5) array t1, t2, dx, dy, dyaw. Keys as `lidar2d eval`'s 'relations' object, plus skipped.");
}

}  // namespace lidar2d::python
