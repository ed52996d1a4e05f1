#include "carousel/core/progress.h"

#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "carousel/core/error.h"

namespace carousel {
namespace {

TEST(ProgressTest, StagesAreDeliveredWithMonotoneFractions) {
  std::vector<ProgressUpdate> updates;
  Progress progress([&](const ProgressUpdate& u) { updates.push_back(u); });
  progress.BeginStage("hull");
  for (int i = 0; i <= 1000; ++i) progress.Report(i, 1000);
  progress.Report(0.2);  // going back is ignored
  progress.EndStage();
  ASSERT_GE(updates.size(), 2u);
  EXPECT_EQ(updates.front().stage, "hull");
  EXPECT_EQ(updates.front().fraction, 0.0);
  EXPECT_TRUE(updates.back().stage_done);
  EXPECT_EQ(updates.back().fraction, 1.0);
  for (std::size_t i = 1; i < updates.size(); ++i) {
    EXPECT_GE(updates[i].fraction, updates[i - 1].fraction);
  }
  // Throttled: far fewer deliveries than reports.
  EXPECT_LT(updates.size(), 300u);
}

TEST(ProgressTest, CancellationThrowsFromReportAndCheck) {
  CancellationToken token;
  Progress progress([](const ProgressUpdate&) {}, token);
  progress.BeginStage("texture");
  EXPECT_NO_THROW(progress.Report(0.1));
  token.Cancel();
  EXPECT_TRUE(progress.IsCancelled());
  EXPECT_THROW(progress.Report(0.2), Cancelled);
  EXPECT_THROW(progress.CheckCancelled(), Cancelled);
  EXPECT_THROW(progress.BeginStage("next"), Cancelled);
}

TEST(ProgressTest, SilentProgressStillCancels) {
  Progress silent;
  EXPECT_NO_THROW(silent.Report(0.5));
  EXPECT_FALSE(silent.IsCancelled());
}

TEST(ProgressTest, SliceMapsIntoTheParentRange) {
  std::vector<ProgressUpdate> updates;
  CancellationToken token;
  Progress parent([&](const ProgressUpdate& u) { updates.push_back(u); }, token);
  parent.BeginStage("reconstruct");
  {
    auto child = parent.Slice(0.5, 0.75);
    child->BeginStage("marching cubes");
    child->Report(1.0);
    child->EndStage();
    token.Cancel();
    EXPECT_THROW(child->CheckCancelled(), Cancelled);  // shares the token
  }
  ASSERT_FALSE(updates.empty());
  EXPECT_EQ(updates.back().stage, "reconstruct: marching cubes");
  EXPECT_DOUBLE_EQ(updates.back().fraction, 0.75);
}

TEST(ProgressTest, ConcurrentReportsAreSafe) {
  std::size_t calls = 0;
  Progress progress([&](const ProgressUpdate&) { ++calls; });  // guarded by Progress
  progress.BeginStage("render");
  std::vector<std::thread> workers;
  for (int t = 0; t < 4; ++t) {
    workers.emplace_back([&progress, t] {
      for (int i = 0; i < 10000; ++i) progress.Report((t * 10000 + i) / 40000.0);
    });
  }
  for (std::thread& worker : workers) worker.join();
  progress.EndStage();
  EXPECT_GE(calls, 2u);
}

}  // namespace
}  // namespace carousel
