// Fixture: a public header including a library-private one.
#pragma once
#include "src/core/internal/detail.hpp"
