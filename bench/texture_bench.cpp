// The texture stage on the simulated rig, timed: a capture session (16 x 5184x3456 by default)
// is rendered and reconstructed once into a work folder, then textured at the requested sizes
// with the time of every phase printed (the target: 4,500 faces, 16 photos of
// 5184x3456 -> an 8192^2 texture plus OBJ/PNG/GLB in <= 10 s on 2 cores, PNG encoding
// included). Held-out views (--exclude) are scored against their photos. A timed command-line
// run that prints its figures and the process's peak memory.
//
// --faces N: the texture paper's case, a mesh given: the simulator's true surface decimated
// to N faces (5,000 in the paper), textured from the same photos and masks (a session folder
// beside the reconstructed one, linking to its photos). Issue 26's target for 5k faces, 16 x
// 5184x3456 and 8192^2: <= 8 s end to end, >= 30 dB, <= 1.5 GB.
//
//   texture_bench [--scene shoe|bottle|...] [--width W] [--height H] [--stops N]
//                 [--sizes 8192,0] [--exclude 3,11] [--work DIR] [--faces N] [--no-blend]
//                 [--no-correction] [--no-gain] [--unlit] [--clean]
//   texture_bench --blob [--blob-faces 50000] [--blob-seeds N]   (blob_scene.h)
//
// --unlit: photos of the albedo alone (the lights fixed in the studio shade every photo
// differently as the table turns; no texture can agree with all of them): what is left of
// the held-out error is the texturing's own (geometry, resampling, seams). The model is then
// also scored against the product's true albedo (albedo_score.h) at a million points of the
// true surface that a used photo saw, next to what those photos themselves score there, and
// rendered into four of its own photos. --clean: no sensor noise and no vignetting.
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "albedo_score.h"
#include "bench_flags.h"
#include "blob_scene.h"
#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/progress.h"
#include "carousel/core/raster.h"
#include "carousel/core/timer.h"
#include "carousel/core/view.h"
#include "carousel/recon/mesh_optimization.h"
#include "carousel/sim/scene.h"
#include "carousel/studio/reconstruct.h"
#include "carousel/studio/session.h"
#include "carousel/studio/sim_capture.h"
#include "carousel/studio/texture_session.h"
#include "carousel/texture/held_out.h"
#include "carousel/texture/textured_model.h"

using namespace carousel;  // NOLINT(google-build-using-namespace)

namespace {

// A session beside `session` whose mesh is the simulator's true surface decimated to `faces`
// (the photos, masks and ground truth are links to the reconstructed session's).
std::filesystem::path GivenMeshSession(const std::filesystem::path& session, int faces) {
  namespace fs = std::filesystem;
  fs::path given = session.string() + "_given" + std::to_string(faces);
  if (fs::exists(given / "recon" / "mesh.ply")) return given;
  fs::remove_all(given);
  fs::create_directories(given / "recon");
  for (const char* entry : {"images", "masks", "backgrounds", "ground_truth"})
    fs::create_directory_symlink(fs::absolute(session / entry), given / entry);
  fs::copy_file(session / "session.json", given / "session.json");
  Mesh mesh = ReadMesh(session / "ground_truth" / "scene.ply");
  const recon::MeshOptimizationOptions defaults;
  const std::size_t left = recon::DecimateQuadric(&mesh, faces, defaults.max_normal_deviation_deg,
                                                  defaults.max_aspect_ratio);
  std::printf("given mesh: the true surface decimated to %zu faces\n", left);
  WriteMesh(mesh, given / "recon" / "mesh.ply");
  return given;
}

// The points of the true surface a photo that was used saw, and what the photos themselves score
// there (each point's colour in the photo that sees it most frontally, bilinear).
struct SeenPoints {
  std::vector<bench::SurfacePoint> points;
  std::vector<cv::Vec3d> photo_colours;  // per point
  double photos_db = 0.0;
};

// Seen: the point's own triangle is the one the exact rendering of the true surface shows at
// its pixel (core's RasterizeMesh: face ids; a shell's two sides and coincident layers are told
// apart) in a view not in `exclude`, and the exact depth map there is not nearer (the plate,
// which the true surface lacks, hides what is below it).
SeenPoints FindSeenPoints(const std::filesystem::path& session_folder, const sim::Scene& truth,
                          const std::vector<bench::SurfacePoint>& points,
                          const std::vector<int>& exclude) {
  const studio::Session session = studio::ReadSession(session_folder);
  std::vector<int> best_view(points.size(), -1);
  std::vector<double> best_cosine(points.size(), 0.0);
  for (std::size_t v = 0; v < session.views.size(); ++v) {
    if (std::find(exclude.begin(), exclude.end(), static_cast<int>(v)) != exclude.end()) continue;
    const CameraModel& camera = session.views[v].camera_model;
    const cv::Mat faces = RasterizeMesh(truth.positions, truth.triangles, camera).FaceIds();
    const cv::Mat depth =
        ReadImage(session_folder / session.ground_truth.depth[v], ImageReadMode::kUnchanged);
    if (depth.type() != CV_16UC1 || depth.size() != faces.size()) {
      throw FormatError(session_folder / session.ground_truth.depth[v],
                        "not a 16-bit depth map of the photo's size");
    }
    const double unit = session.ground_truth.depth_unit_m;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3d to_camera = (camera.Centre() - points[i].point).normalized();
      const double cosine = points[i].normal.dot(to_camera);
      if (cosine <= best_cosine[i]) continue;
      const std::optional<Eigen::Vector2d> pixel = camera.Project(points[i].point);
      if (!pixel) continue;
      const int x = static_cast<int>(std::lround(pixel->x()));
      const int y = static_cast<int>(std::lround(pixel->y()));
      if (x < 0 || y < 0 || x >= faces.cols || y >= faces.rows) continue;
      if (faces.at<int>(y, x) != static_cast<int>(points[i].triangle)) continue;
      const double z = (camera.cam_from_world * points[i].point).z();
      if (unit * depth.at<std::uint16_t>(y, x) < z - 1e-3) continue;
      best_view[i] = static_cast<int>(v);
      best_cosine[i] = cosine;
    }
  }
  SeenPoints seen;
  bench::GainCompensatedPsnr photos;
  for (std::size_t v = 0; v < session.views.size(); ++v) {
    if (std::find(best_view.begin(), best_view.end(), static_cast<int>(v)) == best_view.end())
      continue;
    const cv::Mat photo = ReadImage(session_folder / session.views[v].image);
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (best_view[i] != static_cast<int>(v)) continue;
      const Eigen::Vector2d pixel = *session.views[v].camera_model.Project(points[i].point);
      cv::Mat value;
      cv::getRectSubPix(photo, {1, 1},
                        cv::Point2f(static_cast<float>(pixel.x()), static_cast<float>(pixel.y())),
                        value, CV_32F);
      const cv::Vec3f c = value.at<cv::Vec3f>(0, 0);
      photos.Add({c[0], c[1], c[2]},
                 bench::TrueColour(truth, points[i].triangle, points[i].barycentrics));
      seen.points.push_back(points[i]);
      seen.photo_colours.emplace_back(c[0], c[1], c[2]);
    }
  }
  if (photos.count() > 0) seen.photos_db = photos.Db();
  return seen;
}

struct TruthScores {
  bench::SurfaceScore surface;
  double reprojected_db = 0.0;  // mean over the views scored
  std::vector<int> reprojected_views;
};

// The textured model `files` (the OBJ is Y-up, export.h: turntable (x, y, z) was written as
// (x, z, -y)) scored at `points` of the true surface, and rendered into four of the views that
// made it (the texture's own photos: what it reproduces of them, over their exact masks).
TruthScores ScoreAgainstTruth(const std::filesystem::path& session_folder, const sim::Scene& truth,
                              const SeenPoints& seen, const texture::ExportResult& files,
                              const std::vector<int>& exclude) {
  Mesh model = ReadMesh(files.obj);
  for (const auto v : model.vertices()) {
    const Mesh::Point q = model.point(v);
    model.set_point(v, Mesh::Point(q[0], -q[2], q[1]));
  }
  const cv::Mat texture = ReadImage(files.texture);
  TruthScores scores;
  scores.surface =
      bench::ScoreAgainstScene(truth, seen.points, model, texture, &seen.photo_colours);
  const texture::TexturedModel textured = texture::TexturedModelFromMesh(model, texture);
  const studio::Session session = studio::ReadSession(session_folder);
  std::vector<texture::HeldOutScore> reprojected;
  const int count = static_cast<int>(session.views.size());
  for (int v = 0; v < count && reprojected.size() < 4; v += std::max(1, count / 4)) {
    int used = v;
    while (used < count && std::find(exclude.begin(), exclude.end(), used) != exclude.end()) ++used;
    if (used >= count) break;
    const auto& view = session.views[static_cast<std::size_t>(used)];
    reprojected.push_back(texture::ScoreHeldOutView(
        textured, View(view.camera_model, session_folder / view.image), used,
        ReadMask(session_folder / session.ground_truth.masks[static_cast<std::size_t>(used)])));
    scores.reprojected_views.push_back(used);
  }
  scores.reprojected_db = texture::MeanPsnrDb(reprojected);
  return scores;
}

int Run(int argc, char** argv) {
  std::string scene = "shoe";
  int width = 5184, height = 3456, stops = 16;
  std::vector<int> sizes = {8192, 0}, exclude;
  std::filesystem::path work = std::filesystem::temp_directory_path() / "carousel_texture_bench";
  bool no_blend = false, no_correction = false, no_gain = false;
  int given_faces = 0;
  bool unlit = false, clean = false, blob = false;
  bench::BlobSceneOptions blob_options;
  texture::GroupingOptions grouping;
  texture::TransferOptions transfer;
  BenchFlags flags(argc, argv, "texture_bench: the texture stage of a simulated session, timed");
  flags.Option("--scene", &scene, "shoe, bottle, avocado, duck")
      .Option("--width", &width)
      .Option("--height", &height)
      .Option("--stops", &stops)
      .List("--sizes", &sizes, "texture sizes, 0 = automatic")
      .List("--exclude", &exclude, "held-out views")
      .Option("--work", &work, "folder for the session (kept between runs)")
      .Option("--faces", &given_faces,
              "texture the true surface decimated to N faces, 0 = the reconstruction's")
      .Flag("--unlit", &unlit,
            "photos of the albedo alone (no studio lights): texturing error only")
      .Flag("--clean", &clean, "photos without sensor noise and vignetting")
      .Flag("--blob", &blob, "the noisy-blob scene instead (procedural albedo, per-view gains)")
      .Option("--blob-faces", &blob_options.faces, "faces of the blob, about")
      .Option("--blob-seeds", &blob_options.seeds, "blobs 1..N")
      .Flag("--no-blend", &no_blend)
      .Flag("--no-correction", &no_correction)
      .Flag("--no-gain", &no_gain)
      .Option("--seam-cost", &grouping.seam_cost, "coherent front views (texture_map.h)")
      .Option("--min-cosine-ratio", &grouping.min_cosine_ratio)
      .Option("--zbuffer-max-side", &grouping.zbuffer_max_side)
      .Option("--texel-zbuffer-max-side", &transfer.zbuffer_max_side, "0 = no per-texel test");
  if (const std::optional<int> exit_code = flags.Parse(std::cout, std::cerr)) return *exit_code;
  if (blob) return bench::RunBlobScene(blob_options);
  const bool blend = !no_blend, correction = !no_correction, gain = !no_gain;
  try {
    Progress progress;
    std::filesystem::path session =
        work / (scene + "_" + std::to_string(width) + "x" + std::to_string(height) + "_" +
                std::to_string(stops) + (unlit ? "_unlit" : "") + (clean ? "_clean" : ""));
    studio::SimCaptureOptions capture;
    capture.scene = scene;
    const char* env = std::getenv("CAROUSEL_SHARED_DATA_DIR");
    capture.data_dir = env != nullptr && *env ? env : CAROUSEL_DEFAULT_SHARED_DATA_DIR;
    capture.stops = stops;
    capture.render.lit = !unlit;
    if (clean) {
      capture.render.noise_sigma = 0.0;
      capture.render.vignetting = 0.0;
    }
    capture.rig.width = width;
    capture.rig.height = height;
    if (!std::filesystem::exists(session / "recon" / "mesh.ply")) {
      std::filesystem::remove_all(session);
      std::filesystem::create_directories(work);
      Stopwatch watch;
      studio::SimulateCapture(capture, session, progress);
      std::printf("capture: %d x %dx%d in %.1f s\n", stops, width, height, watch.ElapsedSeconds());
      watch = Stopwatch();
      const studio::ReconstructResult r = studio::ReconstructSession(session, {}, progress);
      std::printf("reconstruct: %zu faces in %.1f s\n", r.mesh_faces, watch.ElapsedSeconds());
    }
    // The product as the capture placed it: the truth the texture is scored against.
    sim::Scene truth = sim::LoadScene(studio::ResolveScene(capture.scene, capture.data_dir));
    truth.OverrideMaterials(capture.material);
    sim::PlaceOnTurntable(truth, capture.placement);
    if (given_faces > 0) session = GivenMeshSession(session, given_faces);
    constexpr int kScorePoints = 1000000;
    SeenPoints seen;
    for (const int size : sizes) {
      studio::TextureSessionOptions options;
      options.grouping = grouping;
      options.atlas.size.size = size;
      options.grouping.exclude_views = exclude;
      options.grouping.correction = correction;
      options.transfer = transfer;
      options.transfer.blend = blend;
      options.transfer.gain = gain;
      const studio::TextureSessionResult t = studio::TextureSession(session, options, progress);
      std::printf(
          "texture %s%d^2: %zu faces, %d charts, %d views; grouping %.2f s, atlas %.2f s, transfer "
          "%.2f s, "
          "export %.2f s (PNG %.2f s, OBJ %.2f s, GLB %.2f s, %.1f MB); total %.2f s (evaluation "
          "%.2f s "
          "apart)\n",
          size == 0 ? "auto " : "", t.size, t.faces, t.charts, t.views, t.seconds_grouping,
          t.seconds_atlas, t.seconds_transfer, t.seconds_export, t.files.seconds_png,
          t.files.seconds_obj, t.files.seconds_glb, static_cast<double>(t.files.glb_bytes) / 1e6,
          t.seconds_total - t.seconds_evaluation, t.seconds_evaluation);
      std::printf("  density: %.1f %% of faces >= 1 texel per photo pixel; faces by texels:",
                  100.0 * t.dense_fraction);
      for (std::size_t i = 0; i < t.histogram_counts.size(); ++i)
        std::printf(" [%d..] %d", t.histogram_edges[i], t.histogram_counts[i]);
      std::printf(
          "\n  grouping: %d moved off the background, %d unseen (filled); texels from other "
          "views: %d (background in the front one), %d (hidden in it); %d inpainted, %d "
          "blended\n",
          t.grouping.corrected_faces, t.grouping.unseen_faces, t.corrected_texels,
          t.occluded_texels, t.inpainted_texels, t.blended_texels);
      if (!t.held_out.empty())
        std::printf("  held out: PSNR %.2f dB, SSIM %.4f\n", t.mean_psnr_db, t.mean_ssim);
      rusage usage{};
      getrusage(RUSAGE_SELF, &usage);
      std::printf("  peak memory so far: %.0f MB\n", static_cast<double>(usage.ru_maxrss) / 1024.0);
      if (unlit) {
        // Lit photos shade the albedo (lights fixed while the table turns): only unlit ones
        // can be compared with it.
        Stopwatch watch;
        if (seen.points.empty()) {
          seen =
              FindSeenPoints(session, truth, bench::SampleScene(truth, kScorePoints, 1), exclude);
        }
        const TruthScores scores = ScoreAgainstTruth(session, truth, seen, t.files, exclude);
        const bench::SurfaceScore& s = scores.surface;
        std::printf(
            "  vs the true albedo: PSNR %.2f dB (gain-compensated) at %zu of %d points of the "
            "true surface (those a photo saw; the photos themselves there: %.2f dB); the model is "
            "%.3f mm from them on average, 95 %% within %.3f mm\n",
            s.psnr_db, s.points, kScorePoints, seen.photos_db, s.mean_distance_mm,
            s.p95_distance_mm);
        std::printf("    by distance from the model (mm: points, texture dB / photos dB):");
        for (const auto& band : s.bands) {
          std::printf(" [%g, %g) %zu %.2f/%.2f;", band.from_mm, band.to_mm, band.points,
                      band.psnr_db, band.reference_db);
        }
        std::printf(" the worst 1 %% of points hold %.0f %% of the squared error\n",
                    100.0 * s.worst_percent_error_share);
        std::printf("  rendered into its own photos (views");
        for (const int v : scores.reprojected_views) std::printf(" %d", v);
        std::printf("): PSNR %.2f dB (scoring %.1f s)\n", scores.reprojected_db,
                    watch.ElapsedSeconds());
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "texture_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "texture_bench: %s\n", e.what());
    return 1;
  }
}
