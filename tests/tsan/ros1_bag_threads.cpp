// ThreadSanitizer check of the ROS1 bag reader's chunk prefetch (src/io/internal/ros1_bag.cpp
// decompresses the next chunks on threads of its own). Built and run by `make test-tsan-bags` (CI
// runs it; the whole suite under TSan would need another full build): each bag given is read
// whole, and again only its first message, so that the bag is destroyed while prefetches are
// running. Exit 1 when a bag fails to read; ThreadSanitizer exits 66 on a race.

#include <cstdio>
#include <exception>
#include <vector>

#include "src/io/internal/ros1_bag.hpp"

using lidar2d::io::internal::Ros1Bag;

int main(int argc, char** argv) {
  int failures = 0;
  for (int a = 1; a < argc; ++a) {
    try {
      std::size_t messages = 0, bytes = 0;
      {
        Ros1Bag bag(argv[a]);
        std::vector<std::uint32_t> ids;
        for (const auto& c : bag.connections()) ids.push_back(c.id);
        for (const auto& e : bag.messages(ids)) {
          bytes += bag.read(e).size();
          ++messages;
        }
      }
      {
        Ros1Bag bag(argv[a]);
        std::vector<std::uint32_t> ids;
        for (const auto& c : bag.connections()) ids.push_back(c.id);
        const auto first = bag.messages(ids);
        if (!first.empty()) bag.read(first.front());
      }
      std::printf("%s: %zu messages, %zu bytes\n", argv[a], messages, bytes);
    } catch (const std::exception& e) {
      std::printf("%s\n", e.what());
      ++failures;
    }
  }
  return failures == 0 ? 0 : 1;
}
