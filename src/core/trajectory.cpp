#include "lidar2d/core/trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace lidar2d {

TimeIndex::TimeIndex(const Trajectory& trajectory) {
  std::vector<double> times;
  times.reserve(trajectory.size());
  for (const auto& p : trajectory) times.push_back(p.time);
  *this = TimeIndex(times);
}

TimeIndex::TimeIndex(const std::vector<double>& times) {
  order_.resize(times.size());
  std::iota(order_.begin(), order_.end(), std::size_t{0});
  // Stable: among equal times the earliest pose in file order comes first.
  std::stable_sort(order_.begin(), order_.end(), [&](std::size_t a, std::size_t b) { return times[a] < times[b]; });
  times_.reserve(times.size());
  for (std::size_t i : order_) times_.push_back(times[i]);
  for (std::size_t k = 1; k < times_.size(); ++k)
    if (times_[k] == times_[k - 1]) repeated_ = true;
}

std::optional<std::size_t> TimeIndex::nearest(double t, double max_dt) const {
  if (times_.empty() || !std::isfinite(t)) return std::nullopt;
  // First sorted time >= t; the nearest is it or its predecessor.
  const auto it = std::lower_bound(times_.begin(), times_.end(), t);
  std::size_t best = times_.size();
  double best_dt = std::numeric_limits<double>::infinity();
  if (it != times_.begin()) {
    // The first of a run of equal times, so repeated timestamps resolve to the earliest pose.
    const auto prev = std::lower_bound(times_.begin(), it, *(it - 1));
    best = static_cast<std::size_t>(prev - times_.begin());
    best_dt = t - *prev;
  }
  if (it != times_.end() && *it - t < best_dt) {
    best = static_cast<std::size_t>(it - times_.begin());
    best_dt = *it - t;
  }
  if (best == times_.size() || !(best_dt <= max_dt)) return std::nullopt;
  return order_[best];
}

}  // namespace lidar2d
