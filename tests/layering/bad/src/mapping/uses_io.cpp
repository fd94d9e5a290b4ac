// Fixture for the layering test: an algorithm module using io.
#include "lidar2d/mapping/grid.hpp"
#include "lidar2d/io/frame_source.hpp"
