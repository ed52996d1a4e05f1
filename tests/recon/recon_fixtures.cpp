#include "recon_fixtures.h"

#include <map>
#include <mutex>

#include "carousel/sim/test_scenes.h"
#include "carousel/testing/testing.h"

namespace carousel::recon::testing {

const sim::SimViews& SimulatedCapture(const std::string& name) {
  static std::mutex mutex;
  static std::map<std::string, sim::SimViews> cache;
  std::lock_guard<std::mutex> lock(mutex);
  if (const auto it = cache.find(name); it != cache.end()) return it->second;
  sim::Scene scene;
  constexpr double kSize = 0.25;
  int stops = 16;
  int width = 960;
  int height = 640;
  if (name == "ring") {
    scene = sim::MakeRingScene(0.4 * kSize, 0.1 * kSize);
  } else if (name == "sphere") {
    scene = sim::MakeSphereScene(0.5 * kSize, {0.0, 0.0, 0.5 * kSize}, 5);
  } else if (name == "duck") {
    // Wider than the plate, which it hides; an eye's white as light as the backdrop.
    scene = sim::LoadScene(carousel::testing::SharedDataFile("models/Duck/glTF/Duck.gltf"));
    sim::PlaceOnTurntable(scene, {.target_height_m = 0.45});
    stops = 12;
  } else {
    const std::string file = name == "shoe"
                                 ? "models/MaterialsVariantsShoe/glTF/MaterialsVariantsShoe.gltf"
                                 : "models/WaterBottle/glTF/WaterBottle.gltf";
    scene = sim::LoadScene(carousel::testing::SharedDataFile(file));
    sim::PlaceOnTurntable(scene, {.scale = 1.0});
    const Eigen::Vector3d size = scene.Bounds().sizes();
    sim::PlaceOnTurntable(scene, {.target_height_m = size.z() * kSize / size.maxCoeff()});
    stops = 12;  // and larger photos: thin parts (laces, the heel tab) need the pixels
    width = 1296;
    height = 864;
  }
  sim::SimViewsOptions options;
  options.rig.width = width;
  options.rig.height = height;
  options.stops = stops;
  options.render.noise_sigma = 1.5;
  options.jpeg_quality = 95;
  options.backgrounds = true;
  return cache.emplace(name, sim::RenderViews(scene, options)).first->second;
}

}  // namespace carousel::recon::testing
