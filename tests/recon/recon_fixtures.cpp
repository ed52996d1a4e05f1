#include "recon_fixtures.h"

#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "carousel/sim/test_scenes.h"
#include "carousel/testing/testing.h"

namespace carousel::recon::testing {

const sim::SimViews& SimulatedCapture(const std::string& name) {
  static std::mutex mutex;
  static std::map<std::string, sim::SimViews> cache;
  std::lock_guard<std::mutex> lock(mutex);
  if (const auto it = cache.find(name); it != cache.end()) return it->second;
  // "scene/material[/backdrop]": the scene with its materials overridden (white, black,
  // glossy), on a backdrop of its own (grey, black).
  std::vector<std::string> parts;
  for (std::size_t begin = 0;;) {
    const std::size_t slash = name.find('/', begin);
    parts.push_back(name.substr(begin, slash - begin));
    if (slash == std::string::npos) break;
    begin = slash + 1;
  }
  const std::string& base = parts[0];
  const std::string material = parts.size() > 1 ? parts[1] : "none";
  const std::string backdrop =
      parts.size() > 2 ? parts[2] : (material == "black" ? "black" : "light");
  // "+flag+flag+" (built by append: GCC 12 warns falsely on "+" + string).
  std::string flags = "+";
  if (parts.size() > 3) flags.append(parts[3]).append("+");
  auto flag = [&](const char* word) {
    std::string wanted = "+";
    wanted.append(word).append("+");
    return flags.find(wanted) != std::string::npos;
  };
  sim::Scene scene;
  const double product_size = flag("small") ? 0.12 : 0.25;
  int stops = 16;
  int width = 960;
  int height = 640;
  if (base == "ring") {
    scene = sim::MakeRingScene(0.4 * product_size, 0.1 * product_size);
  } else if (base == "sphere") {
    scene = sim::MakeSphereScene(0.5 * product_size, {0.0, 0.0, 0.5 * product_size}, 5);
  } else if (base == "mug") {
    scene = sim::MakeMugScene(0.6 * product_size);
    stops = 12;
    width = 1296;
    height = 864;
  } else if (base == "duck") {
    // Wider than the plate, which it hides; an eye's white as light as the backdrop.
    scene = sim::LoadScene(carousel::testing::SharedDataFile("models/Duck/glTF/Duck.gltf"));
    sim::PlaceOnTurntable(scene, {.target_height_m = 0.45});
    stops = 12;
  } else {
    const std::string file = base == "shoe"
                                 ? "models/MaterialsVariantsShoe/glTF/MaterialsVariantsShoe.gltf"
                                 : "models/WaterBottle/glTF/WaterBottle.gltf";
    scene = sim::LoadScene(carousel::testing::SharedDataFile(file));
    sim::PlaceOnTurntable(scene, {.scale = 1.0});
    const Eigen::Vector3d size = scene.Bounds().sizes();
    sim::PlaceOnTurntable(scene, {.target_height_m = size.z() * product_size / size.maxCoeff()});
    stops = 12;  // and larger photos: thin parts (laces, the heel tab) need the pixels
    width = 1296;
    height = 864;
  }
  scene.OverrideMaterials(sim::ParseMaterialOverride(material));
  sim::SimViewsOptions options;
  if (material == "white") {
    // A white product on the light backdrop, the exposure lowered as a photographer would so
    // that it is not clipped (the backdrop is lit on its own).
    options.render.exposure = 0.65;
  }
  if (flag("shadow")) options.render.contact_shadow = 0.6;
  if (flag("studio")) {
    options.render.cast_shadow = 0.4;
    options.render.backdrop_falloff = 0.2;
    options.render.vignetting = 0.2;
    options.render.samples_per_axis = 3;
  }
  options.mask_shots = flag("backlit");
  if (backdrop == "white") {
    options.render.backdrop_top = {0.96, 0.96, 0.96};
    options.render.backdrop_bottom = {0.92, 0.92, 0.92};
  } else if (backdrop == "black") {
    options.render.backdrop_top = {0.07, 0.07, 0.07};
    options.render.backdrop_bottom = {0.05, 0.05, 0.05};
  } else if (backdrop == "grey") {
    options.render.backdrop_top = {0.5, 0.5, 0.5};
    options.render.backdrop_bottom = {0.45, 0.45, 0.45};
  }
  options.rig.width = width;
  options.rig.height = height;
  options.stops = stops;
  options.render.noise_sigma = 1.5;
  options.jpeg_quality = 95;
  options.backgrounds = true;
  return cache.emplace(name, sim::RenderViews(scene, options)).first->second;
}

}  // namespace carousel::recon::testing
