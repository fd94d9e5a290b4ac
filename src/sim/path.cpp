#include "lidar2d/sim/path.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "lidar2d/core/error.hpp"

namespace lidar2d::sim {
namespace {

// One piece of the path: a line, an arc of curvature `kappa`, or a turn on the spot.
struct Piece {
  enum class Kind { kLine, kArc, kTurn } kind = Kind::kLine;
  Eigen::Vector2d start = Eigen::Vector2d::Zero();
  double heading = 0.0;   // at the start [rad]
  double length = 0.0;    // [m] (lines, arcs)
  double kappa = 0.0;     // signed curvature [1/m] (arcs)
  double turn = 0.0;      // signed rotation [rad] (turns)
  double duration = 0.0;  // [s]

  SE2 at(double t, const PathOptions& o) const {
    switch (kind) {
      case Kind::kLine: {
        const double s = std::min(t * o.speed_mps, length);
        return {start + s * Eigen::Vector2d(std::cos(heading), std::sin(heading)), heading};
      }
      case Kind::kArc: {
        const double s = std::min(t * o.speed_mps, length);
        const double h = heading + kappa * s;
        return {start.x() + (std::sin(h) - std::sin(heading)) / kappa,
                start.y() - (std::cos(h) - std::cos(heading)) / kappa, h};
      }
      case Kind::kTurn: {
        const double a = std::min(t * o.turn_rate_radps, std::abs(turn));
        return {start, heading + std::copysign(a, turn)};
      }
    }
    return {};
  }
};

double cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }

std::vector<Piece> buildPieces(const std::vector<Eigen::Vector2d>& w, const PathOptions& o) {
  const std::size_t n = w.size();
  std::vector<Eigen::Vector2d> dir(n - 1);
  std::vector<double> len(n - 1);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    len[i] = (w[i + 1] - w[i]).norm();
    dir[i] = (w[i + 1] - w[i]) / len[i];
  }
  // Per interior vertex: signed turn angle, fillet tangent length (0: none or turn on the spot).
  std::vector<double> phi(n, 0.0), tangent(n, 0.0);
  for (std::size_t i = 1; i + 1 < n; ++i) {
    phi[i] = std::atan2(cross(dir[i - 1], dir[i]), dir[i - 1].dot(dir[i]));
    const double a = std::abs(phi[i]);
    if (a < 1e-12 || a > o.max_fillet_turn_rad) continue;
    tangent[i] = std::min(o.turn_radius_m * std::tan(a / 2), 0.45 * std::min(len[i - 1], len[i]));
  }
  std::vector<Piece> pieces;
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const double heading = std::atan2(dir[i].y(), dir[i].x());
    Piece line;
    line.kind = Piece::Kind::kLine;
    line.start = w[i] + tangent[i] * dir[i];
    line.heading = heading;
    line.length = len[i] - tangent[i] - tangent[i + 1];
    line.duration = line.length / o.speed_mps;
    if (line.length > 0) pieces.push_back(line);
    if (i + 2 > n - 1) break;
    const std::size_t v = i + 1;  // the corner at the end of this line
    if (std::abs(phi[v]) < 1e-12) continue;
    if (tangent[v] > 0) {
      Piece arc;
      arc.kind = Piece::Kind::kArc;
      arc.start = w[v] - tangent[v] * dir[i];
      arc.heading = heading;
      const double radius = tangent[v] / std::tan(std::abs(phi[v]) / 2);
      arc.kappa = std::copysign(1.0 / radius, phi[v]);
      arc.length = radius * std::abs(phi[v]);
      arc.duration = arc.length / o.speed_mps;
      pieces.push_back(arc);
    } else {
      Piece turn;
      turn.kind = Piece::Kind::kTurn;
      turn.start = w[v];
      turn.heading = heading;
      turn.turn = phi[v];
      turn.duration = std::abs(phi[v]) / o.turn_rate_radps;
      pieces.push_back(turn);
    }
  }
  return pieces;
}

double totalDuration(const std::vector<Piece>& pieces) {
  double d = 0;
  for (const Piece& p : pieces) d += p.duration;
  return d;
}

}  // namespace

// Passes back and forth over a route that samplePath drives at most.
constexpr double kMaxPasses = 1000;

std::vector<TimedPose> samplePath(const std::vector<Eigen::Vector2d>& waypoints, const PathOptions& o,
                                  std::size_t scans) {
  const ErrorLocation where({}, 0, "path");
  if (!(o.speed_mps > 0) || !(o.turn_rate_radps > 0) || !(o.turn_radius_m > 0) || !(o.rate_hz > 0) ||
      !std::isfinite(o.speed_mps) || !std::isfinite(o.turn_rate_radps) || !std::isfinite(o.rate_hz) ||
      !std::isfinite(o.turn_radius_m) || !std::isfinite(o.start_time_s) || !(o.max_fillet_turn_rad >= 0))
    throw invalidArgument("speed, turn rate, turn radius and rate must be finite and > 0", where);
  std::vector<Eigen::Vector2d> w;
  for (const auto& p : waypoints) {
    if (!std::isfinite(p.x()) || !std::isfinite(p.y())) throw invalidArgument("waypoints must be finite", where);
    if (w.empty() || (p - w.back()).norm() > 1e-9) w.push_back(p);
  }
  if (w.size() < 2) throw invalidArgument("a path needs at least two distinct waypoints", where);

  const double dt = 1.0 / o.rate_hz;
  std::vector<Piece> pieces = buildPieces(w, o);
  if (scans > 0) {
    // Drive back and forth until the path lasts long enough for all samples.
    const double needed = static_cast<double>(scans - 1) * dt;
    // Each pass rebuilds the pieces: bounded, so that a tiny rate cannot make this loop endless.
    const double passes = needed / totalDuration(pieces);
    if (!(passes <= kMaxPasses))
      throw invalidArgument(fmt::format("{} scans at {:g} Hz last {:g} s, {:g} passes over the route at {:g} m/s: more "
                                        "than the limit of {:g} (fewer scans, a higher rate or a lower speed?)",
                                        scans, o.rate_hz, needed, passes, o.speed_mps, kMaxPasses),
                            where);
    const std::vector<Eigen::Vector2d> forward = w;
    bool reverse = true;
    while (totalDuration(pieces) < needed) {
      if (reverse)
        w.insert(w.end(), forward.rbegin() + 1, forward.rend());
      else
        w.insert(w.end(), forward.begin() + 1, forward.end());
      reverse = !reverse;
      pieces = buildPieces(w, o);
    }
  }
  const double total = totalDuration(pieces);
  const std::size_t count = scans > 0 ? scans : static_cast<std::size_t>(std::floor(total / dt + 1e-9)) + 1;
  std::vector<TimedPose> out;
  out.reserve(count);
  std::size_t k = 0;
  double piece_start = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    const double t = static_cast<double>(i) * dt;
    while (k + 1 < pieces.size() && t > piece_start + pieces[k].duration) {
      piece_start += pieces[k].duration;
      ++k;
    }
    out.push_back({o.start_time_s + t, pieces[k].at(t - piece_start, o)});
  }
  return out;
}

double pathLength(const std::vector<TimedPose>& poses) {
  double len = 0;
  for (std::size_t i = 1; i < poses.size(); ++i)
    len += (poses[i].T_world_robot.translation() - poses[i - 1].T_world_robot.translation()).norm();
  return len;
}

}  // namespace lidar2d::sim
