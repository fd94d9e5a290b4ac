#pragma once
/// @file
/// Shared pieces of the Python bindings (lidar2d._lidar2d): argument checks that turn wrong NumPy
/// input into Python exceptions (TypeError for a wrong dtype, ValueError for a wrong shape or a
/// non-finite pose), and the per-area registration functions. The bindings wire the library; they
/// hold no algorithm.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/core/trajectory.hpp"

namespace lidar2d::python {
namespace py = pybind11;

/// A 1-D array of real numbers (any float or integer dtype; bool, complex, object and strings are
/// refused with TypeError naming `what`) as doubles. Copies (the library owns its vectors).
std::vector<double> toDoubles(const py::handle& obj, const char* what);
/// An (N, 2) array of real numbers as points [m]; ValueError names `what` and the shape.
Points2 toPoints(const py::handle& obj, const char* what);
/// (N, 2) float64 array of points.
py::array_t<double> fromPoints(const Points2& points);
/// A pose given as SE2 or as a 3-sequence (x, y, theta); non-finite values raise ValueError naming
/// `what`.
SE2 toPose(const py::handle& obj, const char* what);
/// A 3x3 matrix as a (3, 3) float64 array.
py::array_t<double> fromMatrix3(const Eigen::Matrix3d& m);
/// A trajectory given as a file path (read with io::readTrajectory), an (N, 4) array of
/// `t x y theta` rows, or a sequence of (t, SE2) pairs.
Trajectory toTrajectory(const py::handle& obj, const char* what);
/// (N, 4) float64 array of `t x y theta` rows.
py::array_t<double> fromTrajectory(const Trajectory& trajectory);

void bindCore(py::module_& m);
void bindIo(py::module_& m);
void bindRegistration(py::module_& m);
void bindMapping(py::module_& m);
void bindLocalization(py::module_& m);
void bindSlam(py::module_& m);
void bindEval(py::module_& m);
}  // namespace lidar2d::python
