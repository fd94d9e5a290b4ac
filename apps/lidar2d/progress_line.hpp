#pragma once
// One line of progress on stderr, shown on a terminal only.

#include <unistd.h>

#include <chrono>
#include <iostream>
#include <string>

namespace lidar2d::cli {

/// Redrawn at most ten times a second; erased by clear() or when it goes out of scope, so that a
/// summary or an error's message that follows starts on a clean line.
class ProgressLine {
 public:
  explicit ProgressLine(bool quiet) : enabled_(!quiet && ::isatty(STDERR_FILENO)) {}
  ~ProgressLine() { clear(); }
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;

  bool enabled() const { return enabled_; }
  /// Draws `text()` (a callable returning the line) unless the last draw is under 100 ms old;
  /// `force` draws regardless.
  template <class Text>
  void update(Text&& text, bool force = false) {
    if (!enabled_) return;
    const auto now = std::chrono::steady_clock::now();
    if (!force && drawn_ && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    drawn_ = true;
    std::cerr << '\r' << text() << std::flush;
  }
  void clear() {
    if (drawn_) std::cerr << "\r\033[K" << std::flush;
    drawn_ = false;
  }

 private:
  bool enabled_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace lidar2d::cli
