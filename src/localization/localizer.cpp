#include "lidar2d/localization/localizer.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <future>
#include <optional>
#include <span>
#include <utility>

#include "lidar2d/core/error.hpp"
#include "lidar2d/geometry/ray_cast.hpp"
#include "lidar2d/registration/correlative.hpp"
#include "lidar2d/registration/likelihood_field.hpp"
#include "src/core/parallel_for.hpp"
#include "src/localization/internal/database_index.hpp"
#include "src/localization/internal/region_search.hpp"

namespace lidar2d::localization {

using internal::badOption;

void LocalizerOptions::validate() const {
  lines.validate();
  if (max_query_lines < 2) throw badOption("max_query_lines", static_cast<double>(max_query_lines));
  if (!(key_radius_m > 0) || !std::isfinite(key_radius_m)) throw badOption("key_radius_m", key_radius_m);
  if (!(vote_bin_m > 0) || !std::isfinite(vote_bin_m)) throw badOption("vote_bin_m", vote_bin_m);
  if (!(vote_bin_rad > 0) || !std::isfinite(vote_bin_rad)) throw badOption("vote_bin_rad", vote_bin_rad);
  if (max_candidates < 1) throw badOption("max_candidates", static_cast<double>(max_candidates));
  if (max_refined < 1) throw badOption("max_refined", static_cast<double>(max_refined));
  if (max_verify_points < 10) throw badOption("max_verify_points", static_cast<double>(max_verify_points));
  if (prescore_points < 10) throw badOption("prescore_points", static_cast<double>(prescore_points));
  if (max_free_space_checked < 1)
    throw badOption("max_free_space_checked", static_cast<double>(max_free_space_checked));
  if (!(hit_distance_m > 0) || !std::isfinite(hit_distance_m)) throw badOption("hit_distance_m", hit_distance_m);
  if (!(free_margin_m >= 0) || !std::isfinite(free_margin_m)) throw badOption("free_margin_m", free_margin_m);
  if (!(max_range_m > 0)) throw badOption("max_range_m", max_range_m);
  if (!(min_score >= 0 && min_score <= 1)) throw badOption("min_score", min_score);
  if (!(ambiguity_ratio >= 0 && ambiguity_ratio <= 1)) throw badOption("ambiguity_ratio", ambiguity_ratio);
  if (!(ambiguity_nats_per_point >= 0 && std::isfinite(ambiguity_nats_per_point)))
    throw badOption("ambiguity_nats_per_point", ambiguity_nats_per_point);
  if (!(unconfident_nats_per_point >= 0 && std::isfinite(unconfident_nats_per_point)))
    throw badOption("unconfident_nats_per_point", unconfident_nats_per_point);
  if (!(distinct_distance_m >= 0) || !std::isfinite(distinct_distance_m))
    throw badOption("distinct_distance_m", distinct_distance_m);
  if (!(distinct_angle_rad >= 0) || !std::isfinite(distinct_angle_rad))
    throw badOption("distinct_angle_rad", distinct_angle_rad);
  if (!(region_half_window_m > 0) || !(region_half_window_m <= 10))
    throw badOption("region_half_window_m", region_half_window_m);
  if (!(confident_score >= 0 && confident_score <= 1)) throw badOption("confident_score", confident_score);
  if (!(confident_ratio >= 0 && confident_ratio <= 1)) throw badOption("confident_ratio", confident_ratio);
  if (!(search_resolution_m > 0) || !std::isfinite(search_resolution_m))
    throw badOption("search_resolution_m", search_resolution_m);
  if (!(budget_ms >= 0)) throw badOption("budget_ms", budget_ms);
  if (threads < 1) throw badOption("threads", static_cast<double>(threads));
}

struct Localizer::State {
  LocalizerOptions options;
  Database db;
  registration::LikelihoodFieldOptions lf_options;
  registration::LikelihoodField field;
  std::optional<registration::CorrelativeGrid> grid;
  OccupancyImage map;  // for the free-space check
  // The map's obstacle cells (db occupied_min) with the open space around each: the free-space
  // check's beams skip the samples that cannot lie on an obstacle (scoreParts).
  std::optional<geometry::ClearanceGrid> clearance;
  SE2 T_map_world;
  registration::CorrelativeOptions corr_options;
};

namespace {

std::unique_ptr<Localizer::State> makeState(const OccupancyImage& map, Database db, const LocalizerOptions& options) {
  options.validate();
  auto s = std::make_unique<Localizer::State>();
  s->options = options;
  s->db = std::move(db);
  s->map = map;
  s->T_map_world = map.origin().inverse();
  s->lf_options.resolution_m = map.resolution();
  s->lf_options.levels = 2;
  s->lf_options.truncation_m = std::max(0.3, 2.0 * map.resolution());
  s->lf_options.occupied_min = s->db.options().occupied_min;
  s->lf_options.max_iterations = 15;
  s->lf_options.line_search = true;  // stops at the minimum of the map's field instead of stepping across its kinks
  s->field = registration::LikelihoodField::fromMap(map, s->lf_options);
  s->clearance.emplace(std::span<const std::int8_t>(map.cells()), s->db.options().occupied_min, map.width(),
                       map.height(), static_cast<unsigned>(std::max<std::size_t>(1, options.threads)));
  if (options.max_regions > 0 || options.budget_ms > 0 || options.fallback_branch_and_bound) {
    // The branch-and-bound grid: obstacles blurred over about a cell, so that a pose off by a
    // fraction of a cell still scores; its max-grids are the coarser resolutions of the search.
    s->corr_options.resolution_m = std::max(map.resolution(), options.search_resolution_m);
    s->corr_options.blur_sigma_m = 0.5 * s->corr_options.resolution_m;
    s->corr_options.occupied_min = s->db.options().occupied_min;
    s->corr_options.depth = 7;
    s->grid = registration::CorrelativeGrid::fromMap(map, s->corr_options);
  }
  return s;
}

}  // namespace

Localizer::Localizer(const OccupancyImage& map, const LocalizerOptions& options, const DatabaseOptions& db_options)
    : s_(makeState(map, Database::build(map, db_options), options)) {}

Localizer::Localizer(const OccupancyImage& map, Database database, const LocalizerOptions& options) {
  const std::uint64_t sum = mapChecksum(map);
  if (database.mapChecksum() != sum)
    throw badInput(fmt::format("the localization database was built from another map (map checksum {:016x}, this map "
                               "{:016x}); rebuild it with 'lidar2d localize-index'",
                               database.mapChecksum(), sum),
                   ErrorLocation({}, 0, "map checksum"));
  s_ = makeState(map, std::move(database), options);
}

Localizer::~Localizer() = default;
const Database& Localizer::database() const { return s_->db; }
const LocalizerOptions& Localizer::options() const { return s_->options; }

namespace {

// The parts of a pose's score: the share of points within hit_distance of an obstacle; the
// evidence against the pose, in both directions: the share of beams crossing an obstacle more than
// free_margin before their end (the map holds a wall where the scan saw through) and the share of
// the other points lying in known free space at least free_margin from any obstacle (the scan saw
// something where the map saw through); and the mean of the kernel 1 - (d / hit_distance)^2 of
// each point's distance d to the nearest obstacle (0 beyond): how close, not only whether, the
// points lie to the walls. The points in free space tell a scan from a place the map lacks, put in
// a mapped room like it (its unexplained points land on that room's open floor), from a scan of
// that room (its unexplained points are mostly near walls or in unknown space).
struct ScoreParts {
  double hit = 0, through = 0, in_free = 0, kernel = 0;
  // The calibrated score, compared with the fixed thresholds (min_score, a tracker's scores): a
  // point in free space counts half. Unlike a beam through a wall (a door or glass at most), a
  // return where the map is free is common for a right pose in a map from another day (people,
  // moved furniture): 7.6% of the points on average, up to 21%, for the ROS2 bag in its map
  // (BENCHMARK.md, global localization), 15% of whose scans a full weight declined.
  double score() const { return std::clamp(hit - through - 0.5 * in_free, 0.0, 1.0); }
  // The decision's ranking: the kernel separates poses that put the same share of points
  // "on" walls, e.g. two places along a corridor, one of which lines up its door frames exactly.
  // Points in free space count fully here: the ranking compares poses of one scan, and clutter
  // new since the map is in free space at most poses alike.
  double fit() const { return std::clamp(kernel - through - in_free, 0.0, 1.0); }
};

// `also_explained` (optional): a point it holds for (world frame) counts as on an obstacle too
// (Localizer::score's overload); in the map's known free space it still counts against the pose.
ScoreParts scoreParts(const Localizer::State& s, const Points2& points_robot, const SE2& T_world_robot,
                      const Eigen::Vector2d& sensor_robot,
                      const std::function<bool(const Eigen::Vector2d&)>* also_explained = nullptr) {
  const OccupancyImage& map = s.map;
  const double res = map.resolution();
  const int free_max = s.db.options().free_max;
  // The field is clamped at its truncation: a point "at least free_margin from any obstacle" is one
  // at the clamp when the margin is wider.
  const double far = std::min(s.options.free_margin_m, s.lf_options.truncation_m);
  const SE2 T_map_robot = s.T_map_world * T_world_robot;
  const Eigen::Vector2d o = (T_map_robot * sensor_robot) / res;  // cell units
  const double hd = s.options.hit_distance_m;
  std::size_t n = 0, hit = 0, through = 0, in_free = 0;
  double kernel = 0;
  for (const auto& p : points_robot) {
    if (!p.allFinite()) continue;
    ++n;
    const Eigen::Vector2d w = T_world_robot * p;
    const double d = s.field.value(w);
    const Eigen::Vector2d e = (T_map_robot * p) / res;
    const int ex = static_cast<int>(std::floor(e.x())), ey = static_cast<int>(std::floor(e.y()));
    const bool also = d >= hd && also_explained && (*also_explained)(w);
    hit += d < hd || also;
    if (d < hd) kernel += 1.0 - (d / hd) * (d / hd);
    // Free-space check: walk the beam cell by cell up to free_margin before the endpoint.
    bool crossed = false;
    const double len = (e - o).norm() - s.options.free_margin_m / res;
    if (len > 0) {
      const Eigen::Vector2d dir = (e - o).normalized();
      // Steps of one cell, or 5 cm on finer maps (walls there are several cells thick).
      const double step = std::max(1.0, 0.05 / res);
      // A sample in a cell whose square is g cells from every obstacle square: the samples less
      // than g further on lie in no obstacle cell, and are skipped (the same answer as reading
      // each; the beams cross mostly open floor, and each read waited on memory). They are stepped
      // over, not jumped, so that every sample read lies where the walk of every sample puts it.
      double open_until = 0.0;
      for (double t = 0.5; t < len && !crossed; t += step) {
        if (t < open_until) continue;
        const Eigen::Vector2d q = o + t * dir;
        const int cx = static_cast<int>(std::floor(q.x())), cy = static_cast<int>(std::floor(q.y()));
        if (!map.contains(cx, cy)) continue;
        const int g = s.clearance->at(cx, cy);  // 0: an obstacle cell, else 1 + floor(distance)
        crossed = g == 0;
        if (g > 1) open_until = t + (g - 1) - 1e-6;
      }
    }
    through += crossed;
    // A point counts against the pose once: its beam crossed a wall, or else it lies in known free space.
    if (!crossed && d >= far) {
      if (map.contains(ex, ey)) {
        const int v = map.at(ex, ey);
        in_free += v >= 0 && v <= free_max;
      }
    }
  }
  ScoreParts out;
  if (n == 0) return out;
  const auto dn = static_cast<double>(n);
  out.hit = static_cast<double>(hit) / dn;
  out.through = static_cast<double>(through) / dn;
  out.in_free = static_cast<double>(in_free) / dn;
  out.kernel = kernel / dn;
  return out;
}

}  // namespace

double Localizer::score(const Points2& points_robot, const SE2& T_world_robot,
                        const Eigen::Vector2d& sensor_robot) const {
  return scoreParts(*s_, points_robot, T_world_robot, sensor_robot).score();
}

double Localizer::score(const Points2& points_robot, const SE2& T_world_robot, const Eigen::Vector2d& sensor_robot,
                        const std::function<bool(const Eigen::Vector2d&)>& also_explained) const {
  return scoreParts(*s_, points_robot, T_world_robot, sensor_robot, &also_explained).score();
}

LocalizationResult Localizer::localize(const LaserScan& scan, const SE2& T_robot_laser) const {
  return localize(scan.toPoints(T_robot_laser), T_robot_laser.translation());
}

LocalizationResult Localizer::localize(const Points2& points_robot, const Eigen::Vector2d& sensor_robot) const {
  using Clock = std::chrono::steady_clock;
  const auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  const auto t0 = Clock::now();
  const LocalizerOptions& o = s_->options;
  LocalizationResult res;

  Points2 pts;
  pts.reserve(points_robot.size());
  for (const auto& p : points_robot)
    if (p.allFinite() && p.norm() <= o.max_range_m) pts.push_back(p);
  res.num_points = pts.size();
  auto finish = [&](const char* reason) {
    res.reason = reason;
    res.total_ms = ms(t0, Clock::now());
    return res;
  };
  if (pts.size() < 10) return finish("no points");

  // 1. Describe: lines of the scan (robot frame), from every point; and its range profile's
  // candidates (the second signature, for scans whose lines give no usable pair).
  // The profiles' candidates on a second thread when there is one (they read `pts`, which is not
  // changed until they are in); the time they take counts as lookup time either way.
  double profiles_ms = 0.0;
  auto findProfiles = [&, &scan = std::as_const(pts)] {
    const auto start = Clock::now();
    std::vector<PoseVote> found = internal::profileCandidates(s_->db, scan, sensor_robot, o.profile_candidates);
    profiles_ms = ms(start, Clock::now());
    return found;
  };
  std::future<std::vector<PoseVote>> profiles_task;
  if (o.threads >= 2) profiles_task = std::async(std::launch::async, findProfiles);
  std::vector<Line> lines = extractLines(pts, o.lines);
  std::vector<PoseVote> from_profiles = o.threads >= 2 ? std::vector<PoseVote>{} : findProfiles();
  if (lines.size() > o.max_query_lines) lines.resize(o.max_query_lines);
  res.num_lines = lines.size();
  const auto t1 = Clock::now();
  res.describe_ms = ms(t0, t1) - (o.threads >= 2 ? 0.0 : profiles_ms);

  // 2. Look up every ordered pair; each hit gives a pose that votes for a bin.
  std::vector<PoseVote> ranked = voteLinePairs(s_->db, lines, o, o.max_candidates, &res.num_hits);
  if (profiles_task.valid()) from_profiles = profiles_task.get();
  // Verification needs no more than max_verify_points (evenly subsampled) to score and refine.
  if (pts.size() > o.max_verify_points) {
    Points2 thin;
    const double stride = static_cast<double>(pts.size()) / static_cast<double>(o.max_verify_points);
    for (std::size_t k = 0; k < o.max_verify_points; ++k) thin.push_back(pts[static_cast<std::size_t>(k * stride)]);
    pts = std::move(thin);
  }
  res.num_profile_candidates = from_profiles.size();
  ranked.insert(ranked.end(), from_profiles.begin(), from_profiles.end());
  const std::size_t n_cand = ranked.size();
  const auto t2 = Clock::now();
  res.lookup_ms = ms(t1, t2) + (o.threads >= 2 ? 0.0 : profiles_ms);

  // 3. Verify in three stages of decreasing count and increasing cost: (A) every candidate bin's
  // mean pose against the likelihood field on a subsample of the points, (B) the best distinct ones
  // with the free-space term, (C) the best of those refined and scored on all (verification) points.
  Points2 sub;
  const std::size_t stride_pts = std::max<std::size_t>(1, pts.size() / o.prescore_points);
  for (std::size_t i = 0; i < pts.size(); i += stride_pts) sub.push_back(pts[i]);
  struct Pre {
    SE2 guess;
    double pre = 0;
    double votes = 0;
  };
  std::vector<Pre> pre(n_cand);
  // Stage A: a smooth kernel of the field value (so that near-ties are ordered by how close the
  // points are, not just whether they are within a tolerance). Each candidate's score is its own:
  // the second thread takes the second half.
  const double pre_sigma = 2.0 * o.hit_distance_m;
  auto preScore = [&](std::size_t begin, std::size_t end) {
    if (begin >= end) return;
    // The field's cells of one candidate are located (and their cache lines requested) while the
    // previous candidate's are interpolated: the lookups land all over a large map, and waiting for
    // each in turn was most of this stage's time. The values are those of LikelihoodField::value.
    using Cell = registration::LikelihoodField::Level::Cell;
    const registration::LikelihoodField::Level& level0 = s_->field.level(0);
    std::vector<Cell> cells[2] = {std::vector<Cell>(sub.size()), std::vector<Cell>(sub.size())};
    auto locate = [&](std::size_t c, std::vector<Cell>& out) {
      const SE2& guess = ranked[c].T_world_robot;
      for (std::size_t i = 0; i < sub.size(); ++i) {
        out[i] = level0.cellAt(guess * sub[i]);
        if (out[i].row0) {
          __builtin_prefetch(out[i].row0);
          __builtin_prefetch(out[i].row0 + level0.width);
        }
      }
    };
    locate(begin, cells[begin % 2]);
    for (std::size_t c = begin; c < end; ++c) {
      if (c + 1 < end) locate(c + 1, cells[(c + 1) % 2]);
      double acc = 0;
      for (const Cell& cell : cells[c % 2]) {
        const double v = (cell.row0 ? level0.interpolate(cell) : level0.truncation) / pre_sigma;
        acc += v < 1.0 ? 1.0 - v * v : 0.0;
      }
      pre[c] = {ranked[c].T_world_robot, acc / static_cast<double>(sub.size()), ranked[c].votes};
    }
  };
  if (o.threads >= 2 && n_cand >= 64) {
    auto second = std::async(std::launch::async, preScore, n_cand / 2, n_cand);
    preScore(0, n_cand / 2);
    second.get();
  } else {
    preScore(0, n_cand);
  }
  std::sort(pre.begin(), pre.end(), [](const Pre& a, const Pre& b) { return a.pre > b.pre; });
  // Stage B: the best distinct ones (neighbouring bins of one pose suppressed, so that distinct
  // hypotheses such as symmetric rooms all get through) scored with the free-space term.
  std::vector<Pre> stage_b;
  for (std::size_t c = 0; c < pre.size() && stage_b.size() < o.max_free_space_checked; ++c) {
    const SE2& guess = pre[c].guess;
    bool dup = false;
    for (const Pre& q : stage_b)
      dup = dup || ((q.guess.translation() - guess.translation()).norm() < 2.0 * o.vote_bin_m &&
                    std::abs(angleDiff(q.guess.theta(), guess.theta())) < 2.0 * o.vote_bin_rad);
    if (dup) continue;
    stage_b.push_back({guess, score(sub, guess, sensor_robot) + 1e-3 * pre[c].pre, pre[c].votes});
  }
  std::sort(stage_b.begin(), stage_b.end(), [](const Pre& a, const Pre& b) { return a.pre > b.pre; });
  // Stage C: refine the best against the likelihood field and score them on every point (the
  // branch-and-bound stages below add their poses the same way). Each refinement is its own: they
  // run on the query's threads, each into its own slot, so `cands` keeps their order.
  auto refined = [&](const SE2& guess, double votes) {
    const registration::Result r = registration::matchLikelihoodField(s_->field, pts, guess, s_->lf_options);
    SE2 T = r.T_target_source;
    if (!T.isFinite() || (T.translation() - guess.translation()).norm() > 0.5) T = guess;
    ScoreParts sc = scoreParts(*s_, pts, T, sensor_robot);
    const ScoreParts sc_guess = scoreParts(*s_, pts, guess, sensor_robot);
    if (sc_guess.score() > sc.score()) {
      T = guess;
      sc = sc_guess;
    }
    return Candidate{T, sc.score(), votes, sc.fit()};
  };
  std::vector<Candidate> cands(std::min(stage_b.size(), o.max_refined));
  parallelFor(cands.size(), o.threads, [&](std::size_t c) { cands[c] = refined(stage_b[c].guess, stage_b[c].votes); });
  res.num_candidates = cands.size();

  auto bestOf = [&] {
    std::sort(cands.begin(), cands.end(), [](const Candidate& a, const Candidate& b) { return a.fit > b.fit; });
  };
  auto distinct = [&](const SE2& a, const SE2& b) {
    return (a.translation() - b.translation()).norm() > o.distinct_distance_m ||
           std::abs(angleDiff(a.theta(), b.theta())) > o.distinct_angle_rad;
  };
  // An answer that needs no further search: it scores well and no distinct candidate comes close
  // (a runner-up near the ambiguity ratio may hide a better pose the descriptors missed).
  auto confident = [&] {
    if (cands.empty() || cands.front().score < std::max(o.min_score, o.confident_score)) return false;
    for (std::size_t c = 1; c < cands.size(); ++c)
      if (distinct(cands[c].T_world_robot, cands.front().T_world_robot))
        return cands[c].fit < o.confident_ratio * cands.front().fit;
    return true;
  };
  bestOf();
  std::unique_ptr<internal::DiscretisedScan> disc;
  if (!confident() && o.max_regions > 0 && s_->grid) {
    // Stage D: candidate regions, ranked by taking each source's next best in turn: the verified
    // candidates, the pre-scored bins, the range profiles' positions, the line votes' bins.
    std::vector<Eigen::Vector2d> regions;
    const std::vector<std::vector<Eigen::Vector2d>> sources = [&] {
      std::vector<std::vector<Eigen::Vector2d>> src(4);
      for (const Candidate& c : cands) src[0].push_back(c.T_world_robot.translation());
      for (const Pre& p : stage_b) src[1].push_back(p.guess.translation());
      for (const PoseVote& v : from_profiles) src[2].push_back(v.T_world_robot.translation());
      for (std::size_t c = 0; c < ranked.size() - from_profiles.size(); ++c)
        src[3].push_back(ranked[c].T_world_robot.translation());
      return src;
    }();
    for (std::size_t rank = 0; regions.size() < o.max_regions; ++rank) {
      bool any = false;
      for (const auto& src : sources) {
        if (rank >= src.size() || regions.size() >= o.max_regions) continue;
        any = true;
        const Eigen::Vector2d& c = src[rank];
        if (std::none_of(regions.begin(), regions.end(),
                         [&](const Eigen::Vector2d& q) { return (q - c).norm() < o.region_half_window_m; }))
          regions.push_back(c);
      }
      if (!any) break;
    }
    disc = std::make_unique<internal::DiscretisedScan>(*s_->grid, sub);
    // Each region's search is its own (the regions are searched in parallel; the result is the same).
    std::vector<std::optional<Candidate>> found(regions.size());
    parallelFor(regions.size(), o.threads, [&](std::size_t r) {
      const internal::GridPose g = disc->searchWindow(regions[r], o.region_half_window_m, Clock::time_point::max());
      if (g.score > 0) found[r] = refined(g.T_world_robot, 0.0);
    });
    for (auto& c : found)
      if (c) cands.push_back(*c);
    res.num_regions = regions.size();
    bestOf();
  }
  const bool unlimited = o.fallback_branch_and_bound;
  if ((cands.empty() || cands.front().score < o.min_score) && (o.budget_ms > 0 || unlimited) && s_->grid) {
    // Stage E, the last resort: the whole map within what is left of the budget.
    const auto deadline = unlimited ? Clock::time_point::max()
                                    : t0 + std::chrono::duration_cast<Clock::duration>(
                                               std::chrono::duration<double, std::milli>(o.budget_ms));
    if (Clock::now() < deadline) {
      if (!disc) disc = std::make_unique<internal::DiscretisedScan>(*s_->grid, sub);
      const internal::GridPose g = disc->searchAll(deadline);
      res.used_fallback = true;
      res.fallback_complete = g.complete;
      if (g.score > 0) cands.push_back(refined(g.T_world_robot, 0.0));
      bestOf();
    }
  }
  const auto t3 = Clock::now();
  res.verify_ms = ms(t2, t3);

  if (cands.empty()) return finish(lines.size() < 2 ? "no lines" : "no candidate");
  const Candidate& best = cands.front();
  res.T_world_robot = best.T_world_robot;
  res.score = best.score;
  for (const Candidate& c : cands) {
    bool seen = false;
    for (const auto& k : res.candidates) seen = seen || !distinct(c.T_world_robot, k.T_world_robot);
    if (!seen) res.candidates.push_back(c);
  }
  for (std::size_t c = 1; c < cands.size(); ++c) {
    if (cands[c].score < o.min_score) continue;
    if (!distinct(cands[c].T_world_robot, best.T_world_robot)) continue;
    bool seen = false;
    for (const auto& a : res.alternatives) seen = seen || !distinct(cands[c].T_world_robot, a.T_world_robot);
    if (!seen) res.alternatives.push_back(cands[c]);
  }
  if (best.score < o.min_score) return finish("low score");
  if (!res.alternatives.empty() && res.alternatives.front().fit >= o.ambiguity_ratio * best.fit)
    return finish("ambiguous");
  // Evidence per point, a fit gap times the points behind it: on the Infinite Corridor's map the 45
  // wrong answers had a median of 18 distinct alternatives, the first within 10% of the best on 33
  // of them, and the truth scored below the answer on 39 (BENCHMARK.md, Global localization).
  // Every distinct candidate is a rival here, those scoring under min_score too: the threshold says
  // what may be answered, not what may compete. A scan from a place the map lacks (another
  // building, the unmapped half of a map) fits many places about equally badly, most of them under
  // min_score; a right answer's rivals under it lie far below it (on the benchmark's seven maps and
  // half maps no right answer has them worth 1 in all).
  // A best pose under confident_score weighs its rivals with unconfident_nats_per_point: on other
  // buildings' scans (every answer wrong) 0.08 declines 30% of the answers 0.12 leaves, at the cost
  // of 9 of the Infinite Corridor's 584 right answers (and 11 of its 21 wrong ones) and none on the
  // six other maps (BENCHMARK.md, global localization).
  if (o.ambiguity_nats_per_point > 0.0) {
    const double nats = best.score >= o.confident_score ? o.ambiguity_nats_per_point : o.unconfident_nats_per_point;
    double odds = 0.0;
    for (std::size_t c = 1; c < res.candidates.size(); ++c)
      odds += std::exp(-nats * static_cast<double>(pts.size()) * (best.fit - res.candidates[c].fit));
    if (odds >= 1.0) return finish("ambiguous");
  }
  res.declined = false;
  res.total_ms = ms(t0, Clock::now());
  return res;
}

}  // namespace lidar2d::localization
