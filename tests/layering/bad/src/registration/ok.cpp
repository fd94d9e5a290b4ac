// Fixture: allowed includes.
#include "src/registration/internal/helper.hpp"
#include "lidar2d/core/se2.hpp"
