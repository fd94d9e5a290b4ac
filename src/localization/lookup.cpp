// The descriptor lookup of the localizer: the vote of line pairs (voteLinePairs) and the
// candidates of the range profiles (internal::profileCandidates).

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

#include "lidar2d/localization/localizer.hpp"
#include "src/localization/internal/database_index.hpp"

namespace lidar2d::localization {

using internal::kPi;
using internal::kTwoPi;
using internal::sectorOf;
using internal::wrapTwoPi;

std::vector<PoseVote> voteLinePairs(const Database& database, const std::vector<Line>& lines, const LocalizerOptions& o,
                                    std::size_t max_bins, std::size_t* num_hits) {
  const DatabaseOptions& dbo = database.options();
  const Database::Impl& db = database.impl();
  struct Bin {
    double votes = 0;
    std::uint32_t stamp = 0xffffffffu;
    double sx = 0, sy = 0, sc = 0, ss = 0;
    int n = 0;
  };
  std::unordered_map<std::uint64_t, Bin> bins;
  bins.reserve(4096);
  const double k = dbo.key_angle_scale_m_per_rad;
  const double min_sin = std::sin(std::max(0.0, dbo.min_pair_angle_rad - o.key_radius_m / k));
  const float r2 = static_cast<float>(o.key_radius_m * o.key_radius_m);
  std::vector<std::uint32_t> hits;
  std::uint32_t stamp = 0;
  if (!db.pairs.empty()) {
    for (std::size_t i = 0; i < lines.size(); ++i)
      for (std::size_t j = 0; j < lines.size(); ++j) {
        if (i == j) continue;
        const Line& li = lines[i];
        const Line& lj = lines[j];
        const double rel = wrapTwoPi(lj.normal_angle - li.normal_angle);
        if (std::abs(std::sin(rel)) < min_sin) continue;
        ++stamp;
        for (const double shift : {0.0, -kTwoPi, kTwoPi}) {
          const double ka = k * (rel + shift);
          if (shift != 0.0 && (ka < -o.key_radius_m || ka > k * kTwoPi + o.key_radius_m)) continue;
          const float q[3] = {static_cast<float>(li.distance), static_cast<float>(lj.distance), static_cast<float>(ka)};
          hits.clear();
          db.tree.radiusSearch(db.pairs, db.key_scale, q, r2,
                               [&hits](std::size_t h) { hits.push_back(static_cast<std::uint32_t>(h)); });
          if (num_hits) *num_hits += hits.size();
          for (const std::uint32_t h : hits) {
            const internal::Pair& pr = db.pairs[h];
            const Database::LineFeature& ma = db.lines[pr.ref];
            const Database::LineFeature& mb = db.lines[pr.ref + pr.other_delta];
            const Database::Position& pos = db.positions[db.line_position[pr.ref]];
            // theta: map normal = scan normal + theta, averaged over the two lines.
            const double th_a = angleDiff(ma.normal_angle, li.normal_angle);
            const double th_b = angleDiff(mb.normal_angle, lj.normal_angle);
            const double theta = wrapAngle(th_a + 0.5 * angleDiff(th_b, th_a));
            // Translation: n_a . t = c_a - d_i and n_b . t = c_b - d_j (c = n . p + d, the map line).
            const Eigen::Vector2d na(std::cos(ma.normal_angle), std::sin(ma.normal_angle));
            const Eigen::Vector2d nb(std::cos(mb.normal_angle), std::sin(mb.normal_angle));
            const Eigen::Vector2d p(pos.x, pos.y);
            const double ra = na.dot(p) + ma.distance - li.distance;
            const double rb = nb.dot(p) + mb.distance - lj.distance;
            const double det = na.x() * nb.y() - na.y() * nb.x();
            if (std::abs(det) < 1e-3) continue;
            const double tx = (ra * nb.y() - na.y() * rb) / det;
            const double ty = (na.x() * rb - ra * nb.x()) / det;
            const auto bx = static_cast<std::int64_t>(std::floor(tx / o.vote_bin_m));
            const auto by = static_cast<std::int64_t>(std::floor(ty / o.vote_bin_m));
            const auto bt = static_cast<std::int64_t>(std::floor((theta + kPi) / o.vote_bin_rad));
            const std::uint64_t key = (static_cast<std::uint64_t>(bx + (1 << 20)) & 0x1fffff) |
                                      ((static_cast<std::uint64_t>(by + (1 << 20)) & 0x1fffff) << 21) |
                                      ((static_cast<std::uint64_t>(bt) & 0x3fffff) << 42);
            Bin& b = bins[key];
            b.sx += tx;
            b.sy += ty;
            b.sc += std::cos(theta);
            b.ss += std::sin(theta);
            ++b.n;
            if (b.stamp != stamp) {  // one vote per scan pair and bin
              b.stamp = stamp;
              b.votes += 1.0;
            }
          }
        }
      }
  }
  std::vector<std::pair<double, const Bin*>> ranked;
  ranked.reserve(bins.size());
  for (const auto& [key, b] : bins) ranked.push_back({b.votes, &b});
  const std::size_t n_cand = std::min(max_bins, ranked.size());
  std::partial_sort(ranked.begin(), ranked.begin() + static_cast<std::ptrdiff_t>(n_cand), ranked.end(),
                    [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<PoseVote> out;
  out.reserve(n_cand);
  for (std::size_t c = 0; c < n_cand; ++c) {
    const Bin& b = *ranked[c].second;
    out.push_back({SE2(b.sx / b.n, b.sy / b.n, std::atan2(b.ss, b.sc)), b.votes, static_cast<std::size_t>(b.n)});
  }
  return out;
}

namespace {

// A sector of the scan's range profile: its nearest point's range and the mismatch scale.
struct Observed {
  std::size_t bin;
  float range, inv_scale;
};

std::vector<Observed> observedSectors(const Points2& pts, const Eigen::Vector2d& sensor, std::size_t bins) {
  std::vector<float> q(bins, std::numeric_limits<float>::infinity());
  for (const auto& p : pts) {
    const Eigen::Vector2d v = p - sensor;
    const double r = v.norm();
    if (!(r > 0) || !std::isfinite(r)) continue;
    float& nearest = q[sectorOf(std::atan2(v.y(), v.x()), bins)];
    nearest = std::min(nearest, static_cast<float>(r));
  }
  std::vector<Observed> seen;
  for (std::size_t b = 0; b < bins; ++b)
    if (std::isfinite(q[b])) seen.push_back({b, q[b], 1.0f / (0.3f + 0.1f * q[b])});
  return seen;
}

// Lowest mismatch over all turns of one profile, and that turn.
std::pair<float, std::size_t> bestTurn(const float* profile, std::size_t bins, const std::vector<Observed>& seen,
                                       std::vector<float>& cost) {
  std::fill(cost.begin(), cost.begin() + static_cast<std::ptrdiff_t>(bins), 0.0f);
  for (const Observed& o : seen) {
    // Robot sector b at turn t is world sector (b + t) mod bins: two contiguous runs of turns.
    const std::size_t wrap = bins - o.bin;
    const float* d = profile + o.bin;
    for (std::size_t t = 0; t < wrap; ++t) cost[t] += std::min(std::abs(o.range - d[t]) * o.inv_scale, 1.0f);
    for (std::size_t t = wrap; t < bins; ++t)
      cost[t] += std::min(std::abs(o.range - profile[t - wrap]) * o.inv_scale, 1.0f);
  }
  const auto it = std::min_element(cost.begin(), cost.begin() + static_cast<std::ptrdiff_t>(bins));
  return {*it, static_cast<std::size_t>(it - cost.begin())};
}

}  // namespace

namespace internal {

// Candidates from the range profiles: the scan's profile (its nearest point in each sector of the
// robot frame, seen from the sensor) against every position's profile turned by each whole number
// of sectors. Per sector the mismatch |r_scan - r_map| / (0.3 m + 0.1 r_scan) counts, at most 1
// (clutter, open doors, a grid position 0.1 m off); sectors without a scan point (outside the
// field of view, no return) do not count. Returns the `k` positions with the lowest total, each
// at its best turn. Two passes: every position at a coarser angular resolution (the nearest
// obstacle of each 3, else 2, sectors), then the best 32 k positions at full resolution. Brute force over the
// positions (vectorised; about 2 M operations for the 7000 positions of a building's database).
std::vector<PoseVote> profileCandidates(const Database& database, const Points2& pts, const Eigen::Vector2d& sensor,
                                        std::size_t k) {
  const Database::Impl& db = database.impl();
  if (k == 0 || db.profiles.empty()) return {};
  const auto B = static_cast<std::size_t>(db.options.profile_bins);
  const std::size_t C = B / db.coarse_factor;
  const std::vector<Observed> fine = observedSectors(pts, sensor, B);
  const std::vector<Observed> coarse = observedSectors(pts, sensor, C);
  if (fine.size() < std::max<std::size_t>(4, B / 16)) return {};  // too little of the circle seen
  const std::size_t P = db.positions.size();
  std::vector<float> cost(B);
  std::vector<std::pair<float, std::size_t>> ranked(P);  // (cost, position)
  for (std::size_t p = 0; p < P; ++p) ranked[p] = {bestTurn(db.coarse.data() + p * C, C, coarse, cost).first, p};
  const std::size_t shortlist = std::min(P, 32 * k);
  std::partial_sort(ranked.begin(), ranked.begin() + static_cast<std::ptrdiff_t>(shortlist), ranked.end());
  std::vector<std::pair<float, std::size_t>> best(shortlist);  // (cost, position * B + turn)
  for (std::size_t c = 0; c < shortlist; ++c) {
    const std::size_t p = ranked[c].second;
    const auto [v, turn] = bestTurn(db.profiles.data() + p * B, B, fine, cost);
    best[c] = {v, p * B + turn};
  }
  const std::size_t n = std::min(k, shortlist);
  std::partial_sort(best.begin(), best.begin() + static_cast<std::ptrdiff_t>(n), best.end());
  std::vector<PoseVote> out;
  const double w = kTwoPi / static_cast<double>(B);
  for (std::size_t c = 0; c < n; ++c) {
    const std::size_t p = best[c].second / B, turn = best[c].second % B;
    const double theta = wrapAngle(static_cast<double>(turn) * w);
    const Eigen::Vector2d t = Eigen::Vector2d(db.positions[p].x, db.positions[p].y) - SE2(0, 0, theta) * sensor;
    out.push_back({SE2(t.x(), t.y(), theta), 0.0, 0});
  }
  return out;
}

}  // namespace internal
}  // namespace lidar2d::localization
