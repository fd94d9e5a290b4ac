// Fixture: a relative include.
#include "../core/thing.hpp"
