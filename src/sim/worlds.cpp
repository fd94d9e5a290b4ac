#include "lidar2d/sim/worlds.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "lidar2d/core/error.hpp"
#include "lidar2d/sim/noise.hpp"

namespace lidar2d::sim {
namespace {

using V = Eigen::Vector2d;
constexpr double kPi = std::numbers::pi;
constexpr double kWallThickness = 0.2;  // [m], a masonry interior wall

struct Builder {
  std::vector<Segment> segs;
  std::vector<Arc> arcs;

  /// A building wall along a -> b, kWallThickness thick (centred on the line) like a real wall:
  /// zero-thickness walls would let a wall seen from both sides look like one infinitely thin
  /// surface, which no real building has (and which defeats TSDF mapping's negative band).
  void wall(V a, V b) {
    const V n = V(a.y() - b.y(), b.x() - a.x()).normalized() * (kWallThickness / 2);
    segs.push_back({a + n, b + n});
    segs.push_back({b + n, b - n});
    segs.push_back({b - n, a - n});
    segs.push_back({a - n, a + n});
  }
  /// A single zero-thickness segment (the faces of furniture).
  void edge(V a, V b) { segs.push_back({a, b}); }
  void polyline(std::initializer_list<V> pts) {
    const V* prev = nullptr;
    for (const V& p : pts) {
      if (prev) edge(*prev, p);
      prev = &p;
    }
  }
  /// A straight wall from a to b with doors: (distance of the door centre from a, width) [m].
  void wallWithDoors(V a, V b, std::vector<std::pair<double, double>> doors) {
    std::sort(doors.begin(), doors.end());
    const double len = (b - a).norm();
    const V d = (b - a) / len;
    double s = 0;
    for (const auto& [c, w] : doors) {
      if (c - w / 2 > s) wall(a + s * d, a + (c - w / 2) * d);
      s = c + w / 2;
    }
    if (s < len) wall(a + s * d, b);
  }
  /// A closed rectangle (cabinet, box) [m].
  void box(double x0, double y0, double x1, double y1) {
    polyline({V(x0, y0), V(x1, y0), V(x1, y1), V(x0, y1), V(x0, y0)});
  }
  /// A table seen at leg height: four round legs at the corners of w x d centred on (cx, cy).
  void table(double cx, double cy, double w, double d, double leg_radius = 0.025) {
    for (double sx : {-1.0, 1.0})
      for (double sy : {-1.0, 1.0}) arcs.push_back(Arc::circle(V(cx + sx * (w / 2 - 0.05), cy + sy * (d / 2 - 0.05)), leg_radius));
  }
  void pillar(double cx, double cy, double r) { arcs.push_back(Arc::circle(V(cx, cy), r)); }
};

// ---- office: 20 x 15 m, corridor y 6.5..8.5 ----
Scenario office() {
  Builder b;
  b.polyline({V(0, 0), V(20, 0), V(20, 15), V(0, 15), V(0, 0)});
  // Corridor walls with one 1 m door per room (door centres along x).
  const double south_doors[] = {1.5, 8.5, 12.0, 18.0};  // rooms [0,5] [5,10] [10,15] [15,20]
  const double north_doors[] = {5.0, 10.0, 15.0};        // rooms [0,7] [7,13] [13,20]
  std::vector<std::pair<double, double>> sd, nd;
  for (double x : south_doors) sd.push_back({x, 1.0});
  for (double x : north_doors) nd.push_back({x, 1.0});
  b.wallWithDoors(V(0, 6.5), V(20, 6.5), sd);
  b.wallWithDoors(V(0, 8.5), V(20, 8.5), nd);
  // Room partitions.
  for (double x : {5.0, 10.0, 15.0}) b.wall(V(x, 0), V(x, 6.5));
  for (double x : {7.0, 13.0}) b.wall(V(x, 8.5), V(x, 15));
  // South rooms' furniture: inside the route loop (x0+1.4 .. x1-1.4, y 1.4 .. 5.1) or against walls.
  b.table(2.5, 3.0, 1.2, 0.8);
  b.box(0.02, 2.0, 0.45, 3.5);  // cabinet, west wall of room S0
  b.pillar(7.5, 3.25, 0.2);
  b.box(6.0, 0.02, 8.0, 0.5);  // cabinet, south wall of room S1
  b.table(12.5, 3.2, 2.0, 1.0);  // meeting table
  b.arcs.push_back(Arc{V(15, 0), 0.8, kPi / 2, kPi / 2});  // curved desk in room S2's south-east corner
  b.pillar(17.5, 3.0, 0.25);
  b.box(19.55, 1.5, 19.98, 4.5);  // cabinets, east wall of room S3
  b.table(17.5, 4.5, 1.0, 0.6);
  // North rooms' furniture (route loop y 9.5 .. 14).
  b.table(2.5, 11.75, 1.2, 0.8);
  b.table(4.5, 11.75, 1.2, 0.8);
  b.box(1.0, 14.5, 3.0, 14.98);  // cabinet, north wall of room N0
  b.box(9.0, 11.0, 11.0, 11.5);  // two rows of cabinets in room N1
  b.box(9.0, 12.3, 11.0, 12.8);
  b.arcs.push_back(Arc{V(16.5, 11.75), 0.6, 0.0, kPi});  // half-round sofa in room N2
  b.pillar(18.0, 12.5, 0.15);

  // Route: along the corridor (y = 7.5) from the west, looping through each room when passing its
  // door (rooms in the order of their doors along x).
  std::vector<V> w{V(0.7, 7.5)};
  struct Room {
    double door, x0, x1;
    bool south;
  };
  const Room rooms[] = {{1.5, 0, 5, true},    {5.0, 0, 7, false},    {8.5, 5, 10, true}, {10.0, 7, 13, false},
                        {12.0, 10, 15, true}, {15.0, 13, 20, false}, {18.0, 15, 20, true}};
  for (const Room& r : rooms) {
    const double ye = r.south ? 5.5 : 9.5;   // loop edge next to the corridor
    const double yf = r.south ? 1.0 : 14.0;  // far loop edge
    w.push_back(V(r.door, 7.5));
    w.push_back(V(r.door, ye));
    w.push_back(V(r.x1 - 1, ye));
    w.push_back(V(r.x1 - 1, yf));
    w.push_back(V(r.x0 + 1, yf));
    w.push_back(V(r.x0 + 1, ye));
    w.push_back(V(r.door, ye));
    w.push_back(V(r.door, 7.5));
  }
  w.push_back(V(19.2, 7.5));
  return {World(std::move(b.segs), std::move(b.arcs), "office"), std::move(w),
          "20 x 15 m office: corridor and seven furnished rooms"};
}

// ---- corridor: 60 m x 2 m, rooms at both ends ----
Scenario corridor() {
  Builder b;
  // Wall centre lines chosen so the inner faces are at y = -1 and +1: 2 m wide.
  b.wall(V(0, -1 - kWallThickness / 2), V(60, -1 - kWallThickness / 2));
  b.wall(V(0, 1 + kWallThickness / 2), V(60, 1 + kWallThickness / 2));
  // West room x -8..0, y -4..4, open to the corridor.
  b.polyline({V(0, 1), V(0, 4), V(-8, 4), V(-8, -4), V(0, -4), V(0, -1)});
  b.pillar(-4, -1.8, 0.3);  // off the corridor's axis: invisible from its middle
  b.box(-7.98, -1.0, -7.5, 1.0);
  b.table(-3, -2.6, 1.2, 0.8);
  // East room x 60..68.
  b.polyline({V(60, 1), V(60, 4), V(68, 4), V(68, -4), V(60, -4), V(60, -1)});
  b.pillar(64, 1.6, 0.3);
  b.box(67.5, -1.0, 67.98, 1.0);
  b.box(63.0, 3.2, 64.5, 3.7);
  std::vector<V> w{V(-6, -2.5), V(-6, 2.5), V(-2, 2.5), V(-2, 0), V(62, 0),
                   V(62, -2.5), V(66, -2.5), V(66, 2.5), V(62.5, 2.5)};
  return {World(std::move(b.segs), std::move(b.arcs), "corridor"), std::move(w),
          "featureless 60 x 2 m corridor between two rooms"};
}

// ---- symmetric: four identical rooms, invariant under a 90 degree rotation ----
V rot90(const V& p) { return V(-p.y(), p.x()); }  // exact: only negation and swap

Scenario symmetric() {
  Builder q;  // room I (x, y in 0..6); the other three are exact 90 degree rotations of it
  q.wall(V(6, 0), V(6, 6));
  q.wall(V(6, 6), V(0, 6));
  q.wallWithDoors(V(0, 0), V(0, 6), {{3.0, 1.0}});  // shared with room II; its rotations give the other doors
  q.table(3, 3, 0.8, 0.6);
  q.box(1.0, 5.55, 2.5, 5.98);
  q.box(5.55, 3.8, 5.98, 5.3);
  q.pillar(5.2, 0.8, 0.2);
  Builder b;
  const std::vector<V> room_route{V(3, 1.2), V(4.5, 3), V(3, 4.5), V(1.2, 3)};
  std::vector<V> w;
  std::vector<Segment> segs = q.segs;
  std::vector<Arc> arcs = q.arcs;
  std::vector<V> route = room_route;
  for (int k = 0; k < 4; ++k) {
    b.segs.insert(b.segs.end(), segs.begin(), segs.end());
    b.arcs.insert(b.arcs.end(), arcs.begin(), arcs.end());
    w.insert(w.end(), route.begin(), route.end());
    for (auto& s : segs) s = {rot90(s.a), rot90(s.b)};
    for (auto& a : arcs) a.center = rot90(a.center);  // circles only: no start angle to rotate
    for (auto& p : route) p = rot90(p);
  }
  w.push_back(room_route.front());
  return {World(std::move(b.segs), std::move(b.arcs), "symmetric"), std::move(w),
          "four identical 6 x 6 m rooms, symmetric under 90 degree rotation"};
}

// ---- open: 60 x 60 m, a few pillars ----
Scenario open() {
  Builder b;
  const double pillars[][3] = {{0, 0, 0.5},    {4, -3, 0.3},   {-4, 3, 0.3},   {12, 12, 0.5},
                               {-12, -13, 0.4}, {14, -10, 0.4}, {-15, 10, 0.4}, {0, 20, 0.5},
                               {22, 2, 0.4},   {-3, -16, 0.3}, {-25, -25, 0.5}, {25, 24, 0.5}};
  for (const auto& p : pillars) b.pillar(p[0], p[1], p[2]);
  b.wall(V(-6, 12), V(-2, 12));
  b.box(16, 4, 18, 6);  // kiosk
  std::vector<V> w{V(-8, -8), V(8, -8), V(8, 8), V(-8, 8), V(-8, -8)};
  return {World(std::move(b.segs), std::move(b.arcs), "open"), std::move(w),
          "60 x 60 m open area with a few pillars"};
}

}  // namespace

std::vector<std::string> listWorlds() { return {"office", "corridor", "symmetric", "open"}; }

Scenario builtinScenario(const std::string& name) {
  if (name == "office") return office();
  if (name == "corridor") return corridor();
  if (name == "symmetric") return symmetric();
  if (name == "open") return open();
  throw invalidArgument(fmt::format("unknown world '{}'; known worlds: {}", name, fmt::join(listWorlds(), ", ")),
                        ErrorLocation({}, 0, "world"));
}

World worldFromMap(const OccupancyImage& map, int occupied_min, const std::string& name) {
  const int w = map.width(), h = map.height();
  auto obstacle = [&](int c, int r) { return c >= 0 && r >= 0 && c < w && r < h && map.at(c, r) >= occupied_min; };
  const double res = map.resolution();
  const SE2& T_world_map = map.origin();
  std::vector<Segment> segs;
  auto add = [&](double x0, double y0, double x1, double y1) {
    segs.push_back({T_world_map * V(x0 * res, y0 * res), T_world_map * V(x1 * res, y1 * res)});
  };
  // Horizontal edges on grid line y = r (between rows r-1 and r), merged into runs along x.
  for (int r = 0; r <= h; ++r) {
    int start = -1;
    for (int c = 0; c <= w; ++c) {
      const bool edge = c < w && obstacle(c, r - 1) != obstacle(c, r);
      if (edge && start < 0) start = c;
      if (!edge && start >= 0) {
        add(start, r, c, r);
        start = -1;
      }
    }
  }
  // Vertical edges on grid line x = c, merged into runs along y.
  for (int c = 0; c <= w; ++c) {
    int start = -1;
    for (int r = 0; r <= h; ++r) {
      const bool edge = r < h && obstacle(c - 1, r) != obstacle(c, r);
      if (edge && start < 0) start = r;
      if (!edge && start >= 0) {
        add(c, start, c, r);
        start = -1;
      }
    }
  }
  // Cells are ~0.05 m: a grid cell of a few map cells keeps the candidate lists short.
  WorldOptions opt;
  opt.cell_size_m = std::max(4 * res, 0.05);
  return World(std::move(segs), {}, name, opt);
}

// A route of 1000 km: the walk's steps are planned one by one, so a longer one would take hours.
constexpr double kMaxRandomWalkLength = 1e6;

std::vector<Eigen::Vector2d> randomWalk(const OccupancyImage& map, const RandomWalkOptions& o) {
  if (!(o.length_m > 0) || !(o.clearance_m >= 0) || !(o.min_step_m > 0) || !(o.max_step_m >= o.min_step_m) ||
      !(o.heading_sigma_rad >= 0))
    throw invalidArgument("random walk: length, clearance and steps must be positive", ErrorLocation({}, 0, "path"));
  if (!(o.length_m <= kMaxRandomWalkLength))
    throw invalidArgument(fmt::format("random walk: a length of {:g} m is more than the limit of {:g} m (fewer scans, "
                                      "a higher rate or a lower speed?)",
                                      o.length_m, kMaxRandomWalkLength),
                          ErrorLocation({}, 0, "path"));
  const int w = map.width(), h = map.height();
  // Distance of every cell to the nearest non-free cell (or the map's border), in cells.
  cv::Mat free_img(h + 2, w + 2, CV_8UC1, cv::Scalar(0));
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const int v = map.at(c, r);
      free_img.at<std::uint8_t>(r + 1, c + 1) = (v >= 0 && v <= o.free_max) ? 255 : 0;
    }
  cv::Mat dist;
  cv::distanceTransform(free_img, dist, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  const double need_cells = o.clearance_m / map.resolution() + 0.5;  // from the cell centre to the blocker's edge
  auto safeCell = [&](int c, int r) { return dist.at<float>(r + 1, c + 1) >= need_cells; };
  auto safePoint = [&](const V& p) {
    const auto cell = map.worldToCell(p);
    return cell && safeCell(cell->x(), cell->y());
  };
  std::vector<int> candidates;
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c)
      if (safeCell(c, r)) candidates.push_back(r * w + c);
  if (candidates.empty())
    throw badInput(fmt::format("no free cell keeps a clearance of {} m; cannot plan a random walk", o.clearance_m),
                   ErrorLocation({}, 0, "map"));
  Rng rng(o.seed);
  const int start = candidates[static_cast<std::size_t>(rng.uniform() * static_cast<double>(candidates.size()))];
  std::vector<V> route{map.cellCenter(start % w, start / w)};
  double heading = 2 * kPi * rng.uniform();
  double length = 0;
  const double step_check = map.resolution() / 2;
  while (length < o.length_m) {
    bool moved = false;
    for (int attempt = 0; attempt < 80 && !moved; ++attempt) {
      // First try gentle turns, then any direction (dead ends).
      const double hd = attempt < 40 ? heading + rng.gaussian(o.heading_sigma_rad) : 2 * kPi * rng.uniform();
      const double len = o.min_step_m + (o.max_step_m - o.min_step_m) * rng.uniform();
      const V d(std::cos(hd), std::sin(hd));
      bool ok = true;
      for (double s = step_check; s <= len && ok; s += step_check) ok = safePoint(route.back() + s * d);
      if (!ok || !safePoint(route.back() + len * d)) continue;
      route.push_back(route.back() + len * d);
      heading = hd;
      length += len;
      moved = true;
    }
    if (!moved) break;
  }
  if (route.size() < 2)
    throw badInput("the random walk is stuck at its start (free space too small for the clearance)",
                   ErrorLocation({}, 0, "map"));
  return route;
}

}  // namespace lidar2d::sim
