#include "lidar2d/localization/mirror_check.hpp"

#include <algorithm>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/laser_mount.hpp"

namespace lidar2d::localization {

MirrorCheck::MirrorCheck(std::size_t max_samples) : max_samples_(max_samples) {
  if (max_samples_ == 0)
    throw invalidArgument("MirrorCheck needs at least one sample", ErrorLocation("", 0, "max_samples"));
}

void MirrorCheck::add(const LaserScan& scan, const SE2& T_robot_laser) {
  const std::size_t k = added_++;
  if (k % stride_ != 0) return;
  kept_.push_back({scan, T_robot_laser});
  if (kept_.size() < 2 * max_samples_) return;
  // Full: keep every other one (those at multiples of twice the stride), so the sample stays even.
  std::size_t w = 0;
  for (std::size_t i = 0; i < kept_.size(); i += 2, ++w)
    if (w != i) kept_[w] = std::move(kept_[i]);
  kept_.resize(w);
  stride_ *= 2;
}

MirrorCheckResult MirrorCheck::run(const Localizer& localizer) const {
  MirrorCheckResult r;
  const std::size_t n = std::min(kept_.size(), max_samples_);
  // The mirror image as an upside-down laser's scan is read: beams reversed, angles negated.
  const LaserMount mirror = LaserMount::planar(SE2(), true);
  for (std::size_t i = 0; i < n; ++i) {
    const Sample& s = kept_[i * kept_.size() / n];
    ++r.tried;
    if (!localizer.localize(mirror.project(s.scan), s.T_robot_laser).declined) ++r.placed;
  }
  return r;
}

std::optional<MirrorCheckResult> MirrorCheck::runIfFewPlaced(const Localizer& localizer, std::size_t scans) const {
  const std::size_t placed = scans > added_ ? scans - added_ : 0;
  if (!(static_cast<double>(placed) < kCheckBelow * static_cast<double>(scans)) ||
      added_ < MirrorCheckResult::kMinTried)
    return std::nullopt;
  return run(localizer);
}

}  // namespace lidar2d::localization
