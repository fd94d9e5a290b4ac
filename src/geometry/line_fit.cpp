#include "lidar2d/geometry/line_fit.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

#include "src/geometry/eigen2.hpp"

namespace lidar2d::geometry {

LineFit fitLine(const Points2& pts, std::size_t first, std::size_t end, const LineFitOptions& options) {
  assert(first < end && end <= pts.size());
  LineFit f;
  f.num_points = end - first;
  const double n = static_cast<double>(f.num_points);
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (std::size_t i = first; i < end; ++i) c += pts[i];
  c /= n;
  double sxx = 0, sxy = 0, syy = 0;
  for (std::size_t i = first; i < end; ++i) {
    const Eigen::Vector2d d = pts[i] - c;
    sxx += d.x() * d.x();
    sxy += d.x() * d.y();
    syy += d.y() * d.y();
  }
  f.centroid = c;
  f.scatter_m2 = sxx + syy;

  // The smaller eigenvalue of S / n, when the normal's computation gives it.
  double minor_eigenvalue = 0.0;
  bool have_minor_eigenvalue = false;
  switch (options.normal) {
    case LineNormal::kPrincipalAngle: {
      const double angle = 0.5 * std::atan2(2.0 * sxy, sxx - syy);
      const Eigen::Vector2d dir(std::cos(angle), std::sin(angle));
      f.normal = Eigen::Vector2d(-dir.y(), dir.x());
      break;
    }
    case LineNormal::kMinorEigenvector: {
      const SymEigen2 e = symEigen2(sxx / n, sxy / n, syy / n);
      f.normal = e.lo_vec;
      minor_eigenvalue = e.lo;
      have_minor_eigenvalue = true;
      break;
    }
  }
  f.offset_m = f.normal.dot(c);
  if (options.normal_from_origin && f.offset_m < 0) {
    f.normal = -f.normal;
    f.offset_m = -f.offset_m;
  }
  f.direction = Eigen::Vector2d(-f.normal.y(), f.normal.x());

  switch (options.residual) {
    case LineResidual::kFromPoints: {
      double ss = 0;
      for (std::size_t i = first; i < end; ++i) {
        const double r = f.normal.dot(pts[i]) - f.offset_m;
        ss += r * r;
      }
      f.rms_m = std::sqrt(ss / n);
      break;
    }
    case LineResidual::kMinorEigenvalue:
      if (!have_minor_eigenvalue) minor_eigenvalue = symEigen2(sxx / n, sxy / n, syy / n).lo;
      f.rms_m = std::sqrt(std::max(0.0, minor_eigenvalue));
      break;
  }

  switch (options.ends) {
    case LineEnds::kFirstAndLast:
      f.a = pts[first] - (f.normal.dot(pts[first]) - f.offset_m) * f.normal;
      f.b = pts[end - 1] - (f.normal.dot(pts[end - 1]) - f.offset_m) * f.normal;
      break;
    case LineEnds::kExtremes: {
      double tmin = std::numeric_limits<double>::infinity(), tmax = -tmin;
      for (std::size_t i = first; i < end; ++i) {
        const double t = f.direction.dot(pts[i] - c);
        tmin = std::min(tmin, t);
        tmax = std::max(tmax, t);
      }
      f.a = c + tmin * f.direction;
      f.b = c + tmax * f.direction;
      break;
    }
  }
  return f;
}

namespace {

// Chords shorter than this have no direction: a closed piece (its ends on one spot).
constexpr double kMinChordM = 1e-9;

// The interior point of pts[first, last] (both ends excluded) farthest from the chord
// pts[first] -> pts[last], the first of equally far ones, with its distance as the rule measures
// it (see SplitRule); distance -1 when there is no interior point.
struct Farthest {
  std::size_t index = 0;
  double distance = -1.0;
  bool closed = false;  // the chord is shorter than kMinChordM
};

Farthest farthestFromChord(const Points2& pts, std::size_t first, std::size_t last, SplitRule rule) {
  const Eigen::Vector2d& p0 = pts[first];
  Eigen::Vector2d chord = pts[last] - p0;
  const double len = chord.norm();
  Farthest f;
  f.index = first;
  f.closed = !(len > kMinChordM);
  if (f.closed && rule == SplitRule::kFitResidual) return f;  // cut in the middle instead
  // kChordDistance divides the cross product by the chord's length, kFitResidual crosses with the
  // unit chord (the same distance, rounded differently).
  double scale = len;
  if (rule == SplitRule::kFitResidual) {
    chord /= len;
    scale = 1.0;
  }
  for (std::size_t i = first + 1; i < last; ++i) {
    const Eigen::Vector2d v = pts[i] - p0;
    const double d = f.closed ? v.norm() : std::abs(chord.x() * v.y() - chord.y() * v.x()) / scale;
    if (d > f.distance) {
      f.distance = d;
      f.index = i;
    }
  }
  return f;
}

}  // namespace

void splitIntoLines(const Points2& pts, std::size_t first, std::size_t end, const LineSplitOptions& options,
                    std::vector<LinePiece>* out) {
  assert(first < end && end <= pts.size());
  assert(options.min_points >= 2 && options.threshold_m > 0 && options.max_depth >= 0);
  struct Task {
    std::size_t first, end;
    int depth;
  };
  // Depth first, left before right, so that the pieces come out in chain order; an explicit stack,
  // as a long chain of near points (a curved wall) splits many levels deep.
  std::vector<Task> stack{{first, end, 0}};
  while (!stack.empty()) {
    const Task t = stack.back();
    stack.pop_back();
    LinePiece piece;
    piece.first = t.first;
    piece.end = t.end;
    const std::size_t n = t.end - t.first;
    if (n < options.min_points) {
      piece.kind = LinePiece::Kind::kTooFewPoints;
      out->push_back(piece);
      continue;
    }
    std::size_t right_first = 0, left_end = 0;
    if (options.rule == SplitRule::kChordDistance) {
      const Farthest far = farthestFromChord(pts, t.first, t.end - 1, options.rule);
      if (!(far.distance > options.threshold_m) || t.depth >= options.max_depth) {
        piece.kind = far.distance > options.threshold_m ? LinePiece::Kind::kTooDeep : LinePiece::Kind::kLine;
        piece.fit = fitLine(pts, t.first, t.end, options.fit);
        out->push_back(piece);
        continue;
      }
      right_first = far.index;
      left_end = far.index + 1;  // the split point ends the left piece too
    } else {
      piece.fit = fitLine(pts, t.first, t.end, options.fit);
      if (piece.fit.rms_m <= options.threshold_m || t.depth >= options.max_depth) {
        piece.kind = piece.fit.rms_m <= options.threshold_m ? LinePiece::Kind::kLine : LinePiece::Kind::kTooDeep;
        out->push_back(piece);
        continue;
      }
      const Farthest far = farthestFromChord(pts, t.first, t.end - 1, options.rule);
      std::size_t k = far.closed || far.distance < 0 ? t.first + n / 2 : far.index;
      k = std::clamp(k, t.first + 1, t.end - 1);
      right_first = k;
      left_end = k;
    }
    stack.push_back({right_first, t.end, t.depth + 1});
    stack.push_back({t.first, left_end, t.depth + 1});
  }
}

}  // namespace lidar2d::geometry
