#include "carousel/studio/sim_capture.h"

#include <cmath>
#include <map>
#include <numbers>

#include <opencv2/core.hpp>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/timer.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

const std::map<std::string, std::string>& SceneNames() {
  static const std::map<std::string, std::string> names = {
      {"shoe", "models/MaterialsVariantsShoe/glTF/MaterialsVariantsShoe.gltf"},
      {"bottle", "models/WaterBottle/glTF/WaterBottle.gltf"},
      {"avocado", "models/Avocado/glTF/Avocado.gltf"},
      {"duck", "models/Duck/glTF/Duck.gltf"},
  };
  return names;
}

}  // namespace

void SimCaptureOptions::Validate() const {
  CAROUSEL_THROW_IF(scene.empty(), InvalidArgument, "SimCaptureOptions.scene is empty");
  CAROUSEL_THROW_IF(stops < 1 || stops > 3600, InvalidArgument,
                    "SimCaptureOptions.stops must be in 1..3600, got " << stops);
  CAROUSEL_THROW_IF(jpeg_quality < 1 || jpeg_quality > 100, InvalidArgument,
                    "SimCaptureOptions.jpeg_quality must be in 1..100, got " << jpeg_quality);
  placement.Validate();
  rig.Validate();
  render.Validate();
}

std::filesystem::path ResolveScene(const std::string& scene,
                                   const std::filesystem::path& data_dir) {
  std::filesystem::path path;
  if (const auto it = SceneNames().find(scene); it != SceneNames().end()) {
    CAROUSEL_THROW_IF(data_dir.empty(), InvalidArgument,
                      "scene '" << scene << "' needs the shared data folder (--data)");
    path = data_dir / it->second;
  } else if (scene.find('/') != std::string::npos || scene.find('.') != std::string::npos) {
    path = scene;
  } else {
    std::string known;
    for (const auto& [name, file] : SceneNames()) known += (known.empty() ? "" : ", ") + name;
    throw InvalidArgument("unknown scene '" + scene + "' (use " + known +
                          ", or a path to a .gltf, .glb or .obj file)");
  }
  if (!std::filesystem::exists(path)) throw IoError(path, "scene file does not exist");
  return path;
}

SimCaptureResult SimulateCapture(const SimCaptureOptions& options,
                                 const std::filesystem::path& session_folder, Progress& progress) {
  options.Validate();
  StagedSessionFolder folder(session_folder, options.overwrite);

  progress.BeginStage("load scene");
  const std::filesystem::path scene_path = ResolveScene(options.scene, options.data_dir);
  sim::Scene scene = sim::LoadScene(scene_path);
  const sim::Placement placement = sim::PlaceOnTurntable(scene, options.placement);
  const std::vector<CameraModel> rig = sim::MakeSimRig(options.rig, scene.Bounds());
  progress.EndStage();

  for (const char* sub : {"images", "backgrounds", "ground_truth/masks", "ground_truth/depth"}) {
    folder.CreateFolder(sub);
  }
  const std::filesystem::path& staging = folder.staging();

  Session session;
  // Depth unit: 0.1 mm, coarser when the farthest surface would not fit in 16 bits.
  double farthest = 0.0;
  const double radius = 0.5 * scene.Bounds().sizes().norm();
  for (const CameraModel& camera : rig) {
    farthest = std::max(farthest, (camera.Centre() - scene.Bounds().center()).norm() + radius);
  }
  session.ground_truth.depth_unit_m = std::max(1e-4, 1.05 * farthest / 65535.0);
  session.product = options.product.empty() ? options.scene : options.product;
  session.created_utc = NowUtc();
  session.source = "sim:" + scene_path.filename().string();
  session.frame = "turntable";
  session.ground_truth.mesh = "ground_truth/scene.ply";
  WriteMesh(scene.ToMesh(), staging / session.ground_truth.mesh);

  SimCaptureResult result;
  // Background plates: each camera's photo of the empty turntable (the difference method).
  for (int c = 0; c < static_cast<int>(rig.size()); ++c) {
    sim::Scene empty;
    empty.source = "empty turntable";
    sim::RenderOptions render = options.render;
    render.seed = options.render.seed * 7919ULL + 1000000ULL + static_cast<std::uint64_t>(c);
    WriteImage(staging / ("backgrounds/cam" + std::to_string(c) + ".jpg"),
               sim::Render(empty, rig[c], 0.0, render).image,
               {.jpeg_quality = options.jpeg_quality, .overwrite = false});
  }
  const int total = options.stops * static_cast<int>(rig.size());
  progress.BeginStage("render views");
  int done = 0;
  for (int stop = 0; stop < options.stops; ++stop) {
    const double angle_deg = 360.0 * stop / options.stops;
    const double angle = angle_deg * std::numbers::pi / 180.0;
    for (int c = 0; c < static_cast<int>(rig.size()); ++c) {
      progress.CheckCancelled();
      const CameraModel camera = sim::CameraAtTableAngle(rig[c], angle);
      sim::RenderOptions render = options.render;
      render.seed = options.render.seed * 1000003ULL + static_cast<std::uint64_t>(done);
      Stopwatch watch;
      const sim::RenderResult rendered = sim::Render(scene, camera, angle, render);
      result.render_seconds += watch.ElapsedSeconds();
      const std::string stem = ViewStem(c, stop);
      SessionView view;
      view.image = "images/" + stem + ".jpg";
      view.camera = c;
      view.stop = stop;
      view.table_angle_deg = angle_deg;
      view.camera_model = camera;
      WriteImage(staging / view.image, rendered.image,
                 {.jpeg_quality = options.jpeg_quality, .overwrite = false});
      const std::string mask = "ground_truth/masks/" + stem + ".png";
      const std::string depth = "ground_truth/depth/" + stem + ".png";
      WriteImage(staging / mask, rendered.mask, {.overwrite = false});
      cv::Mat depth16;
      rendered.depth.convertTo(depth16, CV_16U, 1.0 / session.ground_truth.depth_unit_m);
      WriteImage(staging / depth, depth16, {.png_compression = 1, .overwrite = false});
      session.views.push_back(view);
      session.ground_truth.masks.push_back(mask);
      session.ground_truth.depth.push_back(depth);
      progress.Report(++done, static_cast<std::size_t>(total));
    }
  }
  progress.EndStage();
  session.stages["capture"] = "done";
  WriteSessionManifest(staging, session);
  CAROUSEL_LOG_DEBUG("scene " << scene_path << " placed with scale " << placement.scale);

  folder.Commit();
  result.session = folder.target();
  result.views = total;
  return result;
}

}  // namespace carousel::studio
