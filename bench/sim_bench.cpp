// Simulated-rig renderer speed: one 5184x3456 view of the 22.7k-triangle shoe (target: under
// 2 s on 2 cores), with and without sensor noise. Needs ../shared/data (or
// $CAROUSEL_SHARED_DATA_DIR). Set CAROUSEL_BENCH_SAVE=DIR to write the rendered photo there.
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <numbers>

#include "carousel/core/image_io.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"

namespace carousel::sim {
namespace {

std::filesystem::path DataDir() {
  const char* env = std::getenv("CAROUSEL_SHARED_DATA_DIR");
  return env != nullptr && *env ? env : CAROUSEL_DEFAULT_SHARED_DATA_DIR;
}

struct ShoeStudio {
  Scene scene;
  CameraModel camera;
  ShoeStudio() {
    scene = LoadScene(DataDir() / "models/MaterialsVariantsShoe/glTF/MaterialsVariantsShoe.gltf");
    PlaceOnTurntable(scene, {.target_height_m = 0.12});
    camera = MakeSimRig({}, scene.Bounds()).front();
  }
};

const ShoeStudio& Studio() {
  static const ShoeStudio studio;
  return studio;
}

void BenchRenderShoeFullSize(benchmark::State& state) {
  const ShoeStudio& studio = Studio();
  RenderOptions options;
  options.noise_sigma = static_cast<double>(state.range(0));
  const double angle = std::numbers::pi / 5;
  const CameraModel camera = CameraAtTableAngle(studio.camera, angle);
  RenderResult result;
  for (auto _ : state) {
    result = Render(studio.scene, camera, angle, options);
    benchmark::DoNotOptimize(result.image.data);
  }
  state.counters["triangles"] = static_cast<double>(studio.scene.TriangleCount());
  state.counters["object_px"] = cv::countNonZero(result.mask);
  if (const char* save = std::getenv("CAROUSEL_BENCH_SAVE"); save != nullptr && *save) {
    WriteImage(std::filesystem::path(save) / "shoe_render.jpg", result.image);
    WriteImage(std::filesystem::path(save) / "shoe_mask.png", result.mask);
  }
}
BENCHMARK(BenchRenderShoeFullSize)->Arg(0)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace carousel::sim

BENCHMARK_MAIN();
