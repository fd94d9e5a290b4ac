// The sequence matcher on a simulated drive through the office: its pairs are those of matchScans
// called pair by pair, whatever the thread count and chunk size; the refine stage is the second
// method run from the first one's estimate; bad options and failing callbacks are reported.

#include <gtest/gtest.h>

#include <optional>
#include <stdexcept>
#include <utility>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/registration/matcher.hpp"
#include "lidar2d/registration/sequence_matcher.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d::registration {
namespace {

// 30 frames along the office's route: 181 beams with range noise, odometry with the default noise.
const std::vector<Frame>& officeFrames() {
  static const std::vector<Frame> frames = [] {
    static const sim::Scenario scenario = sim::builtinScenario("office");
    sim::SimulatorOptions o;
    o.laser.beams = 181;
    o.seed = 7;
    return sim::simulate(scenario.world, sim::samplePath(scenario.waypoints, {}, 30), o);
  }();
  return frames;
}

Points2 pointsOf(const Frame& f) { return f.scan.toPoints(f.T_robot_laser); }

std::vector<SequencePair> runAll(const SequenceMatcher& matcher, const std::vector<Frame>& frames,
                                 SequenceSummary* summary = nullptr) {
  std::vector<SequencePair> pairs;
  const SequenceSummary s = matcher.run(frames, [&](const SequencePair& p) { pairs.push_back(p); });
  if (summary) *summary = s;
  return pairs;
}

// Same pose to the last bit, and the same convergence report.
::testing::AssertionResult sameResult(const Result& a, const Result& b) {
  if (a.T_target_source.x() != b.T_target_source.x() || a.T_target_source.y() != b.T_target_source.y() ||
      a.T_target_source.theta() != b.T_target_source.theta())
    return ::testing::AssertionFailure() << "poses differ: " << a.T_target_source.vector().transpose() << " vs "
                                         << b.T_target_source.vector().transpose();
  if (a.status != b.status || a.converged != b.converged || a.iterations != b.iterations ||
      a.num_inliers != b.num_inliers)
    return ::testing::AssertionFailure() << "status/iterations/inliers differ: " << toString(a.status) << " "
                                         << a.iterations << " " << a.num_inliers << " vs " << toString(b.status) << " "
                                         << b.iterations << " " << b.num_inliers;
  return ::testing::AssertionSuccess();
}

class SequenceMethods : public ::testing::TestWithParam<Method> {};

TEST_P(SequenceMethods, EqualsMatchingEachPairWithMatchScans) {
  const std::vector<Frame>& frames = officeFrames();
  SequenceOptions o;
  o.matcher.method = GetParam();
  SequenceSummary summary;
  const std::vector<SequencePair> pairs = runAll(SequenceMatcher(o), frames, &summary);
  ASSERT_EQ(pairs.size(), frames.size() - 1);
  EXPECT_EQ(summary.frames, frames.size());
  EXPECT_EQ(summary.pairs, pairs.size());
  std::size_t converged = 0, near_truth = 0;
  for (std::size_t k = 1; k < frames.size(); ++k) {
    const SequencePair& p = pairs[k - 1];
    EXPECT_EQ(p.index_prev, frames[k - 1].index);
    EXPECT_EQ(p.index_cur, frames[k].index);
    EXPECT_EQ(p.t_prev, frames[k - 1].time);
    EXPECT_EQ(p.t_cur, frames[k].time);
    EXPECT_FALSE(p.refined);
    const SE2 guess = frames[k - 1].T_odom_robot->inverse() * *frames[k].T_odom_robot;
    EXPECT_TRUE(sameResult(p.result, matchScans(pointsOf(frames[k - 1]), pointsOf(frames[k]), guess, o.matcher)))
        << "pair " << k;
    converged += p.result.converged;
    const SE2 truth = frames[k - 1].T_world_robot->inverse() * *frames[k].T_world_robot;
    near_truth += test::IsNearPose(truth, p.result.T_target_source, 0.1, 2.0) ? 1 : 0;
  }
  EXPECT_EQ(summary.converged, converged);
  EXPECT_GE(near_truth, pairs.size() - 1) << toString(GetParam());  // a sanity check of the frames
}

INSTANTIATE_TEST_SUITE_P(All, SequenceMethods,
                         ::testing::Values(Method::kP2P, Method::kP2L, Method::kLikelihoodField, Method::kCorrelative),
                         [](const ::testing::TestParamInfo<Method>& info) {
                           return std::string(toString(info.param));
                         });

TEST(SequenceMatcher, ThreadsAndChunksDoNotChangeTheResults) {
  const std::vector<Frame>& frames = officeFrames();
  SequenceOptions o;
  o.then = Method::kP2L;
  o.matcher.method = Method::kCorrelative;
  const std::vector<SequencePair> reference = runAll(SequenceMatcher(o), frames);
  ASSERT_EQ(reference.size(), frames.size() - 1);
  const std::vector<std::pair<unsigned, std::size_t>> runs{{1, 1}, {2, 7}, {3, 4}, {3, 128}};  // threads, chunk
  for (const auto& [threads, chunk] : runs) {
    o.threads = threads;
    o.chunk_frames = chunk;
    const std::vector<SequencePair> pairs = runAll(SequenceMatcher(o), frames);
    ASSERT_EQ(pairs.size(), reference.size());
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      EXPECT_EQ(pairs[i].t_cur, reference[i].t_cur);
      EXPECT_TRUE(sameResult(pairs[i].result, reference[i].result))
          << "pair " << i << ", " << threads << " threads, chunks of " << chunk;
    }
  }
}

// The refine stage starts from the first stage's estimate; a correlative first stage then skips
// its own likelihood-field refinement.
TEST(SequenceMatcher, RefineStageIsTheSecondMethodFromTheFirstEstimate) {
  const std::vector<Frame>& frames = officeFrames();
  for (const Method then : {Method::kP2P, Method::kP2L}) {
    SequenceOptions o;
    o.matcher.method = Method::kCorrelative;
    o.then = then;
    o.init = identityGuess;
    const SequenceMatcher matcher(o);
    const std::vector<SequencePair> pairs = runAll(matcher, frames);
    ASSERT_EQ(pairs.size(), frames.size() - 1);
    MatcherOptions first = o.matcher, second = o.matcher;
    first.corr.refine = false;
    second.method = then;
    for (std::size_t k = 1; k < frames.size(); ++k) {
      const Points2 target = pointsOf(frames[k - 1]), source = pointsOf(frames[k]);
      const Result r1 = matchScans(target, source, SE2(), first);
      const Result r2 = matchScans(target, source, r1.T_target_source, second);
      EXPECT_TRUE(pairs[k - 1].refined);
      EXPECT_TRUE(sameResult(pairs[k - 1].result, r2)) << toString(then) << " pair " << k;
      bool refined = false;
      EXPECT_TRUE(sameResult(matcher.matchPair(target, source, SE2(), &refined), r2))
          << toString(then) << " pair " << k;
      EXPECT_TRUE(refined);
    }
  }
}

// A first stage that reports kInvalidInput (here: an out-of-domain field option) is not refined.
TEST(SequenceMatcher, InvalidFirstStageIsNotRefined) {
  SequenceOptions o;
  o.matcher.method = Method::kLikelihoodField;
  o.matcher.lf.resolution_m = -1.0;
  o.then = Method::kP2L;
  const std::vector<Frame> frames(officeFrames().begin(), officeFrames().begin() + 4);
  const std::vector<SequencePair> pairs = runAll(SequenceMatcher(o), frames);
  ASSERT_EQ(pairs.size(), 3u);
  for (const SequencePair& p : pairs) {
    EXPECT_EQ(p.result.status, Status::kInvalidInput);
    EXPECT_FALSE(p.refined);
    EXPECT_NE(p.result.message.find("resolution_m"), std::string::npos) << p.result.message;
  }
}

TEST(SequenceMatcher, ReportsProgressAfterEachChunkAndTimes) {
  const std::vector<Frame>& frames = officeFrames();
  SequenceOptions o;
  o.chunk_frames = 8;
  o.threads = 2;
  std::vector<std::size_t> progress;
  std::size_t reported = 0;
  const SequenceSummary summary = SequenceMatcher(o).run(
      frames,
      [&](const SequencePair& p) {
        ++reported;
        EXPECT_GT(p.wall_s, 0.0);
        EXPECT_GE(p.cpu_s, 0.0);
      },
      [&](std::size_t done) {
        EXPECT_EQ(done, reported);  // after the chunk's pairs
        progress.push_back(done);
      });
  // 30 frames in chunks of 8: 7 pairs, then 8 per chunk (the first frame has no pair).
  EXPECT_EQ(progress, (std::vector<std::size_t>{7, 15, 23, 29}));
  EXPECT_EQ(summary.pairs, 29u);
  EXPECT_GT(summary.wall_s, 0.0);
}

TEST(SequenceMatcher, FewerThanTwoFramesGiveNoPairs) {
  const SequenceMatcher matcher{SequenceOptions{}};
  for (const std::size_t n : {0u, 1u}) {
    const std::vector<Frame> frames(officeFrames().begin(), officeFrames().begin() + static_cast<std::ptrdiff_t>(n));
    SequenceSummary summary;
    EXPECT_TRUE(runAll(matcher, frames, &summary).empty());
    EXPECT_EQ(summary.frames, n);
    EXPECT_EQ(summary.pairs, 0u);
  }
}

TEST(SequenceMatcher, BadOptionsThrowInvalidArgument) {
  auto make = [](auto&& change) {
    return [change] {
      SequenceOptions o;
      change(o);
      const SequenceMatcher m(o);
    };
  };
  EXPECT_TRUE(test::throwsError(make([](SequenceOptions& o) { o.matcher.icp.max_iterations = 0; }),
                                ErrorKind::kInvalidArgument, {"invalid matcher option", "max_iterations"}));
  EXPECT_TRUE(test::throwsError(make([](SequenceOptions& o) { o.then = Method::kLikelihoodField; }),
                                ErrorKind::kInvalidArgument, {"then", "ICP"}));
  EXPECT_TRUE(
      test::throwsError(make([](SequenceOptions& o) { o.init = nullptr; }), ErrorKind::kInvalidArgument, {"init"}));
  EXPECT_TRUE(test::throwsError(make([](SequenceOptions& o) { o.chunk_frames = 0; }), ErrorKind::kInvalidArgument,
                                {"chunk_frames"}));
}

// Exceptions from the frames, the guess (frames without odometry) and the sink end the run and
// reach the caller; the pairs reported before stand.
TEST(SequenceMatcher, ExceptionsOfTheCallbacksReachTheCaller) {
  std::vector<Frame> frames(officeFrames().begin(), officeFrames().begin() + 12);
  SequenceOptions o;
  o.threads = 3;
  o.chunk_frames = 5;
  {
    std::vector<Frame> no_odometry = frames;
    no_odometry[8].T_odom_robot.reset();
    std::size_t reported = 0;
    EXPECT_TRUE(
        test::throwsError([&] { SequenceMatcher(o).run(no_odometry, [&](const SequencePair&) { ++reported; }); },
                          ErrorKind::kBadInput, {"scan 8", "no odometry"}));
    EXPECT_EQ(reported, 4u);  // the first chunk's
  }
  std::size_t reported = 0;
  EXPECT_THROW(SequenceMatcher(o).run(frames,
                                      [&](const SequencePair&) {
                                        if (++reported == 6) throw std::runtime_error("sink");
                                      }),
               std::runtime_error);
  EXPECT_EQ(reported, 6u);
  std::size_t produced = 0;
  const SequenceMatcher::FrameProducer failing = [&]() -> std::optional<Frame> {
    if (produced == 7) throw badInput("frame 7 is broken");
    return frames[produced++];
  };
  EXPECT_TRUE(test::throwsError([&] { SequenceMatcher(o).run(failing, [](const SequencePair&) {}); },
                                ErrorKind::kBadInput, {"frame 7"}));
}

}  // namespace
}  // namespace lidar2d::registration
