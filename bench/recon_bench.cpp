// Reconstruction on the simulated rig, timed and measured against ground truth: silhouettes
// (IoU per view), visual hull (containment, Chamfer and Hausdorff distances to the true
// surface), optimized mesh (faces, topology, self-intersections, distance and volume vs the
// hull). A timed command-line run that prints its figures (the targets: hull <= 5 s,
// whole stage <= 15 s for 16 views of 5184x3456 on 2 cores).
//
//   recon_bench [--scene shoe|bottle|avocado|duck|ring|sphere|mug] [--width W] [--height H]
//               [--stops N] [--voxel-px P] [--resolution R] [--max-resolution R] [--faces F]
//               [--method auto|key|difference|backlit] [--mask-shots] [--size-m S]
//               [--noise SIGMA] [--jpeg Q] [--material none|white|black|glossy|see-through]
//               [--backdrop light|white|grey|black|green] [--exposure E] [--contact-shadow C]
//               [--cast-shadow C] [--vignetting V] [--falloff F] [--seed N] [--truth-masks]
//               [--save DIR]
// With --mask-shots every view also gets its backlit mask shot (method auto takes them).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <utility>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bench_flags.h"
#include "carousel/core/image_io.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/mesh_query.h"
#include "carousel/core/parallel.h"
#include "carousel/core/progress.h"
#include "carousel/core/timer.h"
#include "carousel/recon/recon.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_session.h"
#include "carousel/sim/test_scenes.h"
#include "carousel/studio/sim_capture.h"

namespace {

using namespace carousel;  // NOLINT(google-build-using-namespace)

std::filesystem::path DataDir() {
  const char* env = std::getenv("CAROUSEL_SHARED_DATA_DIR");
  return env != nullptr && *env ? env : CAROUSEL_DEFAULT_SHARED_DATA_DIR;
}

sim::Scene MakeScene(const std::string& name, double size_m) {
  if (name == "ring") return sim::MakeRingScene(0.4 * size_m, 0.1 * size_m);
  if (name == "sphere") return sim::MakeSphereScene(0.5 * size_m, {0.0, 0.0, 0.5 * size_m});
  if (name == "mug") return sim::MakeMugScene(0.6 * size_m);
  sim::Scene scene = sim::LoadScene(studio::ResolveScene(name, DataDir()));
  sim::PlaceOnTurntable(scene, {.scale = 1.0});
  const double longest = scene.Bounds().sizes().maxCoeff();
  const double height = scene.Bounds().sizes().z();
  sim::PlaceOnTurntable(scene, {.target_height_m = height * size_m / longest});
  return scene;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_name = "shoe";
  std::string method = "auto";
  std::string material = "none", backdrop = "light";
  std::string save;
  bool mask_shots = false, no_multi_view = false;
  double exposure = 1.0, contact_shadow = 0.0, cast_shadow = 0.0, vignetting = 0.0, falloff = 0.0;
  std::uint64_t seed = 0;
  int samples = sim::RenderOptions().samples_per_axis;
  int width = 5184, height = 3456, stops = 16, faces = 4500, resolution = 0, jpeg = 95;
  int max_resolution = recon::VisualHullOptions().max_resolution;
  double voxel_px = recon::VisualHullOptions().voxel_px, size_m = 0.25, noise = 1.5;
  bool truth_masks = false;
  bool silhouettes_only = false;
  BenchFlags flags(argc, argv,
                   "recon_bench: reconstruction on the simulated rig, measured against the truth");
  flags.Option("--scene", &scene_name, "shoe, bottle, ring, sphere")
      .Option("--width", &width)
      .Option("--height", &height)
      .Option("--stops", &stops, "turntable stops")
      .Option("--voxel-px", &voxel_px, "automatic voxel size: pixels a voxel spans")
      .Option("--resolution", &resolution, "voxels along the longest side, 0 = from --voxel-px")
      .Option("--max-resolution", &max_resolution,
              "at most this many voxels along the longest side")
      .Option("--faces", &faces, "faces of the optimized mesh")
      .Option("--method", &method, "silhouettes: auto, key, difference or backlit")
      .Flag("--mask-shots", &mask_shots, "render a backlit mask shot beside every photo")
      .Flag("--no-multi-view", &no_multi_view, "silhouettes without the multi-view step")
      .Option("--material", &material, "none, white, black, glossy or see-through")
      .Option("--backdrop", &backdrop, "light (default), white, grey, black or green")
      .Option("--exposure", &exposure, "exposure of the object and plate")
      .Option("--contact-shadow", &contact_shadow, "contact shadow on the plate, 0..1")
      .Option("--cast-shadow", &cast_shadow, "the key light's cast shadow, 0..1")
      .Option("--vignetting", &vignetting, "lens vignetting in the corners, 0..0.9")
      .Option("--falloff", &falloff, "backdrop light falloff in the corners, 0..0.9")
      .Option("--seed", &seed, "render noise seed")
      .Option("--samples", &samples, "anti-aliasing samples per pixel and axis")
      .Option("--size-m", &size_m, "longest side of the object, metres")
      .Option("--noise", &noise, "render noise sigma, grey levels")
      .Option("--jpeg", &jpeg, "JPEG quality")
      .Flag("--truth-masks", &truth_masks, "carve the hull from the true masks")
      .Flag("--silhouettes-only", &silhouettes_only, "stop after the silhouettes")
      .Option("--save", &save, "folder for masks and meshes, empty = none");
  if (const std::optional<int> exit_code = flags.Parse(std::cout, std::cerr)) return *exit_code;
  try {
    sim::Scene scene = MakeScene(scene_name, size_m);
    scene.OverrideMaterials(sim::ParseMaterialOverride(material));
    sim::SimViewsOptions sim_options;
    if (backdrop != "light") {
      const Eigen::Vector3d colour = studio::ParseBackdropColour(backdrop, "backdrop");
      sim_options.render.backdrop_top = colour;
      sim_options.render.backdrop_bottom = 0.9 * colour;
    }
    sim_options.render.exposure = exposure;
    sim_options.render.contact_shadow = contact_shadow;
    sim_options.render.cast_shadow = cast_shadow;
    sim_options.render.vignetting = vignetting;
    sim_options.render.backdrop_falloff = falloff;
    sim_options.render.seed = seed;
    sim_options.render.samples_per_axis = samples;
    sim_options.mask_shots = mask_shots;
    sim_options.rig.width = width;
    sim_options.rig.height = height;
    sim_options.stops = stops;
    sim_options.render.noise_sigma = noise;
    sim_options.jpeg_quality = jpeg;
    sim_options.backgrounds = method == "difference";
    Stopwatch watch;
    sim::SimViews sim_views = sim::RenderViews(scene, sim_options);
    const Eigen::Vector3d extent = scene.Bounds().sizes();
    std::printf("scene %s: %.1f x %.1f x %.1f mm, %zu views %dx%d rendered in %.1f s\n",
                scene_name.c_str(), extent.x() * 1e3, extent.y() * 1e3, extent.z() * 1e3,
                sim_views.views.size(), width, height, watch.ElapsedSeconds());

    Stopwatch since_start;
    Progress progress([&](const ProgressUpdate& update) {
      if (update.fraction == 0.0 && !update.stage_done)
        std::fprintf(stderr, "[%7.2f s] %s\n", since_start.ElapsedSeconds(), update.stage.c_str());
    });
    // The yardstick: decoding the same photos as JPEG files, in parallel as the silhouettes
    // run (issue 20: silhouettes within 2x of it).
    const std::vector<View>& inputs = mask_shots ? sim_views.mask_shots : sim_views.views;
    std::vector<std::vector<std::uint8_t>> jpegs(inputs.size());
    for (std::size_t i = 0; i < jpegs.size(); ++i)
      cv::imencode(".jpg", inputs[i].Image(), jpegs[i], {cv::IMWRITE_JPEG_QUALITY, 95});
    Stopwatch decode_watch;
    ParallelFor(jpegs.size(), 1, 0, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        const cv::Mat decoded = cv::imdecode(jpegs[i], cv::IMREAD_COLOR);
        if (decoded.empty()) std::abort();
      }
    });
    const double decode_seconds = decode_watch.ElapsedSeconds();
    jpegs.clear();
    Stopwatch stage;
    recon::SilhouetteOptions silhouette_options;
    silhouette_options.method = recon::ParseSilhouetteMethod(method);
    silhouette_options.multi_view = !no_multi_view;
    const auto silhouettes =
        recon::ComputeSilhouettes(sim_views.views, sim_views.backgrounds, silhouette_options,
                                  progress, {}, sim_views.mask_shots);
    const std::string resolved = recon::SilhouetteMethodName(recon::ResolveSilhouetteMethod(
        silhouette_options.method, sim_views.views.size(), sim_views.mask_shots.size()));
    const double silhouette_seconds = stage.ElapsedSeconds();
    double min_iou = 1.0, sum_iou = 0.0;
    std::string worst_view;
    for (std::size_t i = 0; i < sim_views.views.size(); ++i) {
      const double iou = recon::MaskIoU(silhouettes.masks[i], sim_views.truth_masks[i]);
      sum_iou += iou;
      if (iou < min_iou) {
        min_iou = iou;
        worst_view = sim_views.views[i].name();
      }
      sim_views.views[i].SetMask(truth_masks ? sim_views.truth_masks[i] : silhouettes.masks[i]);
      if (!save.empty()) {
        WriteImage(std::filesystem::path(save) / (sim_views.views[i].name() + "_mask.png"),
                   silhouettes.masks[i]);
        WriteImage(std::filesystem::path(save) / (sim_views.views[i].name() + "_truth.png"),
                   sim_views.truth_masks[i]);
        WriteImage(std::filesystem::path(save) / (inputs[i].name() + ".png"), inputs[i].Image());
        // Where the mask is wrong, at most 1296 pixels wide: red = missed, green = extra.
        const cv::Mat ours = silhouettes.masks[i] >= 128;
        const cv::Mat truth = sim_views.truth_masks[i] >= 128;
        cv::Mat diff;
        cv::merge(std::vector<cv::Mat>{cv::Mat::zeros(ours.size(), CV_8UC1), ours & ~truth,
                                       truth & ~ours},
                  diff);
        diff.setTo(cv::Scalar(60, 60, 60), ours & truth);
        const double scale = std::min(1.0, 1296.0 / diff.cols);
        cv::Mat small;
        cv::resize(diff, small, cv::Size(), scale, scale, cv::INTER_AREA);
        small.convertTo(small, CV_8UC3, 4.0);
        WriteImage(std::filesystem::path(save) / (sim_views.views[i].name() + "_maskdiff.png"),
                   small);
      }
    }
    std::printf("decoding the %zu photos as JPEG: %.2f s; silhouettes %.2fx that\n",
                sim_views.views.size(), decode_seconds, silhouette_seconds / decode_seconds);
    std::printf("silhouettes (%s): %.2f s; IoU min %.5f (%s), mean %.5f\n", resolved.c_str(),
                silhouette_seconds, min_iou, worst_view.c_str(),
                sum_iou / static_cast<double>(sim_views.views.size()));

    if (silhouettes_only) return 0;
    recon::VisualHullOptions hull_options;
    hull_options.voxel_px = voxel_px;
    hull_options.resolution = resolution;
    hull_options.max_resolution = max_resolution;
    stage.Restart();
    const auto hull = recon::ComputeVisualHull(sim_views.views, hull_options, progress);
    const double hull_seconds = stage.ElapsedSeconds();
    const double voxel = hull.voxel_size_m;
    std::printf(
        "visual hull: %.2f s (distance %.2f, carve %.2f, surface %.2f); voxel %.3f mm, "
        "grid %dx%dx%d, %zu surface cells, %zu faces, %zu pieces dropped; proxy level %d, "
        "%zu faces\n",
        hull_seconds, hull.seconds_distance, hull.seconds_carve, hull.seconds_surface, voxel * 1e3,
        hull.grid.x(), hull.grid.y(), hull.grid.z(), hull.surface_cells, hull.mesh.n_faces(),
        hull.components_dropped, hull.proxy_level, hull.proxy.n_faces());

    if (!save.empty()) WriteMesh(hull.mesh, std::filesystem::path(save) / "hull.ply");
    recon::MeshOptimizationOptions mesh_options;
    mesh_options.target_faces = faces;
    stage.Restart();
    mesh_options.target_volume_m3 = hull.volume_m3;
    const auto optimized = recon::OptimizeMesh(hull.OptimizationInput(), mesh_options, progress);
    const double mesh_seconds = stage.ElapsedSeconds();
    std::printf("mesh: %.2f s (smooth %.2f, decimate %.2f, remesh %.2f); %zu faces\n", mesh_seconds,
                optimized.seconds_smooth, optimized.seconds_decimate, optimized.seconds_remesh,
                optimized.mesh.n_faces());
    std::printf("stage total (silhouettes + hull + mesh): %.2f s\n",
                silhouette_seconds + hull_seconds + mesh_seconds);

    const auto truth_to_hull = MeasureSurfaceDistance(sim_views.truth_mesh, hull.mesh, 20000);
    const Containment containment = MeasureContainment(sim_views.truth_mesh, hull.mesh);
    std::printf(
        "hull vs truth: Chamfer %.3f mm, Hausdorff %.3f mm, truth->hull mean %.3f mm "
        "(%.2f voxels), truth outside hull by at most %.3f mm (%.2f voxels)\n",
        truth_to_hull.chamfer() * 1e3, truth_to_hull.hausdorff() * 1e3,
        truth_to_hull.mean_a_to_b * 1e3, truth_to_hull.mean_a_to_b / voxel,
        containment.max_outside * 1e3, containment.max_outside / voxel);
    const auto mesh_to_hull = MeasureSurfaceDistance(optimized.mesh, hull.mesh, 20000);
    const auto topology = AnalyzeTopology(optimized.mesh);
    const auto intersections = FindSelfIntersections(optimized.mesh, 10);
    std::printf(
        "optimized vs hull: mean %.3f mm (%.2f voxels), Hausdorff %.3f mm; volume %+.3f %%; "
        "closed %d, manifold %d, components %zu, self-intersections %zu\n",
        mesh_to_hull.mean_a_to_b * 1e3, mesh_to_hull.mean_a_to_b / voxel,
        mesh_to_hull.hausdorff() * 1e3, 100.0 * (optimized.volume_m3 / hull.volume_m3 - 1.0),
        topology.closed(), topology.manifold(), topology.components, intersections.size());
    for (const auto& [label, mesh] : {std::pair<const char*, const Mesh*>{"hull", &hull.mesh},
                                      {"optimized", &optimized.mesh}}) {
      Stopwatch agreement_watch;
      const auto agreement = recon::MeasureSilhouetteAgreement(*mesh, sim_views.views);
      double worst_iou = 1.0, mean_deviation = 0.0, max_deviation = 0.0, max_mean_deviation = 0.0;
      for (const auto& a : agreement) {
        worst_iou = std::min(worst_iou, a.iou);
        mean_deviation += a.mean_deviation_px / static_cast<double>(agreement.size());
        max_mean_deviation = std::max(max_mean_deviation, a.mean_deviation_px);
        max_deviation = std::max(max_deviation, a.max_deviation_px);
      }
      std::printf(
          "%s vs silhouettes: IoU min %.5f; outline deviation mean %.2f px (worst view %.2f px), "
          "max %.1f px (measured in %.1f s)\n",
          label, worst_iou, mean_deviation, max_mean_deviation, max_deviation,
          agreement_watch.ElapsedSeconds());
    }
    const auto mesh_to_truth = MeasureSurfaceDistance(optimized.mesh, sim_views.truth_mesh, 20000);
    std::printf("optimized vs truth: Chamfer %.3f mm, Hausdorff %.3f mm\n",
                mesh_to_truth.chamfer() * 1e3, mesh_to_truth.hausdorff() * 1e3);
    if (!save.empty()) {
      WriteMesh(optimized.mesh, std::filesystem::path(save) / "mesh.ply");
    }
  } catch (const std::exception& error) {
    std::fprintf(stderr, "recon_bench: %s\n", error.what());
    return 1;
  }
  return 0;
}
