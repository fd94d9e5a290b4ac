#include "progress.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>

namespace lidar2d::cli {

ProgressLine::ProgressLine(bool quiet) : enabled_(!quiet && ::isatty(STDERR_FILENO)) {}

void ProgressLine::clear() {
  if (drawn_) std::cerr << "\r\033[K" << std::flush;
  drawn_ = false;
}

void ProgressLine::finish() {
  if (drawn_) std::cerr << "\n" << std::flush;
  drawn_ = false;
}

std::string progressBar(std::size_t done, std::size_t total, int width) {
  const double f = std::min(1.0, static_cast<double>(done) / static_cast<double>(total));
  const int filled = static_cast<int>(width * f);
  return fmt::format("[{}{}] {:3.0f}%", std::string(filled, '#'), std::string(width - filled, '.'), 100.0 * f);
}

std::string progressText(const std::string& what, std::size_t done, std::optional<std::size_t> total, double seconds,
                         const std::string& unit) {
  const double rate = seconds > 0 ? static_cast<double>(done) / seconds : 0.0;
  std::string s = what + " ";
  if (total && *total > 0)
    s += fmt::format("{} {}/{} {}", progressBar(done, *total), done, *total, unit);
  else
    s += fmt::format("{} {}", done, unit);
  if (rate > 0) s += fmt::format(", {:.1f} {}/s", rate, unit);
  if (total && *total > done && rate > 0) {
    const auto left = static_cast<long long>(static_cast<double>(*total - done) / rate + 0.5);
    s += fmt::format(", {}:{:02d} left", left / 60, left % 60);
  }
  return s + " ";
}

}  // namespace lidar2d::cli
