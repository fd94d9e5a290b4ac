#pragma once
// One ICP problem, a source point set against a prepared target: the correspondence search and the
// normal equations (icp_problem.cpp), shared by the Gauss-Newton solver (icp_gauss_newton.cpp) and
// the Ceres solver (icp_ceres.cpp), and what both do around their iterations.

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "lidar2d/registration/icp.hpp"
#include "lidar2d/registration/result.hpp"
#include "src/registration/internal/icp_target.hpp"

namespace lidar2d::registration::internal {

struct Pair {
  std::uint32_t src = 0;
  std::uint32_t tgt = 0;
  double key = 0.0;  // squared residual used for trimming [m^2]
};

// Normal equations of one linearisation (Gauss-Newton: H = sum w J^T J, g = sum w J^T r).
struct Linearisation {
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  double cost = 0.0;  // 0.5 * sum rho(r^2) [m^2]
  double wr2 = 0.0;   // sum w r^2 [m^2]
  std::size_t residuals = 0;
  // H without point-to-line's two-point lines (with the cost only): the information reported.
  Eigen::Matrix3d H_info = Eigen::Matrix3d::Zero();
};

class Icp {
 public:
  // Point-to-line: one residual's data, a source point, its target point and the line's normal.
  struct LineTerm {
    double px, py, mx, my, nx, ny;
  };

  Icp(const IcpTarget& target, const Points2& source, const IcpOptions& o);

  // Pairs each transformed source point with its nearest target point; rejects by distance (and,
  // for point-to-line, target points without a line), then keeps the closest fraction.
  void findPairs(const SE2& T);

  // Fingerprint of the pairs of the last findPairs.
  std::uint64_t setHash() const { return set_hash_; }

  // The normal equations at T; the cost and sum w r^2 only `with_cost` (the final linearisation:
  // the Gauss-Newton steps need H and g alone).
  Linearisation linearise(const SE2& T, bool with_cost = true) const;

  const std::vector<Pair>& pairs() const { return pairs_; }
  // Point-to-line: the residuals of the last search (a point pair gives two, its x and y offsets).
  const std::vector<LineTerm>& lines() const { return lines_; }
  const Points2& source() const { return src_; }
  const IcpTarget::Impl& target() const { return tgt_; }

 private:
  template <class Weight>
  Linearisation lineariseWith(const SE2& T, bool with_cost, Weight&& weight) const;

  const IcpTarget::Impl& tgt_;  // (the search structures themselves: the search inlines)
  const Points2& src_;
  const IcpOptions& o_;
  const bool p2l_;
  const bool two_point_;  // point-to-line: IcpOptions::two_point_lines, and the target has them
  const double point_w_;  // point-to-line: weight of the point pairs (0: none)
  std::vector<Pair> pairs_;
  // Point-to-line: per source point, the normal of its pair's line in the last search ((0, 0): a
  // point pair), the target point's own or a two-point line's.
  Points2 normal_;
  // A pair's point-to-line data, gathered once per search for the linearisations that follow:
  // source point p, target point m and the normal n of its line; r(T) = n^T (T p - m).
  std::vector<LineTerm> lines_;  // per kept pair, in the order of pairs_, two-point lines last
  std::size_t info_lines_ = 0;   // lines_ before the two-point lines
  // Point-to-line: per source point, whether its pair's line in the last search is a two-point line.
  std::vector<std::uint8_t> via_corner_;
  std::vector<std::size_t> last_match_;  // per source point: its nearest target point last time, or size()
  static constexpr std::uint32_t kNoHint = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> hints_;  // per source point: its search hint (IcpTarget::nearestWithin)
  std::uint64_t set_hash_ = 0;

  static std::uint64_t mix(std::uint64_t z) {  // splitmix64 finaliser
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
};

// The fingerprints of the last few sets of pairs: when a search returns a set already solved, the
// iteration has reached a fixed point of the correspondence search (the same set again) or a cycle
// through a few sets; searching on cannot settle further, so the loop stops there.
class PairSetHistory {
 public:
  // True when `h` is one of the remembered fingerprints; remembers it either way.
  bool seenBefore(std::uint64_t h) {
    const bool seen = std::find(hashes_.begin(), hashes_.begin() + static_cast<std::ptrdiff_t>(count_), h) !=
                      hashes_.begin() + static_cast<std::ptrdiff_t>(count_);
    hashes_[next_] = h;
    next_ = (next_ + 1) % hashes_.size();
    count_ = std::min(count_ + 1, hashes_.size());
    return seen;
  }

 private:
  std::array<std::uint64_t, 8> hashes_{};
  std::size_t next_ = 0, count_ = 0;
};

// A failed match: the initial guess (the identity when it is not finite), not converged.
Result failure(const SE2& init, Status status, std::string message);
// The failure of iteration `iteration`, whose search kept `pairs` pairs (fewer than o.min_inliers).
Result tooFewInliers(const SE2& init, int iteration, std::size_t pairs, const IcpOptions& o);
// True when the step dx = (x, y, theta) is below both convergence thresholds of `o`.
inline bool smallStep(const Eigen::Vector3d& dx, const IcpOptions& o) {
  return std::hypot(dx.x(), dx.y()) < o.translationEps() && std::abs(dx.z()) < o.rotationEps();
}
// The result at the final estimate T after `iterations` iterations: status and message, and the
// information, covariance, cost and inliers of a last correspondence search and linearisation at
// T (so that they describe the returned pose and do not depend on the solver's path to it).
Result finalResult(Icp& icp, const SE2& T, int iterations, bool converged, const IcpOptions& o);

// The solvers: outer iterations of correspondence searches from `init`, each followed by a few
// steps on its set of pairs (IcpOptions::gn_inner_iterations, ceres_max_inner_iterations).
Result runGaussNewton(Icp& icp, const SE2& init, const IcpOptions& o);
Result runCeres(Icp& icp, const SE2& init, const IcpOptions& o);

}  // namespace lidar2d::registration::internal
