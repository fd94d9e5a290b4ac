#pragma once
// The CLI's progress display: one line on stderr, redrawn in place, shown on a terminal only.

#include <chrono>
#include <cstddef>
#include <iostream>
#include <string>

namespace lidar2d::cli {

/// A line of progress on stderr, enabled unless `quiet` or stderr is not a terminal (then every
/// call does nothing). Redrawn at most ten times a second. The line is erased by clear() or when
/// the object goes out of scope (so that an error's message starts on a clean line), or kept by
/// finish().
class ProgressLine {
 public:
  explicit ProgressLine(bool quiet);
  ~ProgressLine() { clear(); }
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;

  bool enabled() const { return enabled_; }
  /// Draws `text()` (a callable returning the line, only called when drawing) unless the last draw
  /// is under 100 ms old; `force` draws regardless.
  template <class Text>
  void update(Text&& text, bool force = false) {
    if (!enabled_) return;
    const auto now = std::chrono::steady_clock::now();
    if (!force && drawn_ && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    drawn_ = true;
    std::cerr << '\r' << text() << std::flush;
  }
  /// Erases the line.
  void clear();
  /// Leaves the last line drawn on screen and moves to the next line.
  void finish();

 private:
  bool enabled_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_{};
};

/// `done` of `total` (> 0) as a bar of `width` characters and a percentage, capped at 100%:
/// "[#########.....................]  30%".
std::string progressBar(std::size_t done, std::size_t total, int width = 30);

}  // namespace lidar2d::cli
