#pragma once
// SLAM's loop closure by descriptors, for a drift too large for the proximity search: each node's
// scan is described by the localization module's line-pair descriptors, each finished submap's
// nodes are indexed, and a node is looked up in the old submaps; a hypothesis is verified like a
// searched closure, plus a drift-plausibility, a see-through and an ambiguity test.

#include <cstddef>
#include <vector>

#include "src/slam/internal/loop_closure.hpp"
#include "src/slam/internal/state.hpp"

namespace lidar2d::slam::internal {

class DescriptorLoops {
 public:
  /// Reads and extends `s`; passes verified closures to `closure` (which confirms them).
  DescriptorLoops(SlamState& s, LoopClosure& closure)
      : s_(s),
        closure_(closure),
        opt(s.opt),
        descriptor_search(s.match.descriptor_search),
        descriptor_query(s.match.descriptor_query),
        descriptor_db(s.match.descriptor_db) {}
  DescriptorLoops(const DescriptorLoops&) = delete;
  DescriptorLoops& operator=(const DescriptorLoops&) = delete;

  /// Appends the lines of the newest node (SlamState::node_lines) from `raw`, its scan's points in
  /// scan order (robot frame); none when descriptor_loops is off.
  void describeNode(const Points2& raw);
  /// Indexes the nodes of the finished submap `sm` (descriptor_loops on).
  void indexSubmap(Submap& sm);
  /// Looks node `n` up when it is due; `covered`: the submaps the proximity search considered.
  void search(std::size_t n, const std::vector<char>& covered);
  /// The share of the beams of `pts` (robot frame) at `T` in `target`'s frame that cross a wall of
  /// `target` well before their endpoint: a placement in a look-alike place sees through walls.
  static double seeThroughFraction(const registration::IcpTarget& target, const Points2& pts, const SE2& T);

 private:
  SlamState& s_;
  LoopClosure& closure_;
  const SlamOptions& opt;
  const registration::CorrelativeOptions& descriptor_search;
  const localization::LocalizerOptions& descriptor_query;
  const localization::DatabaseOptions& descriptor_db;
};

}  // namespace lidar2d::slam::internal
