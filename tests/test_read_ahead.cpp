// ReadAhead: a producer on a background thread, consumed in order; its exceptions reach the
// consumer; abandoning it early stops the producer.

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <string>

#include "lidar2d/core/read_ahead.hpp"

namespace lidar2d {
namespace {

TEST(ReadAhead, DeliversEveryItemInOrderThenTheEnd) {
  int n = 0;
  ReadAhead<int> ahead([&]() -> std::optional<int> { return n < 1000 ? std::optional<int>(n++) : std::nullopt; }, 4);
  for (int i = 0; i < 1000; ++i) {
    const auto v = ahead.next();
    ASSERT_TRUE(v.has_value());
    EXPECT_EQ(*v, i);
  }
  EXPECT_FALSE(ahead.next().has_value());
  EXPECT_FALSE(ahead.next().has_value());  // and stays at the end
  EXPECT_TRUE(ahead.done());
}

TEST(ReadAhead, TheProducersExceptionReachesTheConsumerAfterTheItemsBeforeIt) {
  int n = 0;
  ReadAhead<std::string> ahead(
      [&]() -> std::optional<std::string> {
        if (n == 3) throw std::runtime_error("bad line 4");
        return std::to_string(n++);
      },
      2);
  EXPECT_EQ(*ahead.next(), "0");
  EXPECT_EQ(*ahead.next(), "1");
  EXPECT_EQ(*ahead.next(), "2");
  EXPECT_THROW(ahead.next(), std::runtime_error);
  EXPECT_FALSE(ahead.next().has_value());  // rethrown once, then the end
}

TEST(ReadAhead, StaysWithinItsCapacityAndStopsWhenAbandoned) {
  std::atomic<int> produced{0};
  {
    // An endless producer: only the destructor ends it.
    ReadAhead<int> ahead([&]() -> std::optional<int> { return produced++; }, 8);
    EXPECT_EQ(*ahead.next(), 0);
    EXPECT_EQ(*ahead.next(), 1);
    // At most 8 queued, plus one being produced, beyond the 2 taken.
    for (int i = 0; i < 100 && produced < 11; ++i) std::this_thread::yield();
    EXPECT_LE(produced.load(), 2 + 8 + 1);
  }  // joins without hanging
  const int after = produced.load();
  EXPECT_LE(after, 2 + 8 + 1);
}

}  // namespace
}  // namespace lidar2d
