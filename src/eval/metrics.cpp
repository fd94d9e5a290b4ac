#include "lidar2d/eval/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/alignment.hpp"

namespace lidar2d::eval {
namespace {

/// Errors of an estimated relative pose against the reference one (see the header's conventions).
struct PoseError {
  double trans = 0.0;
  double rot = 0.0;
};
PoseError relativeError(const SE2& T_est, const SE2& T_ref) {
  return {(T_est.translation() - T_ref.translation()).norm(), std::abs(angleDiff(T_est.theta(), T_ref.theta()))};
}

bool sameTimes(const Trajectory& a, const Trajectory& b, double tol) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (!(std::abs(a[i].time - b[i].time) <= tol)) return false;
  return true;
}

}  // namespace

const char* toString(AssociationMode mode) {
  switch (mode) {
    case AssociationMode::kAuto:
      return "auto";
    case AssociationMode::kIndex:
      return "index";
    case AssociationMode::kTime:
      return "time";
  }
  return "unknown";
}

ErrorStats summarize(std::vector<double> values) {
  ErrorStats s;
  s.count = values.size();
  if (values.empty()) return s;
  const double n = static_cast<double>(values.size());
  double sum = 0.0, sum_sq = 0.0;
  for (double v : values) {
    sum += v;
    sum_sq += v * v;
  }
  s.mean = sum / n;
  s.rmse = std::sqrt(sum_sq / n);
  // Two-pass variance: the one-pass formula cancels catastrophically for near-equal values.
  double ss = 0.0;
  for (double v : values) ss += (v - s.mean) * (v - s.mean);
  s.stddev = values.size() > 1 ? std::sqrt(ss / (n - 1.0)) : 0.0;
  std::sort(values.begin(), values.end());
  s.min = values.front();
  s.max = values.back();
  const std::size_t mid = values.size() / 2;
  s.median = values.size() % 2 ? values[mid] : 0.5 * (values[mid - 1] + values[mid]);
  return s;
}

double percentile(std::vector<double> values, double q) {
  if (values.empty() || !(q >= 0.0 && q <= 1.0)) return std::numeric_limits<double>::quiet_NaN();
  std::sort(values.begin(), values.end());
  const double pos = q * static_cast<double>(values.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(pos));
  const std::size_t hi = std::min(lo + 1, values.size() - 1);
  return values[lo] + (pos - static_cast<double>(lo)) * (values[hi] - values[lo]);
}

Association associate(const Trajectory& est, const Trajectory& ref, const Options& options) {
  Association a;
  AssociationMode mode = options.association;
  if (mode == AssociationMode::kAuto)
    mode = sameTimes(est, ref, options.same_time_tol_s) ? AssociationMode::kIndex : AssociationMode::kTime;
  a.mode = mode;
  if (mode == AssociationMode::kIndex) {
    if (est.size() != ref.size())
      throw invalidArgument("index association needs trajectories of equal length, got " +
                            std::to_string(est.size()) + " estimated and " + std::to_string(ref.size()) +
                            " reference poses");
    for (std::size_t i = 0; i < est.size(); ++i) {
      a.matches.push_back({i, i});
      a.max_abs_dt_s = std::max(a.max_abs_dt_s, std::abs(est[i].time - ref[i].time));
    }
    return a;
  }
  const TimeIndex index(est);
  a.ambiguous_times = index.hasRepeatedTimes();
  std::vector<bool> used(est.size(), false);
  for (std::size_t r = 0; r < ref.size(); ++r) {
    const auto e = index.nearest(ref[r].time, options.max_dt_s);
    if (!e) {
      ++a.unmatched_reference;
      continue;
    }
    a.matches.push_back({*e, r});
    used[*e] = true;
    a.max_abs_dt_s = std::max(a.max_abs_dt_s, std::abs(est[*e].time - ref[r].time));
  }
  a.unmatched_estimate = static_cast<std::size_t>(std::count(used.begin(), used.end(), false));
  return a;
}

AteResult computeAte(const Trajectory& est, const Trajectory& ref, const Association& association,
                     const Options& options) {
  if (association.matches.empty())
    throw badInput("no estimated pose is within " + std::to_string(options.max_dt_s) +
                   " s of a reference pose: nothing to evaluate");
  std::vector<Eigen::Vector2d> p_est, p_ref;
  p_est.reserve(association.matches.size());
  p_ref.reserve(association.matches.size());
  for (const Match& m : association.matches) {
    p_est.push_back(est[m.est].pose.translation());
    p_ref.push_back(ref[m.ref].pose.translation());
  }
  AteResult r;
  r.T_ref_est = options.align ? alignPoints(p_est, p_ref) : SE2();
  std::vector<double> trans, rot, unaligned;
  for (const Match& m : association.matches) {
    const SE2& T_ref = ref[m.ref].pose;
    const SE2 T_aligned = r.T_ref_est * est[m.est].pose;
    trans.push_back((T_ref.translation() - T_aligned.translation()).norm());
    rot.push_back(std::abs(angleDiff(T_ref.theta(), T_aligned.theta())));
    unaligned.push_back((T_ref.translation() - est[m.est].pose.translation()).norm());
  }
  r.trans_m = summarize(std::move(trans));
  r.rot_rad = summarize(std::move(rot));
  r.unaligned_trans_m = summarize(std::move(unaligned));
  return r;
}

RpeResult computeRpe(const Trajectory& est, const Trajectory& ref, const Association& association,
                     const Options& options) {
  RpeResult r;
  r.distance_m = options.rpe_distance_m;
  const auto& m = association.matches;
  const auto segment = [&](std::size_t k, std::size_t j) {
    const SE2 T_est = est[m[k].est].pose.inverse() * est[m[j].est].pose;
    const SE2 T_ref = ref[m[k].ref].pose.inverse() * ref[m[j].ref].pose;
    return relativeError(T_est, T_ref);
  };
  std::vector<double> trans, rot;
  for (std::size_t k = 0; k + 1 < m.size(); ++k) {
    const PoseError e = segment(k, k + 1);
    trans.push_back(e.trans);
    rot.push_back(e.rot);
  }
  r.trans_m = summarize(std::move(trans));
  r.rot_rad = summarize(std::move(rot));

  // Cumulative reference path length along the matches; non-decreasing, so each segment end is a
  // binary search.
  std::vector<double> s(m.size(), 0.0);
  for (std::size_t k = 1; k < m.size(); ++k)
    s[k] = s[k - 1] + (ref[m[k].ref].pose.translation() - ref[m[k - 1].ref].pose.translation()).norm();
  std::vector<double> trans_pm, rot_pm;
  if (options.rpe_distance_m > 0.0) {
    for (std::size_t k = 0; k + 1 < m.size(); ++k) {
      const auto it = std::lower_bound(s.begin() + static_cast<std::ptrdiff_t>(k) + 1, s.end(),
                                       s[k] + options.rpe_distance_m);
      if (it == s.end()) break;  // later starts have even less path ahead
      const auto j = static_cast<std::size_t>(it - s.begin());
      const double len = s[j] - s[k];
      const PoseError e = segment(k, j);
      trans_pm.push_back(e.trans / len);
      rot_pm.push_back(e.rot / len);
    }
  }
  r.trans_per_m = summarize(std::move(trans_pm));
  r.rot_rad_per_m = summarize(std::move(rot_pm));
  return r;
}

TrajectoryResult evaluateTrajectory(const Trajectory& est, const Trajectory& ref, const Options& options) {
  TrajectoryResult r;
  r.association = associate(est, ref, options);
  r.ate = computeAte(est, ref, r.association, options);
  r.rpe = computeRpe(est, ref, r.association, options);
  return r;
}

RelationsResult evaluateRelations(const Trajectory& est, const Relations& relations, const Options& options) {
  RelationsResult r;
  const TimeIndex index(est);
  r.ambiguous_times = index.hasRepeatedTimes();
  std::vector<double> trans, rot;
  for (std::size_t i = 0; i < relations.size(); ++i) {
    const Relation& rel = relations[i];
    const auto i1 = index.nearest(rel.t1, options.max_dt_s);
    const auto i2 = index.nearest(rel.t2, options.max_dt_s);
    if (!i1 || !i2) {
      ++r.skipped;
      continue;
    }
    const SE2 T_rel_est = est[*i1].pose.inverse() * est[*i2].pose;
    const PoseError e = relativeError(T_rel_est, rel.T_1_2);
    r.errors.push_back({i, e.trans, e.rot});
    trans.push_back(e.trans);
    rot.push_back(e.rot);
  }
  r.count = r.errors.size();
  r.trans_m = summarize(std::move(trans));
  r.rot_rad = summarize(std::move(rot));
  return r;
}

PairsResult evaluatePairs(const std::vector<RelativePose>& pairs, const Trajectory& ref,
                          const Options& options) {
  PairsResult r;
  bool by_index = false;
  if (options.association != AssociationMode::kTime && !ref.empty() && pairs.size() + 1 == ref.size()) {
    by_index = true;
    for (std::size_t k = 0; k < pairs.size() && by_index; ++k)
      by_index = std::abs(pairs[k].t_prev - ref[k].time) <= options.same_time_tol_s &&
                 std::abs(pairs[k].t_cur - ref[k + 1].time) <= options.same_time_tol_s;
  }
  if (options.association == AssociationMode::kIndex && !by_index)
    throw invalidArgument("index association of pairs needs pair k to join reference poses k and k+1");
  r.mode = by_index ? AssociationMode::kIndex : AssociationMode::kTime;
  const TimeIndex index(ref);
  const double max_trans = options.pair_max_trans_m;
  const double max_rot = options.pair_max_rot_deg * std::numbers::pi / 180.0;
  std::vector<double> trans, rot;
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    std::optional<std::size_t> a, b;
    if (by_index) {
      a = k;
      b = k + 1;
    } else {
      a = index.nearest(pairs[k].t_prev, options.max_dt_s);
      b = index.nearest(pairs[k].t_cur, options.max_dt_s);
    }
    if (!a || !b) {
      ++r.skipped;
      continue;
    }
    const SE2 T_ref = ref[*a].pose.inverse() * ref[*b].pose;
    const PoseError e = relativeError(pairs[k].T_prev_cur, T_ref);
    const bool ok = e.trans < max_trans && e.rot < max_rot;
    r.errors.push_back({k, e.trans, e.rot, ok});
    trans.push_back(e.trans);
    rot.push_back(e.rot);
    if (ok) ++r.successes;
    if (pairs[k].converged) ++r.converged;
  }
  r.count = r.errors.size();
  r.trans_m = summarize(std::move(trans));
  r.rot_rad = summarize(std::move(rot));
  if (r.count > 0) r.success_rate = static_cast<double>(r.successes) / static_cast<double>(r.count);
  return r;
}

}  // namespace lidar2d::eval
