// Total-least-squares line fit (every variant against Eigen's eigen-solver on the scatter matrix and
// brute-force residuals) and the split of chains into line pieces (both rules on an L-corner, a
// closed square, the depth and size limits, and the covering / per-piece properties on seeded
// random polylines).

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <numbers>
#include <random>
#include <tuple>

#include "lidar2d/geometry/line_fit.hpp"
#include "src/geometry/eigen2.hpp"

namespace lidar2d::geometry {
namespace {

using V = Eigen::Vector2d;
constexpr double kPi = std::numbers::pi;

// `n` points from a to b (b excluded), each moved by up to `noise` across the segment.
Points2 wall(const V& a, const V& b, int n, double noise, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const V d = (b - a).normalized();
  const V perp(-d.y(), d.x());
  Points2 pts;
  for (int i = 0; i < n; ++i) pts.push_back(a + (b - a) * (static_cast<double>(i) / n) + noise * u(rng) * perp);
  return pts;
}

// The reference fit: Eigen's solver on the scatter matrix, residuals summed point by point.
struct Reference {
  V centroid, normal;
  double rms = 0.0;
};
Reference referenceFit(const Points2& pts, std::size_t first, std::size_t end) {
  Reference r;
  r.centroid = V::Zero();
  for (std::size_t i = first; i < end; ++i) r.centroid += pts[i];
  r.centroid /= static_cast<double>(end - first);
  Eigen::Matrix2d S = Eigen::Matrix2d::Zero();
  for (std::size_t i = first; i < end; ++i) S += (pts[i] - r.centroid) * (pts[i] - r.centroid).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(S);
  r.normal = es.eigenvectors().col(0);  // smallest eigenvalue first
  double ss = 0;
  for (std::size_t i = first; i < end; ++i) ss += std::pow(r.normal.dot(pts[i] - r.centroid), 2);
  r.rms = std::sqrt(ss / static_cast<double>(end - first));
  return r;
}

// Distance of p from the line through a and b.
double distanceFromLine(const V& p, const V& a, const V& b) {
  const V d = (b - a).normalized();
  return std::abs(d.x() * (p - a).y() - d.y() * (p - a).x());
}

using Variant = std::tuple<LineNormal, LineResidual, LineEnds, bool>;

class LineFitVariants : public ::testing::TestWithParam<Variant> {
 protected:
  LineFitOptions options() const {
    const auto [normal, residual, ends, from_origin] = GetParam();
    return {normal, residual, ends, from_origin};
  }
};

TEST_P(LineFitVariants, MatchesEigenSolverOnRandomWalls) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-10.0, 10.0);
  const LineFitOptions o = options();
  for (int trial = 0; trial < 500; ++trial) {
    const Points2 pts = wall(V(u(rng), u(rng)), V(u(rng), u(rng)), 5 + trial % 40, 0.05 * (trial % 3), rng);
    const std::size_t first = trial % 2, end = pts.size() - trial % 3;
    const LineFit f = fitLine(pts, first, end, o);
    const Reference ref = referenceFit(pts, first, end);
    ASSERT_EQ(f.num_points, end - first);
    EXPECT_TRUE(f.centroid.isApprox(ref.centroid, 1e-12)) << "trial " << trial;
    EXPECT_NEAR(f.normal.norm(), 1.0, 1e-12);
    EXPECT_NEAR(std::abs(f.normal.dot(ref.normal)), 1.0, 1e-9) << "trial " << trial;
    EXPECT_NEAR(f.direction.dot(f.normal), 0.0, 1e-12);
    EXPECT_NEAR(f.direction.x(), -f.normal.y(), 0.0);  // n turned by +90 deg
    EXPECT_NEAR(f.offset_m, f.normal.dot(f.centroid), 1e-12);
    if (o.normal_from_origin) {
      EXPECT_GE(f.offset_m, 0.0);
    }
    EXPECT_NEAR(f.rms_m, ref.rms, 1e-6) << "trial " << trial;
    // End points lie on the line.
    EXPECT_NEAR(f.normal.dot(f.a), f.offset_m, 1e-9);
    EXPECT_NEAR(f.normal.dot(f.b), f.offset_m, 1e-9);
    if (o.ends == LineEnds::kFirstAndLast) {
      EXPECT_NEAR(f.direction.dot(f.a - pts[first]), 0.0, 1e-9);
      EXPECT_NEAR(f.direction.dot(f.b - pts[end - 1]), 0.0, 1e-9);
    } else {
      for (std::size_t i = first; i < end; ++i) {
        const double t = f.direction.dot(pts[i] - f.centroid);
        EXPECT_GE(t, f.direction.dot(f.a - f.centroid) - 1e-9);
        EXPECT_LE(t, f.direction.dot(f.b - f.centroid) + 1e-9);
      }
    }
  }
}

TEST_P(LineFitVariants, CoincidentPointsHaveNoScatter) {
  const Points2 pts(6, V(2.0, -1.0));
  for (std::size_t n : {1u, 6u}) {
    const LineFit f = fitLine(pts, 0, n, options());
    EXPECT_EQ(f.scatter_m2, 0.0);
    EXPECT_EQ(f.rms_m, 0.0);
    EXPECT_TRUE(f.centroid.isApprox(V(2.0, -1.0)));
    EXPECT_NEAR(f.normal.norm(), 1.0, 1e-12);
    EXPECT_TRUE(f.a.allFinite() && f.b.allFinite());
  }
}

INSTANTIATE_TEST_SUITE_P(
    AllVariants, LineFitVariants,
    ::testing::Combine(::testing::Values(LineNormal::kPrincipalAngle, LineNormal::kMinorEigenvector),
                       ::testing::Values(LineResidual::kFromPoints, LineResidual::kMinorEigenvalue),
                       ::testing::Values(LineEnds::kFirstAndLast, LineEnds::kExtremes), ::testing::Bool()));

TEST(LineFit, HessianNormalFormOfAKnownWall) {
  // The wall x = 3 seen from the origin: n = (1, 0), offset 3, whatever the order of the points.
  std::mt19937_64 rng(1);
  const Points2 up = wall(V(3.0, -2.0), V(3.0, 2.0), 40, 0.0, rng);
  const Points2 down = wall(V(3.0, 2.0), V(3.0, -2.0), 40, 0.0, rng);
  for (const Points2* pts : {&up, &down}) {
    LineFitOptions o;
    o.normal_from_origin = true;
    const LineFit f = fitLine(*pts, 0, pts->size(), o);
    EXPECT_TRUE(f.normal.isApprox(V(1.0, 0.0), 1e-12));
    EXPECT_NEAR(f.offset_m, 3.0, 1e-12);
    EXPECT_NEAR(f.rms_m, 0.0, 1e-7);
    EXPECT_NEAR(f.scatter_m2, 40 * (4.0 * 4.0 / 12.0), 0.5);
  }
}

TEST(SymEigen2, MatchesEigenSolver) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-5.0, 5.0);
  for (int trial = 0; trial < 1000; ++trial) {
    const double a = u(rng), b = trial % 10 == 0 ? 0.0 : u(rng), c = trial % 7 == 0 ? a : u(rng);
    Eigen::Matrix2d M;
    M << a, b, b, c;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(M);
    const SymEigen2 e = symEigen2(a, b, c);
    const SymEigen2Angle ea = symEigen2Angle(a, b, c);
    EXPECT_NEAR(e.lo, es.eigenvalues()(0), 1e-9);
    EXPECT_NEAR(e.hi, es.eigenvalues()(1), 1e-9);
    EXPECT_NEAR(ea.lo, es.eigenvalues()(0), 1e-9);
    EXPECT_NEAR(ea.hi, es.eigenvalues()(1), 1e-9);
    if (es.eigenvalues()(1) - es.eigenvalues()(0) > 1e-6) {
      EXPECT_NEAR(std::abs(e.lo_vec.dot(es.eigenvectors().col(0))), 1.0, 1e-9) << "trial " << trial;
      EXPECT_NEAR(
          std::abs(std::cos(ea.lo_angle) * es.eigenvectors()(0, 0) + std::sin(ea.lo_angle) * es.eigenvectors()(1, 0)),
          1.0, 1e-9);
    }
    EXPECT_GT(ea.lo_angle, -kPi / 2 - 1e-12);
    EXPECT_LE(ea.lo_angle, kPi / 2 + 1e-12);
  }
  EXPECT_TRUE(symEigen2(2.0, 0.0, 2.0).lo_vec.isApprox(V::UnitX()));  // isotropic
}

// ---- split ----

LineSplitOptions chordRule(double threshold = 0.05) {
  LineSplitOptions o;
  o.rule = SplitRule::kChordDistance;
  o.threshold_m = threshold;
  o.min_points = 3;
  return o;
}
LineSplitOptions fitRule(double threshold = 0.04) {
  LineSplitOptions o;
  o.rule = SplitRule::kFitResidual;
  o.threshold_m = threshold;
  o.min_points = 3;
  return o;
}

// An L-corner: 30 points along +x to the corner (4, 0), then 30 along +y.
Points2 lCorner() {
  std::mt19937_64 rng(5);
  Points2 pts = wall(V(0, 0), V(4, 0), 30, 0.0, rng);
  const Points2 up = wall(V(4, 0), V(4, 4), 30, 0.0, rng);
  pts.insert(pts.end(), up.begin(), up.end());
  return pts;
}

TEST(SplitIntoLines, ChordRuleSplitsAnLCornerAtTheCornerSharedByBothPieces) {
  const Points2 pts = lCorner();
  std::vector<LinePiece> pieces;
  splitIntoLines(pts, 0, pts.size(), chordRule(), &pieces);
  ASSERT_EQ(pieces.size(), 2u);
  EXPECT_EQ(pieces[0].kind, LinePiece::Kind::kLine);
  EXPECT_EQ(pieces[1].kind, LinePiece::Kind::kLine);
  EXPECT_EQ(pieces[0].first, 0u);
  EXPECT_EQ(pieces[0].end, 31u);  // ... up to and including the corner point 30
  EXPECT_EQ(pieces[1].first, 30u);
  EXPECT_EQ(pieces[1].end, pts.size());
  EXPECT_NEAR(std::abs(pieces[0].fit.normal.y()), 1.0, 1e-9);
  EXPECT_NEAR(std::abs(pieces[1].fit.normal.x()), 1.0, 1e-9);
}

TEST(SplitIntoLines, FitRuleSplitsAnLCornerIntoDisjointPieces) {
  const Points2 pts = lCorner();
  std::vector<LinePiece> pieces;
  splitIntoLines(pts, 0, pts.size(), fitRule(), &pieces);
  ASSERT_EQ(pieces.size(), 2u);
  EXPECT_EQ(pieces[0].kind, LinePiece::Kind::kLine);
  EXPECT_EQ(pieces[1].kind, LinePiece::Kind::kLine);
  EXPECT_EQ(pieces[0].end, 30u);  // the corner point starts the right piece only
  EXPECT_EQ(pieces[1].first, 30u);
  EXPECT_LE(pieces[0].fit.rms_m, 1e-9);
  EXPECT_LE(pieces[1].fit.rms_m, 1e-9);
}

TEST(SplitIntoLines, LimitsOfSizeAndDepth) {
  const Points2 pts = lCorner();
  std::vector<LinePiece> pieces;
  LineSplitOptions o = fitRule();
  o.max_depth = 0;
  splitIntoLines(pts, 0, pts.size(), o, &pieces);
  ASSERT_EQ(pieces.size(), 1u);
  EXPECT_EQ(pieces[0].kind, LinePiece::Kind::kTooDeep);
  EXPECT_GT(pieces[0].fit.rms_m, o.threshold_m);
  EXPECT_EQ(pieces[0].fit.num_points, pts.size());

  pieces.clear();
  o = chordRule();
  o.max_depth = 0;
  splitIntoLines(pts, 0, pts.size(), o, &pieces);
  ASSERT_EQ(pieces.size(), 1u);
  EXPECT_EQ(pieces[0].kind, LinePiece::Kind::kTooDeep);

  for (const LineSplitOptions& rule : {chordRule(), fitRule()}) {
    pieces.clear();
    splitIntoLines(pts, 5, 7, rule, &pieces);  // 2 points < min_points 3
    ASSERT_EQ(pieces.size(), 1u);
    EXPECT_EQ(pieces[0].kind, LinePiece::Kind::kTooFewPoints);
    EXPECT_EQ(pieces[0].first, 5u);
    EXPECT_EQ(pieces[0].end, 7u);
  }
}

TEST(SplitIntoLines, ClosedChains) {
  // A closed square: the chord of the whole chain has no length. The chord rule measures from the
  // first point (the opposite corner is farthest); the fit rule cuts in the middle.
  std::mt19937_64 rng(9);
  Points2 pts;
  const V c[5] = {V(0, 0), V(2, 0), V(2, 2), V(0, 2), V(0, 0)};
  for (int k = 0; k < 4; ++k) {
    const Points2 side = wall(c[k], c[k + 1], 10, 0.0, rng);
    pts.insert(pts.end(), side.begin(), side.end());
  }
  pts.push_back(c[4]);  // 41 points, the last on the first
  std::vector<LinePiece> pieces;
  LineSplitOptions chord = chordRule();
  chord.max_depth = 1;
  splitIntoLines(pts, 0, pts.size(), chord, &pieces);
  ASSERT_EQ(pieces.size(), 2u);
  EXPECT_EQ(pieces[0].end - 1, 20u);  // the corner (2, 2)
  EXPECT_EQ(pieces[1].first, 20u);

  pieces.clear();
  LineSplitOptions fit = fitRule();
  fit.max_depth = 1;
  splitIntoLines(pts, 0, pts.size(), fit, &pieces);
  ASSERT_EQ(pieces.size(), 2u);
  EXPECT_EQ(pieces[0].end, 20u);  // 0 + 41 / 2
  EXPECT_EQ(pieces[1].first, 20u);
}

class SplitRules : public ::testing::TestWithParam<SplitRule> {};

TEST_P(SplitRules, PiecesCoverRandomPolylinesAndSatisfyTheRule) {
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> u(-5.0, 5.0);
  const bool chord = GetParam() == SplitRule::kChordDistance;
  for (int trial = 0; trial < 300; ++trial) {
    Points2 pts;
    V p(u(rng), u(rng));
    for (int k = 0; k < 1 + trial % 5; ++k) {
      const V q(u(rng), u(rng));
      const Points2 side = wall(p, q, 3 + static_cast<int>(rng() % 30), 0.02 * (trial % 3), rng);
      pts.insert(pts.end(), side.begin(), side.end());
      p = q;
    }
    pts.push_back(p);
    LineSplitOptions o = chord ? chordRule(0.05) : fitRule(0.03);
    o.min_points = 2 + trial % 4;
    if (trial % 4 == 3) o.max_depth = 2;
    std::vector<LinePiece> pieces;
    splitIntoLines(pts, 0, pts.size(), o, &pieces);
    ASSERT_FALSE(pieces.empty());
    EXPECT_EQ(pieces.front().first, 0u);
    EXPECT_EQ(pieces.back().end, pts.size());
    for (std::size_t i = 0; i < pieces.size(); ++i) {
      const LinePiece& piece = pieces[i];
      const std::size_t n = piece.end - piece.first;
      ASSERT_GE(n, 1u);
      if (i + 1 < pieces.size()) {
        EXPECT_EQ(pieces[i + 1].first, chord ? piece.end - 1 : piece.end) << "trial " << trial;
      }
      if (n < o.min_points) {
        EXPECT_EQ(piece.kind, LinePiece::Kind::kTooFewPoints);
        continue;
      }
      EXPECT_NE(piece.kind, LinePiece::Kind::kTooFewPoints);
      EXPECT_EQ(piece.fit.num_points, n);
      EXPECT_NEAR(piece.fit.rms_m, referenceFit(pts, piece.first, piece.end).rms, 1e-6);
      if (piece.kind != LinePiece::Kind::kLine) continue;
      if (chord) {
        const V& a = pts[piece.first];
        const V& b = pts[piece.end - 1];
        if ((b - a).norm() > 1e-9) {
          for (std::size_t k = piece.first; k < piece.end; ++k) {
            EXPECT_LE(distanceFromLine(pts[k], a, b), o.threshold_m + 1e-12) << "trial " << trial;
          }
        }
      } else {
        EXPECT_LE(piece.fit.rms_m, o.threshold_m);
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(BothRules, SplitRules, ::testing::Values(SplitRule::kChordDistance, SplitRule::kFitResidual));

}  // namespace
}  // namespace lidar2d::geometry
