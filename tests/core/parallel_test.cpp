// ParallelFor hands out every chunk once and rethrows the first error; the process-wide default
// thread count (carousel --threads) is what a stage asking for 0 threads gets.
#include "carousel/core/parallel.h"

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <thread>
#include <vector>

#include "carousel/core/error.h"

namespace carousel {
namespace {

TEST(ParallelTest, EveryItemOnceWhateverTheThreadCount) {
  for (const int threads : {1, 2, 7}) {
    std::vector<std::atomic<int>> seen(1001);
    ParallelFor(seen.size(), 10, threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) ++seen[i];
    });
    for (const auto& s : seen) ASSERT_EQ(s.load(), 1) << threads << " threads";
  }
}

TEST(ParallelTest, TheFirstErrorReachesTheCaller) {
  EXPECT_THROW(ParallelFor(100, 1, 4,
                           [](std::size_t begin, std::size_t) {
                             if (begin == 37) throw std::runtime_error("chunk 37");
                           }),
               std::runtime_error);
}

TEST(ParallelTest, TheDefaultThreadCountIsWhatZeroMeans) {
  EXPECT_EQ(ResolveThreadCount(5), 5);
  SetDefaultThreadCount(3);
  EXPECT_EQ(ResolveThreadCount(0), 3);
  EXPECT_EQ(ResolveThreadCount(2), 2);  // an explicit count still wins
  EXPECT_THROW(SetDefaultThreadCount(-1), InvalidArgument);
  SetDefaultThreadCount(0);
  EXPECT_GE(ResolveThreadCount(0), 1);
}

}  // namespace
}  // namespace carousel
