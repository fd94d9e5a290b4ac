#include "lidar2d/geometry/ray_cast.hpp"

#include <algorithm>
#include <cmath>
#include <thread>

namespace lidar2d::geometry {

// The distance between the squares of cells (x, y) and (x + dx, y + dy) is
// sqrt(max(0, |dx| - 1)^2 + max(0, |dy| - 1)^2): the distance between the centres of (x, y) and the
// nearest cell of the 3 x 3 block around the other. So g is the Euclidean distance transform of the
// obstacles dilated by one cell (Felzenszwalb & Huttenlocher 2012: a column pass, then the lower
// envelope of parabolas along each row). The column distances saturate at 255 cells (one byte
// each): g is exact below 255 and the grid stores at most 254 + 1 anyway.
namespace {

// Calls f(begin, end) on `threads` consecutive parts of [0, n) in parallel.
template <class F>
void parallelRanges(std::size_t n, unsigned threads, F&& f) {
  threads = std::max(1u, std::min<unsigned>(threads, static_cast<unsigned>(std::min<std::size_t>(n, 64))));
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back([&, t] { f(n * t / threads, n * (t + 1) / threads); });
  f(std::size_t{0}, n / threads);
  for (auto& th : pool) th.join();
}

}  // namespace

ClearanceGrid::ClearanceGrid(const std::vector<std::uint8_t>& obstacle, std::int32_t width, std::int32_t height,
                             unsigned threads)
    : width_(std::max(0, width)), height_(std::max(0, height)) {
  build([&obstacle](std::size_t i) { return obstacle[i] != 0; }, threads);
}

ClearanceGrid::ClearanceGrid(std::span<const std::int8_t> values, int occupied_min, std::int32_t width,
                             std::int32_t height, unsigned threads)
    : width_(std::max(0, width)), height_(std::max(0, height)) {
  build([values, occupied_min](std::size_t i) { return values[i] >= occupied_min; }, threads);
}

template <class Obstacle>
void ClearanceGrid::build(Obstacle&& obstacle, unsigned threads) {
  const auto W = static_cast<std::size_t>(width_), H = static_cast<std::size_t>(height_);
  cells_.assign(W * H, 0);
  if (W == 0 || H == 0) return;
  // Rows dilated horizontally.
  parallelRanges(H, threads, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (std::size_t x = 0; x < W; ++x) {
        const std::size_t i = y * W + x;
        cells_[i] = obstacle(i) || (x > 0 && obstacle(i - 1)) || (x + 1 < W && obstacle(i + 1));
      }
  });
  // Column pass: vertical distance to the nearest dilated cell (vertically dilated on the fly).
  parallelRanges(W, threads, [&](std::size_t x0, std::size_t x1) { columns(x0, x1); });
  // Row pass.
  parallelRanges(H, threads, [&](std::size_t y0, std::size_t y1) { rows(obstacle, y0, y1); });
}

void ClearanceGrid::columns(std::size_t x0, std::size_t x1) {
  const auto W = static_cast<std::size_t>(width_), H = static_cast<std::size_t>(height_);
  std::vector<std::uint8_t> col(H), dist(H);
  for (std::size_t x = x0; x < x1; ++x) {
    for (std::size_t y = 0; y < H; ++y) col[y] = cells_[y * W + x];
    auto dilated = [&](std::size_t y) { return col[y] || (y > 0 && col[y - 1]) || (y + 1 < H && col[y + 1]); };
    int d = 255;
    for (std::size_t y = 0; y < H; ++y) {
      d = dilated(y) ? 0 : std::min(255, d + 1);
      dist[y] = static_cast<std::uint8_t>(d);
    }
    d = 255;
    for (std::size_t y = H; y-- > 0;) {
      d = dist[y] == 0 ? 0 : std::min(255, d + 1);
      dist[y] = static_cast<std::uint8_t>(std::min<int>(dist[y], d));
    }
    for (std::size_t y = 0; y < H; ++y) cells_[y * W + x] = dist[y];
  }
}

// Row pass: g^2(x) = min_q (x - q)^2 + f(q), f = squared column distance.
template <class Obstacle>
void ClearanceGrid::rows(const Obstacle& obstacle, std::size_t y0, std::size_t y1) {
  const auto W = static_cast<std::size_t>(width_);
  std::vector<double> f(W), z(W + 1);
  std::vector<std::size_t> v(W);
  for (std::size_t y = y0; y < y1; ++y) {
    std::uint8_t* row = cells_.data() + y * W;
    for (std::size_t x = 0; x < W; ++x) f[x] = static_cast<double>(row[x]) * row[x];
    std::size_t k = 0;
    v[0] = 0;
    z[0] = -1e300;
    z[1] = 1e300;
    for (std::size_t q = 1; q < W; ++q) {
      const auto qd = static_cast<double>(q);
      auto intersection = [&] {
        const auto vk = static_cast<double>(v[k]);
        return ((f[q] + qd * qd) - (f[v[k]] + vk * vk)) / (2.0 * qd - 2.0 * vk);
      };
      double s = intersection();
      while (s <= z[k]) {  // ends at k = 0 at the latest (z[0] is below any intersection)
        --k;
        s = intersection();
      }
      ++k;
      v[k] = q;
      z[k] = s;
      z[k + 1] = 1e300;
    }
    k = 0;
    for (std::size_t x = 0; x < W; ++x) {
      while (z[k + 1] < static_cast<double>(x)) ++k;
      const double dx = static_cast<double>(x) - static_cast<double>(v[k]);
      const double g = std::sqrt(dx * dx + f[v[k]]);
      row[x] = obstacle(y * W + x) ? 0 : static_cast<std::uint8_t>(1 + std::min(254.0, std::floor(g)));
    }
  }
}

void castRaysInClearance(const Eigen::Vector2d& start, const Eigen::Vector2d* dirs, std::size_t n, double max_t,
                         const ClearanceGrid& grid, double* out) {
  constexpr std::size_t kBatch = 8;
  for (std::size_t first = 0; first < n; first += kBatch) {
    const std::size_t m = std::min(kBatch, n - first);
    double t[kBatch] = {};
    std::size_t active[kBatch];
    std::size_t n_active = m;
    for (std::size_t k = 0; k < m; ++k) active[k] = first + k;
    while (n_active > 0) {
      for (std::size_t k = 0; k < n_active;) {
        const std::size_t i = active[k];
        if (internal::advanceInClearance(start, dirs[i], max_t, grid, &t[i - first], &out[i])) {
          active[k] = active[--n_active];  // done: swap the last active ray in
        } else {
          ++k;
        }
      }
    }
  }
}

}  // namespace lidar2d::geometry
