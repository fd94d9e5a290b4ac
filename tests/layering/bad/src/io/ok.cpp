// Fixture: a cycle-free io file using only core.
#include "lidar2d/core/se2.hpp"
