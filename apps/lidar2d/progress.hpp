#pragma once
// The CLI's progress display: one line on stderr, redrawn in place, shown on a terminal only.

#include <chrono>
#include <cstddef>
#include <iostream>
#include <optional>
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

/// "what [bar] done/total unit, R unit/s, M:SS left" after `seconds` of work; without a known
/// `total` (CARMEN text logs, whose length is unknown until read) "what done unit, R unit/s".
std::string progressText(const std::string& what, std::size_t done, std::optional<std::size_t> total, double seconds,
                         const std::string& unit);

/// The progress of a command's main loop on a terminal: counts, rate and time left (ProgressLine's
/// rules: nothing when `quiet` or stderr is not a terminal, erased when it goes out of scope).
class RateProgress {
 public:
  RateProgress(bool quiet, std::string what, std::string unit, std::optional<std::size_t> total)
      : line_(quiet), what_(std::move(what)), unit_(std::move(unit)), total_(total) {}
  void update(std::size_t done, bool force = false) {
    line_.update(
        [&] {
          return progressText(what_, done, total_,
                              std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(), unit_);
        },
        force);
  }
  bool enabled() const { return line_.enabled(); }
  /// Sets the total once it is known (a database's positions, once they are laid out).
  void setTotal(std::size_t total) { total_ = total; }
  /// Erases the line (before a summary is printed).
  void clear() { line_.clear(); }

 private:
  ProgressLine line_;
  std::string what_, unit_;
  std::optional<std::size_t> total_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

}  // namespace lidar2d::cli
