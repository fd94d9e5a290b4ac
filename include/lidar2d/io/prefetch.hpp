#pragma once
/// @file
/// Reads a FrameSource on a background thread so that parsing (one core) overlaps with the
/// algorithm consuming the frames (the other core).

#include <memory>

#include "lidar2d/io/frame_source.hpp"

namespace lidar2d::io {

/// Wraps `source`, reading up to `capacity` frames ahead on its own thread. `next()` returns the
/// frames in the same order; an exception thrown by the wrapped reader is rethrown by the `next()`
/// call that reaches it. Destroying the wrapper stops and joins the thread.
std::unique_ptr<FrameSource> prefetch(std::unique_ptr<FrameSource> source, std::size_t capacity = 256);

}  // namespace lidar2d::io
