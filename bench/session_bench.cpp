// The one-button session on the simulated rig at full size, timed: `RunSession` with 16 stops of
// 5184x3456 (the benchmark), the time of every stage and sub-stage printed as it ends,
// then capture, the processing after capture (goal: <= 30 s on 2 cores) and the total. A timed
// command-line run that prints its figures.
//
//   session_bench [--scene shoe] [--width 5184] [--height 3456] [--views 16] [--work DIR]
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <string>

#include "bench_flags.h"
#include "carousel/core/progress.h"
#include "carousel/studio/run_session.h"

using namespace carousel;  // NOLINT(google-build-using-namespace)
using Clock = std::chrono::steady_clock;

namespace {

int Run(int argc, char** argv) {
  studio::RunOptions options;
  options.product = "bench";
  options.sim.scene = "shoe";
  options.sim.data_dir = CAROUSEL_DEFAULT_SHARED_DATA_DIR;
  options.sim.rig.width = 5184;
  options.sim.rig.height = 3456;
  options.sim.stops = 16;
  options.force = true;
  std::filesystem::path work = std::filesystem::temp_directory_path() / "carousel_session_bench";
  BenchFlags flags(argc, argv, "session_bench: the one-button session on the simulated rig, timed");
  flags.Option("--scene", &options.sim.scene)
      .Option("--width", &options.sim.rig.width)
      .Option("--height", &options.sim.rig.height)
      .Option("--views", &options.sim.stops, "turntable stops")
      .Option("--data", &options.sim.data_dir, "shared test data folder")
      .Option("--work", &work, "scratch folder (removed first)");
  if (const std::optional<int> exit_code = flags.Parse(std::cout, std::cerr)) return *exit_code;
  std::filesystem::remove_all(work);
  options.out = work;

  std::map<std::string, Clock::time_point> started;
  Progress progress([&](const ProgressUpdate& u) {
    const auto now = Clock::now();
    if (!started.count(u.stage)) started[u.stage] = now;
    if (u.stage_done) {
      std::printf("  %-40s %7.2f s\n", u.stage.c_str(),
                  std::chrono::duration<double>(now - started[u.stage]).count());
      started.erase(u.stage);
    }
  });
  std::printf("session: %s, %d stops of %dx%d\n", options.sim.scene.c_str(), options.sim.stops,
              options.sim.rig.width, options.sim.rig.height);
  const auto start = Clock::now();
  const studio::RunResult r = studio::RunSession(options, progress);
  const double total = std::chrono::duration<double>(Clock::now() - start).count();
  std::printf("capture (rendering the photos):  %7.2f s\n", r.seconds_capture);
  std::printf("reconstruct:                     %7.2f s\n", r.seconds_reconstruct);
  std::printf("texture + export + scoring:      %7.2f s (texture map alone %.2f s)\n",
              r.seconds_texture, r.texture.seconds_total - r.texture.seconds_evaluation);
  std::printf("after capture:                   %7.2f s (goal <= 30 s)\n",
              r.seconds_reconstruct + r.seconds_texture);
  std::printf("total:                           %7.2f s\n", total);
  std::filesystem::remove_all(work);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "session_bench: %s\n", e.what());
    return 1;
  }
}
