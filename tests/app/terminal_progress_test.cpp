#include "carousel/app/terminal_progress.h"

#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace carousel::app {
namespace {

using ::testing::HasSubstr;

TEST(TerminalProgressTest, PlainOutputPrintsQuartersAndTheEnd) {
  std::ostringstream out;
  TerminalProgress bar(out, /*interactive=*/false);
  bar.OnUpdate({"hull", 0.0, false});
  bar.OnUpdate({"hull", 0.1, false});
  bar.OnUpdate({"hull", 0.3, false});
  bar.OnUpdate({"hull", 0.31, false});
  bar.OnUpdate({"hull", 0.8, false});
  bar.OnUpdate({"hull", 1.0, true});
  bar.OnUpdate({"mesh", 0.0, false});
  const std::string text = out.str();
  EXPECT_THAT(text, HasSubstr("hull: 0%\nhull: 30%\nhull: 80%\nhull: 100% ("));
  EXPECT_EQ(text.find("hull: 10%"), std::string::npos);
  EXPECT_EQ(text.find("hull: 31%"), std::string::npos);
  EXPECT_THAT(text, HasSubstr("mesh: 0%\n"));
}

TEST(TerminalProgressTest, InteractiveOutputRedrawsOneLinePerStage) {
  std::ostringstream out;
  TerminalProgress bar(out, /*interactive=*/true, /*width=*/10);
  Progress progress(bar.Listener());
  progress.BeginStage("atlas");
  progress.Report(0.5);
  progress.EndStage();
  progress.BeginStage("export");
  const std::string text = out.str();
  EXPECT_THAT(text, HasSubstr("\ratlas [#####.....]  50%"));
  EXPECT_THAT(text, HasSubstr("\ratlas [##########] 100%"));
  EXPECT_THAT(text, HasSubstr(" s\n\rexport [..........]   0%"));
}

}  // namespace
}  // namespace carousel::app
