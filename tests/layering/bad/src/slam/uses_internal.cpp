// Fixture: another module's internal header.
#include "src/registration/internal/helper.hpp"
#include "lidar2d/registration/icp.hpp"
