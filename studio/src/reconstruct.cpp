#include "carousel/studio/reconstruct.h"

#include <map>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/parallel.h"
#include "carousel/core/timer.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

// Background plates per view for the difference method, one file per camera.
std::vector<cv::Mat> LoadBackgrounds(const std::filesystem::path& folder, const Session& session) {
  std::map<int, cv::Mat> per_camera;
  std::vector<cv::Mat> backgrounds;
  for (const SessionView& view : session.views) {
    auto it = per_camera.find(view.camera);
    if (it == per_camera.end()) {
      const std::string stem = "backgrounds/cam" + std::to_string(view.camera);
      std::filesystem::path path = folder / (stem + ".jpg");
      if (!std::filesystem::exists(path)) path = folder / (stem + ".png");
      if (!std::filesystem::exists(path))
        throw IoError(folder / (stem + ".jpg"),
                      "no background plate for camera " + std::to_string(view.camera) +
                          " (the difference method needs a photo of the empty turntable)");
      cv::Mat image = ReadImage(path);
      if (image.cols != view.camera_model.width || image.rows != view.camera_model.height)
        throw FormatError(path, "background plate is " + std::to_string(image.cols) + "x" +
                                    std::to_string(image.rows) + ", the camera's photos are " +
                                    std::to_string(view.camera_model.width) + "x" +
                                    std::to_string(view.camera_model.height));
      it = per_camera.emplace(view.camera, image).first;
    }
    backgrounds.push_back(it->second);
  }
  return backgrounds;
}

}  // namespace

const OptionTable<ReconstructOptions>& ReconstructOptions::Fields() {
  static const OptionTable<ReconstructOptions> table =
      OptionTable<ReconstructOptions>()
          .Include(&ReconstructOptions::silhouettes, recon::SilhouetteOptions::Fields())
          .Include(&ReconstructOptions::hull, recon::VisualHullOptions::Fields())
          .Include(&ReconstructOptions::mesh, recon::MeshOptimizationOptions::Fields());
  return table;
}

void ReconstructOptions::Validate() const {
  silhouettes.Validate();
  hull.Validate();
  mesh.Validate();
}

ReconstructResult ReconstructSession(const std::filesystem::path& session_folder,
                                     const ReconstructOptions& options, Progress& progress) {
  options.Validate();  // a bad option is named before any file is read
  Session session = ReadSession(session_folder);
  return ReconstructSession(session_folder, session, options, progress);
}

ReconstructResult ReconstructSession(const std::filesystem::path& session_folder, Session& session,
                                     const ReconstructOptions& requested, Progress& progress) {
  requested.Validate();
  if (session.views.size() < 2)
    throw FormatError(session_folder / kManifestName,
                      "a reconstruction needs at least 2 views, the session has " +
                          std::to_string(session.views.size()));
  ReconstructOptions options = requested;
  if (session.frame != "turntable") {
    // Not on our turntable: no plate to remove, no floor to stand on.
    options.silhouettes.plate_radius_m = 0.0;
    options.hull.use_floor = false;
  }
  std::vector<View> views = SessionViews(session_folder, session);
  ReconstructResult result;
  result.views = static_cast<int>(views.size());

  // Silhouettes -> masks/.
  Stopwatch watch;
  std::vector<cv::Mat> backgrounds;
  if (options.silhouettes.method == recon::SilhouetteMethod::kDifference)
    backgrounds = LoadBackgrounds(session_folder, session);
  const recon::SilhouettesResult silhouettes =
      recon::ComputeSilhouettes(views, backgrounds, options.silhouettes, progress, options.hull);
  std::filesystem::create_directories(session_folder / "masks");
  result.min_mask_fraction = 1.0;
  // The masks are encoded in parallel (18 MP PNGs take a few tenths of a second each); binary
  // masks compress well at the fastest level.
  ParallelFor(views.size(), 1, options.hull.threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const std::string mask =
          "masks/" + std::filesystem::path(session.views[i].image).stem().string() + ".png";
      WriteImage(session_folder / mask, silhouettes.masks[i], {.png_compression = 1});
    }
  });
  for (std::size_t i = 0; i < views.size(); ++i) {
    const std::string mask =
        "masks/" + std::filesystem::path(session.views[i].image).stem().string() + ".png";
    session.views[i].mask = mask;
    views[i].set_mask_path(session_folder / mask);
    views[i].SetMask(silhouettes.masks[i]);
    result.min_mask_fraction =
        std::min(result.min_mask_fraction, silhouettes.stats[i].object_fraction);
  }
  result.seconds_silhouettes = watch.ElapsedSeconds();

  // Visual hull -> recon/hull.ply.
  watch.Restart();
  const recon::VisualHullResult hull = recon::ComputeVisualHull(views, options.hull, progress);
  std::filesystem::create_directories(session_folder / "recon");
  WriteMesh(hull.mesh, session_folder / "recon/hull.ply");
  result.hull_faces = hull.mesh.n_faces();
  result.voxel_size_m = hull.voxel_size_m;
  result.seconds_hull = watch.ElapsedSeconds();

  // Optimized mesh -> recon/mesh.ply.
  watch.Restart();
  recon::MeshOptimizationOptions mesh_options = options.mesh;
  mesh_options.target_volume_m3 = hull.volume_m3;
  const recon::MeshOptimizationResult mesh =
      recon::OptimizeMesh(hull.OptimizationInput(), mesh_options, progress);
  WriteMesh(mesh.mesh, session_folder / "recon/mesh.ply");
  result.mesh_faces = mesh.mesh.n_faces();
  result.seconds_mesh = watch.ElapsedSeconds();

  // How well the mesh reproduces the silhouettes: calibration or mask trouble shows here.
  watch.Restart();
  result.agreement = recon::MeasureSilhouetteAgreement(mesh.mesh, views, options.hull.threads);
  result.seconds_agreement = watch.ElapsedSeconds();

  session.stages["reconstruct"] = "done";
  session.stage_seconds["reconstruct/silhouettes"] = result.seconds_silhouettes;
  session.stage_seconds["reconstruct/hull"] = result.seconds_hull;
  session.stage_seconds["reconstruct/mesh"] = result.seconds_mesh;
  session.stage_seconds["reconstruct/agreement"] = result.seconds_agreement;
  WriteSessionManifest(session_folder, session);
  return result;
}

}  // namespace carousel::studio
