// The extension module lidar2d._lidar2d: exceptions, argument conversions, and the core types
// (SE2, Frame); each area registers itself from its own file (bindings.hpp).
#include <fmt/format.h>

#include <cmath>

#include "bindings.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/core/frame.hpp"
#include "lidar2d/io/trajectory.hpp"

namespace lidar2d::python {

namespace {
// lidar2d.Error (a ValueError) and lidar2d.IoError (also an OSError), created once at import.
PyObject* g_error = nullptr;
PyObject* g_io_error = nullptr;

const char* kindName(ErrorKind k) {
  switch (k) {
    case ErrorKind::kBadInput: return "bad_input";
    case ErrorKind::kIo: return "io";
    case ErrorKind::kInvalidArgument: return "invalid_argument";
    case ErrorKind::kUnsupported: return "unsupported";
  }
  return "unknown";
}

// Raises the Python counterpart of a lidar2d::Error with the C++ message and its location as
// attributes (kind, file, line, field).
void raiseError(const Error& e) {
  PyObject* type = e.kind() == ErrorKind::kIo ? g_io_error : g_error;
  py::object exc = py::reinterpret_steal<py::object>(PyObject_CallFunction(type, "s", e.what()));
  if (!exc) return;  // the call set its own Python error
  exc.attr("kind") = kindName(e.kind());
  exc.attr("file") = e.where().file;
  exc.attr("line") = e.where().line;
  exc.attr("field") = e.where().field;
  PyErr_SetObject(type, exc.ptr());
}

bool isRealDtype(const py::dtype& dt) { return dt.kind() == 'f' || dt.kind() == 'i' || dt.kind() == 'u'; }

// A NumPy array of `obj` (a list is converted), refusing non-numeric dtypes.
py::array asRealArray(const py::handle& obj, const char* what) {
  py::array a;
  try {
    a = py::array::ensure(obj);
  } catch (const py::error_already_set&) {
  }
  if (!a) throw py::type_error(fmt::format("{}: expected an array of numbers", what));
  if (!isRealDtype(a.dtype()))
    throw py::type_error(fmt::format("{}: expected real numbers, got dtype {}", what,
                                     py::str(a.dtype()).cast<std::string>()));
  return a;
}

std::string shapeOf(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) s += fmt::format("{}{}", i ? ", " : "", a.shape(i));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

SE2 checkedPose(double x, double y, double theta, const char* what) {
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(theta))
    throw py::value_error(fmt::format("{}: pose ({}, {}, {}) is not finite", what, x, y, theta));
  return SE2(x, y, theta);
}
}  // namespace

std::vector<double> toDoubles(const py::handle& obj, const char* what) {
  const py::array a = asRealArray(obj, what);
  if (a.ndim() != 1) throw py::value_error(fmt::format("{}: expected a 1-D array, got shape {}", what, shapeOf(a)));
  const auto d = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
  return std::vector<double>(d.data(), d.data() + d.size());
}

Points2 toPoints(const py::handle& obj, const char* what) {
  const py::array a = asRealArray(obj, what);
  if (a.ndim() != 2 || a.shape(1) != 2)
    throw py::value_error(fmt::format("{}: expected an (N, 2) array of points, got shape {}", what, shapeOf(a)));
  const auto d = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
  Points2 out(static_cast<std::size_t>(d.shape(0)));
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = {d.data()[2 * i], d.data()[2 * i + 1]};
  return out;
}

py::array_t<double> fromPoints(const Points2& points) {
  py::array_t<double> a({static_cast<py::ssize_t>(points.size()), py::ssize_t{2}});
  double* p = a.mutable_data();
  for (const auto& q : points) {
    *p++ = q.x();
    *p++ = q.y();
  }
  return a;
}

SE2 toPose(const py::handle& obj, const char* what) {
  if (py::isinstance<SE2>(obj)) return obj.cast<SE2>();  // SE2 objects are finite by construction
  const auto v = toDoubles(obj, what);
  if (v.size() != 3) throw py::value_error(fmt::format("{}: expected an SE2 or (x, y, theta), got {} values", what, v.size()));
  return checkedPose(v[0], v[1], v[2], what);
}

py::array_t<double> fromMatrix3(const Eigen::Matrix3d& m) {
  py::array_t<double> a({3, 3});
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) a.mutable_at(r, c) = m(r, c);
  return a;
}

Trajectory toTrajectory(const py::handle& obj, const char* what) {
  if (py::isinstance<py::str>(obj) || py::hasattr(obj, "__fspath__"))
    return io::readTrajectory(py::str(obj).cast<std::string>());
  Trajectory out;
  if (py::isinstance<py::array>(obj)) {
    const py::array a = asRealArray(obj, what);
    if (a.ndim() != 2 || a.shape(1) != 4)
      throw py::value_error(fmt::format("{}: expected an (N, 4) array of t x y theta rows, got shape {}", what, shapeOf(a)));
    const auto d = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
    for (py::ssize_t i = 0; i < d.shape(0); ++i) {
      const double* r = d.data() + 4 * i;
      if (!std::isfinite(r[0])) throw py::value_error(fmt::format("{}: row {}: time is not finite", what, i));
      out.push_back({r[0], checkedPose(r[1], r[2], r[3], fmt::format("{}: row {}", what, i).c_str())});
    }
    return out;
  }
  for (const py::handle item : obj) {
    const auto pair = item.cast<py::sequence>();
    if (pair.size() != 2) throw py::value_error(fmt::format("{}: expected (t, SE2) pairs", what));
    const double t = pair[0].cast<double>();
    if (!std::isfinite(t)) throw py::value_error(fmt::format("{}: time is not finite", what));
    out.push_back({t, toPose(pair[1], what)});
  }
  return out;
}

py::array_t<double> fromTrajectory(const Trajectory& trajectory) {
  py::array_t<double> a({static_cast<py::ssize_t>(trajectory.size()), py::ssize_t{4}});
  double* p = a.mutable_data();
  for (const auto& s : trajectory) {
    *p++ = s.time;
    *p++ = s.pose.x();
    *p++ = s.pose.y();
    *p++ = s.pose.theta();
  }
  return a;
}

void bindCore(py::module_& m) {
  py::class_<SE2>(m, "SE2",
                  "A rigid transform of the plane: rotation theta [rad], then translation (x, y) [m].\n"
                  "T_a_b maps points of frame b to frame a; poses compose as T_a_c = T_a_b * T_b_c.\n"
                  "theta is wrapped to (-pi, pi]; non-finite values raise ValueError.")
      .def(py::init([](double x, double y, double theta) { return checkedPose(x, y, theta, "SE2"); }),
           py::arg("x") = 0.0, py::arg("y") = 0.0, py::arg("theta") = 0.0)
      .def_property_readonly("x", &SE2::x, "translation x [m]")
      .def_property_readonly("y", &SE2::y, "translation y [m]")
      .def_property_readonly("theta", &SE2::theta, "rotation [rad], in (-pi, pi]")
      .def("inverse", &SE2::inverse, "T_b_a for T_a_b")
      .def("matrix", [](const SE2& T) { return fromMatrix3(T.matrix()); }, "homogeneous 3x3 matrix")
      .def("to_array", [](const SE2& T) { return py::array_t<double>(3, T.vector().data()); }, "array (x, y, theta)")
      .def("log", [](const SE2& T) { const Eigen::Vector3d v = T.log(); return py::array_t<double>(3, v.data()); },
           "tangent vector (rho_x, rho_y, omega)")
      .def_static("exp", [](const py::handle& xi) {
            const auto v = toDoubles(xi, "SE2.exp");
            if (v.size() != 3) throw py::value_error("SE2.exp: expected 3 values (rho_x, rho_y, omega)");
            const SE2 T = SE2::exp({v[0], v[1], v[2]});
            if (!T.isFinite()) throw py::value_error("SE2.exp: not finite");
            return T;
          }, py::arg("xi"), "pose of the tangent vector (rho_x, rho_y, omega)")
      .def("adjoint", [](const SE2& T) { return fromMatrix3(T.adjoint()); })
      .def("__mul__", [](const SE2& a, const SE2& b) { return a * b; }, py::is_operator())
      .def("__mul__", [](const SE2& T, const py::array& pts) -> py::object {
            if (pts.ndim() == 1) {
              const auto v = toDoubles(pts, "SE2 * point");
              if (v.size() != 2) throw py::value_error("SE2 * point: expected 2 values");
              const Eigen::Vector2d q = T * Eigen::Vector2d(v[0], v[1]);
              return py::array_t<double>(2, q.data());
            }
            Points2 p = toPoints(pts, "SE2 * points");
            for (auto& q : p) q = T * q;
            return fromPoints(p);
          }, py::is_operator(), "transforms a point (2,) or points (N, 2)")
      .def("is_approx", &SE2::isApprox, py::arg("other"), py::arg("tol_m") = 1e-9, py::arg("tol_rad") = 1e-9)
      .def("__eq__", [](const SE2& a, const SE2& b) { return a.x() == b.x() && a.y() == b.y() && a.theta() == b.theta(); })
      .def("__repr__", [](const SE2& T) { return fmt::format("SE2(x={:.6g}, y={:.6g}, theta={:.6g})", T.x(), T.y(), T.theta()); })
      .def(py::pickle([](const SE2& T) { return py::make_tuple(T.x(), T.y(), T.theta()); },
                      [](const py::tuple& t) { return checkedPose(t[0].cast<double>(), t[1].cast<double>(), t[2].cast<double>(), "SE2"); }));

  py::class_<Frame>(m, "Frame",
                    "One laser scan and the poses known at its time. ranges and angles are 1-D float64\n"
                    "arrays of equal length (ranges is a read-only view of the frame's data; invalid beams\n"
                    "are NaN/inf or outside (range_min, range_max)). odometry and truth are SE2 or None.")
      .def(py::init([](double stamp, const py::handle& ranges, double angle_min, double angle_increment, double range_min,
                       double range_max, std::optional<SE2> odometry, std::optional<SE2> truth,
                       std::optional<SE2> laser_pose, std::size_t index) {
             if (!std::isfinite(stamp)) throw py::value_error("Frame: stamp is not finite");
             Frame f;
             f.index = index;
             f.time = stamp;
             f.scan = LaserScan::create({.time = stamp, .angle_min = angle_min, .angle_increment = angle_increment,
                                         .range_min = range_min, .range_max = range_max,
                                         .ranges = toDoubles(ranges, "Frame ranges"), .intensities = {}});
             f.T_odom_robot = odometry;
             f.T_world_robot = truth;
             if (laser_pose) f.T_robot_laser = *laser_pose;
             return f;
           }),
           py::arg("stamp"), py::arg("ranges"), py::arg("angle_min"), py::arg("angle_increment"),
           py::arg("range_min") = 0.0, py::arg("range_max") = 30.0, py::arg("odometry") = py::none(),
           py::arg("truth") = py::none(), py::arg("laser_pose") = py::none(), py::arg("index") = 0)
      .def_readonly("index", &Frame::index, "0-based position of the scan in its log")
      .def_readonly("stamp", &Frame::time, "scan time [s]")
      .def_property_readonly("ranges", [](py::object self) {
            const Frame& f = self.cast<const Frame&>();
            py::array_t<double> a(static_cast<py::ssize_t>(f.scan.size()), f.scan.ranges().data(), self);
            a.attr("flags").attr("writeable") = false;
            return a;
          }, "ranges [m], a read-only view (no copy)")
      .def_property_readonly("angles", [](const Frame& f) {
            py::array_t<double> a(static_cast<py::ssize_t>(f.scan.size()));
            for (std::size_t i = 0; i < f.scan.size(); ++i) a.mutable_at(i) = f.scan.angle(i);
            return a;
          }, "beam angles in the laser frame [rad]")
      .def_property_readonly("valid", [](const Frame& f) {
            py::array_t<bool> a(static_cast<py::ssize_t>(f.scan.size()));
            for (std::size_t i = 0; i < f.scan.size(); ++i) a.mutable_at(i) = f.scan.isValid(i);
            return a;
          }, "per beam: a usable return")
      .def_readonly("odometry", &Frame::T_odom_robot, "wheel odometry T_odom_robot, or None")
      .def_readonly("truth", &Frame::T_world_robot, "ground truth T_world_robot, or None")
      .def_readonly("laser_pose", &Frame::T_robot_laser, "mounting T_robot_laser")
      .def_property_readonly("angle_min", [](const Frame& f) { return f.scan.angleMin(); })
      .def_property_readonly("angle_increment", [](const Frame& f) { return f.scan.angleIncrement(); })
      .def_property_readonly("range_min", [](const Frame& f) { return f.scan.rangeMin(); })
      .def_property_readonly("range_max", [](const Frame& f) { return f.scan.rangeMax(); })
      .def("points", [](const Frame& f, const std::string& frame) {
            if (frame == "robot") return fromPoints(f.scan.toPoints(f.T_robot_laser));
            if (frame == "laser") return fromPoints(f.scan.toPoints());
            throw py::value_error("Frame.points: frame must be 'robot' or 'laser'");
          }, py::arg("frame") = "robot", "endpoints of the valid beams, (N, 2) [m], in the robot or laser frame")
      .def("__len__", [](const Frame& f) { return f.scan.size(); })
      .def("__repr__", [](const Frame& f) {
            return fmt::format("Frame(index={}, stamp={:.6f}, beams={}, odometry={}, truth={})", f.index, f.time,
                               f.scan.size(), f.T_odom_robot ? "yes" : "None", f.T_world_robot ? "yes" : "None");
          });
}

}  // namespace lidar2d::python

PYBIND11_MODULE(_lidar2d, m) {
  namespace py = pybind11;
  using namespace lidar2d::python;
  m.doc() = "lidar2d: 2D LiDAR scan matching, mapping, degeneracy, global localization, SLAM, evaluation";
  m.attr("__version__") = LIDAR2D_VERSION;
  g_error = PyErr_NewExceptionWithDoc("lidar2d.Error",
                                      "Bad input or a failed call in lidar2d; the message names the file, line and "
                                      "field. Attributes: kind, file, line, field.",
                                      PyExc_ValueError, nullptr);
  py::object bases = py::make_tuple(py::handle(g_error), py::handle(PyExc_OSError));
  g_io_error = PyErr_NewExceptionWithDoc("lidar2d.IoError", "A file could not be opened, read or written.",
                                         bases.ptr(), nullptr);
  m.attr("Error") = py::handle(g_error);
  m.attr("IoError") = py::handle(g_io_error);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const lidar2d::Error& e) {
      raiseError(e);
    }
  });
  bindCore(m);
  bindIo(m);
  bindRegistration(m);
  bindMapping(m);
  bindLocalization(m);
  bindSlam(m);
  bindEval(m);
}
