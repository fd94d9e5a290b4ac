#include "lidar2d/eval/alignment.hpp"

#include <cmath>
#include <string>

#include "lidar2d/core/error.hpp"

namespace lidar2d::eval {

SE2 alignPoints(const std::vector<Eigen::Vector2d>& p_est, const std::vector<Eigen::Vector2d>& p_ref) {
  if (p_est.empty()) throw invalidArgument("alignPoints: no points");
  if (p_est.size() != p_ref.size())
    throw invalidArgument("alignPoints: " + std::to_string(p_est.size()) + " estimated points but " +
                          std::to_string(p_ref.size()) + " reference points");
  const double n = static_cast<double>(p_est.size());
  Eigen::Vector2d mu_est = Eigen::Vector2d::Zero(), mu_ref = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < p_est.size(); ++i) {
    mu_est += p_est[i];
    mu_ref += p_ref[i];
  }
  mu_est /= n;
  mu_ref /= n;
  // Cost in theta: sum |b - R a|^2 = const - 2 (C cos(theta) + S sin(theta)) with C = sum a.b and
  // S = sum a x b (Horn 1987 in 2D), minimised at theta = atan2(S, C).
  double c = 0.0, s = 0.0;
  for (std::size_t i = 0; i < p_est.size(); ++i) {
    const Eigen::Vector2d a = p_est[i] - mu_est;
    const Eigen::Vector2d b = p_ref[i] - mu_ref;
    c += a.dot(b);
    s += a.x() * b.y() - a.y() * b.x();
  }
  const double theta = (c == 0.0 && s == 0.0) ? 0.0 : std::atan2(s, c);
  const SE2 R(0.0, 0.0, theta);
  const Eigen::Vector2d t = mu_ref - R.rotation() * mu_est;
  return {t, theta};
}

}  // namespace lidar2d::eval
