// Scan matching: scan-to-scan and scan-to-map, every method, with the library's rich result.
#include <fmt/format.h>

#include "bindings.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/registration/matcher.hpp"

namespace lidar2d::python {

namespace {
registration::MatcherOptions matcherOptions(const std::string& method, const std::string& solver) {
  registration::MatcherOptions o;
  const auto m = registration::parseMethod(method);
  if (!m) throw py::value_error(fmt::format("method: unknown '{}' (p2p, p2l, lf, corr)", method));
  const auto s = registration::parseSolver(solver);
  if (!s) throw py::value_error(fmt::format("solver: unknown '{}' (gn, ceres)", solver));
  o.method = *m;
  o.solver = *s;
  return o;
}
}  // namespace

void bindRegistration(py::module_& m) {
  using registration::Result;
  py::class_<Result>(m, "MatchResult",
                     "What a scan match returns: the pose T_target_source (the initial guess when it failed),\n"
                     "status, iterations, inliers, cost, and the 3x3 information matrix H = J^T J of the last\n"
                     "linearisation in (x, y, theta) with the covariance estimate.")
      .def_readonly("pose", &Result::T_target_source, "estimate T_target_source")
      .def_readonly("converged", &Result::converged)
      .def_property_readonly("status", [](const Result& r) { return registration::toString(r.status); },
                             "'converged', 'max_iterations', 'too_few_points', ... (the library's names)")
      .def_readonly("iterations", &Result::iterations)
      .def_readonly("num_inliers", &Result::num_inliers)
      .def_readonly("final_cost", &Result::final_cost)
      .def_property_readonly("information", [](const Result& r) { return fromMatrix3(r.information); })
      .def_property_readonly("covariance", [](const Result& r) { return fromMatrix3(r.covariance); })
      .def_readonly("message", &Result::message)
      .def("__repr__", [](const Result& r) {
        return fmt::format("MatchResult(status={}, pose=SE2({:.4f}, {:.4f}, {:.4f}), iterations={})",
                           registration::toString(r.status), r.T_target_source.x(), r.T_target_source.y(),
                           r.T_target_source.theta(), r.iterations);
      });

  m.def("match_scans",
        [](const py::handle& target, const py::handle& source, const py::handle& init, const std::string& method,
           const std::string& solver) {
          const Points2 t = toPoints(target, "match_scans target");
          const Points2 s = toPoints(source, "match_scans source");
          const SE2 guess = init.is_none() ? SE2() : toPose(init, "match_scans init");
          const auto o = matcherOptions(method, solver);
          py::gil_scoped_release release;
          return registration::matchScans(t, s, guess, o);
        },
        py::arg("target"), py::arg("source"), py::arg("init") = py::none(), py::arg("method") = "p2l",
        py::arg("solver") = "gn",
        "Aligns source points (N, 2) to target points (M, 2) from init (T_target_source guess).\n"
        "method: 'p2p', 'p2l' (Censi's PL-ICP), 'lf' (likelihood field), 'corr' (correlative search);\n"
        "solver: 'gn' or 'ceres'. Bad points (too few, degenerate) do not raise: the result's status\n"
        "says why it failed.");
  m.def("match_scan_to_map",
        [](const OccupancyImage& map, const py::handle& points, const py::handle& init, const std::string& method,
           const std::string& solver) {
          const Points2 s = toPoints(points, "match_scan_to_map points");
          const SE2 guess = toPose(init, "match_scan_to_map init");
          const auto o = matcherOptions(method, solver);
          if (o.method != registration::Method::kLikelihoodField && o.method != registration::Method::kCorrelative)
            throw py::value_error("match_scan_to_map: method must be 'lf' or 'corr' (ICP matches point sets)");
          py::gil_scoped_release release;
          const auto target = registration::PreparedTarget::fromMap(map, o);
          return registration::matchScans(target, s, guess, o);
        },
        py::arg("map"), py::arg("points"), py::arg("init"), py::arg("method") = "lf", py::arg("solver") = "gn",
        "Aligns scan points (N, 2, robot frame) to an occupancy map (MapImage) from init (a guess of\n"
        "T_world_robot); the result's pose is T_world_robot. method: 'lf' or 'corr'.");
}

}  // namespace lidar2d::python
