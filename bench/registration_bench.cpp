// The second pass (the product laid down another way) on the simulated rig, registered and
// measured against the simulator's truth: registration error (rotation, and the largest
// displacement of the true surface), residual, ambiguity, the time; with --model also the
// whole reconstruction and texture of both passes: hull volume error vs the true mesh for one
// and two passes, the faces seen by no view, and the PSNR of views from below (which no photo
// shows) against held-out side views. A timed command-line run that prints its figures
// (issue 24: registration of 16 + 16 views of 5184x3456 in <= 5 s on 2 cores).
//
//   registration_bench [--scene shoe] [--pose side|upside-down|random] [--seeds 1,2,3]
//                      [--size 1296x864] [--views 16] [--backdrop light] [--mask-shots none]
//                      [--truth-masks] [--unlit] [--model] [--keep DIR]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "bench_flags.h"
#include "carousel/core/image_io.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/mesh_query.h"
#include "carousel/core/progress.h"
#include "carousel/core/timer.h"
#include "carousel/recon/recon.h"
#include "carousel/recon/reprojection.h"
#include "carousel/studio/pipeline.h"
#include "carousel/studio/reconstruct.h"
#include "carousel/studio/session.h"
#include "carousel/studio/sim_capture.h"
#include "carousel/studio/texture_session.h"
#include "carousel/texture/held_out.h"
#include "carousel/texture/textured_model.h"

namespace {

using namespace carousel;  // NOLINT(google-build-using-namespace)

std::filesystem::path DataDir() {
  const char* env = std::getenv("CAROUSEL_SHARED_DATA_DIR");
  return env != nullptr && *env ? env : CAROUSEL_DEFAULT_SHARED_DATA_DIR;
}

// The largest displacement of the true surface's vertices between two poses, metres.
double Displacement(const Mesh& mesh, const Rigid3d& a, const Rigid3d& b) {
  double worst = 0.0;
  for (const auto vertex : mesh.vertices()) {
    const auto& p = mesh.point(vertex);
    const Eigen::Vector3d x(p[0], p[1], p[2]);
    worst = std::max(worst, (a * x - b * x).norm());
  }
  return worst;
}

std::vector<View> PassViews(const std::filesystem::path& folder, const studio::Session& session,
                            int pass, bool truth_masks) {
  std::vector<View> views;
  for (std::size_t i = 0; i < session.views.size(); ++i) {
    const studio::SessionView& entry = session.views[i];
    if (entry.pass != pass) continue;
    View view(entry.camera_model, folder / entry.image,
              folder / (truth_masks ? session.ground_truth.masks[i] : entry.mask));
    views.push_back(std::move(view));
  }
  return views;
}

struct ModelFigures {
  double hull_volume_m3 = 0.0;
  std::size_t faces = 0;
  int unseen_faces = 0;
  double held_out_psnr = 0.0;  // side views of pass 0, left out of the texture
  double below_psnr = 0.0;     // the evaluation views from below
};

// Texture the reconstructed session with some side views of pass 0 held out, and score the
// model from below.
ModelFigures ScoreModel(const std::filesystem::path& folder, bool gain, Progress& progress) {
  studio::Session session = studio::ReadSession(folder);
  ModelFigures figures;
  figures.hull_volume_m3 = SignedVolume(ReadMesh(folder / "recon/hull.ply"));
  studio::TextureSessionOptions options;
  options.transfer.gain = gain;
  int first_pass = 0;
  for (const studio::SessionView& view : session.views) first_pass += view.pass == 0 ? 1 : 0;
  for (int k = 0; k < 4; ++k) options.grouping.exclude_views.push_back(2 + k * first_pass / 4);
  const studio::TextureSessionResult textured =
      studio::TextureSession(folder, session, options, progress);
  figures.faces = textured.faces;
  figures.unseen_faces = textured.grouping.unseen_faces;
  figures.held_out_psnr = textured.mean_psnr_db;
  const texture::TexturedModel model = texture::ReadTexturedModel(textured.files.glb);
  std::vector<texture::HeldOutScore> below;
  for (const studio::EvalView& eval : session.ground_truth.eval_views) {
    const View view(eval.camera_model, folder / eval.image);
    below.push_back(texture::ScoreHeldOutView(model, view, static_cast<int>(below.size()),
                                              ReadMask(folder / eval.mask)));
    // Beside the photo, for a look: the model from there.
    const texture::ModelRendering rendering =
        texture::RenderTexturedModel(model, eval.camera_model);
    cv::Mat pair;
    cv::hconcat(view.Image(), rendering.image, pair);
    WriteImage(folder / (std::filesystem::path(eval.image).stem().string() + "_vs_model.png"), pair,
               {.overwrite = true});
  }
  figures.below_psnr = texture::MeanPsnrDb(below);
  return figures;
}

// The mesh's silhouettes against the simulator's exact ones, per pass (the second pass's
// cameras brought into the object frame by the true pose): mean IoU and mean deviation.
struct PassAgreement {
  double iou = 0.0, deviation_px = 0.0;
};
std::vector<PassAgreement> TrueSilhouetteAgreement(const Mesh& mesh,
                                                   const std::filesystem::path& folder,
                                                   const studio::Session& session) {
  std::vector<PassAgreement> passes(session.ground_truth.table_from_object.size());
  std::vector<int> counts(passes.size(), 0);
  for (std::size_t i = 0; i < session.views.size(); ++i) {
    const studio::SessionView& entry = session.views[i];
    CameraModel camera = entry.camera_model;
    camera.cam_from_world =
        camera.cam_from_world * session.ground_truth.table_from_object.at(entry.pass);
    const recon::SilhouetteAgreement a =
        recon::CompareSilhouette(mesh, camera, ReadMask(folder / session.ground_truth.masks.at(i)));
    passes[entry.pass].iou += a.iou;
    passes[entry.pass].deviation_px += a.mean_deviation_px;
    ++counts[entry.pass];
  }
  for (std::size_t p = 0; p < passes.size(); ++p) {
    passes[p].iou /= std::max(1, counts[p]);
    passes[p].deviation_px /= std::max(1, counts[p]);
  }
  return passes;
}

// A copy of the session with its first pass only.
std::filesystem::path FirstPassOnly(const std::filesystem::path& folder) {
  std::filesystem::path copy = folder.string() + "_1pass";
  std::filesystem::remove_all(copy);
  std::filesystem::copy(folder, copy, std::filesystem::copy_options::recursive);
  studio::Session session = studio::ReadSession(copy);
  std::erase_if(session.views, [](const studio::SessionView& v) { return v.pass != 0; });
  session.passes.clear();
  session.stages = {{"capture", "done"}};
  studio::WriteSessionManifest(copy, session);
  return copy;
}

int Run(int argc, char** argv) {
  std::string scene = "shoe", pose = "side", size = "1296x864", keep, backdrop = "light",
              mask_shots = "none";
  std::vector<int> seeds = {1};
  int views = 16;
  bool truth_masks = false, model = false, unlit = false, no_gain = false;
  BenchFlags flags(argc, argv,
                   "registration_bench: a second pass registered, against the simulator's truth");
  flags.Option("--scene", &scene, "shoe, bottle, avocado, duck or a model file")
      .Option("--pose", &pose, "side, upside-down or random")
      .List("--seeds", &seeds, "pose seeds (random) and noise seeds")
      .Option("--size", &size, "photo size WxH")
      .Option("--views", &views, "turntable stops per pass")
      .Flag("--truth-masks", &truth_masks, "register from the exact silhouettes")
      .Flag("--unlit", &unlit, "render the albedo (no shading that differs between the passes)")
      .Flag("--no-gain", &no_gain, "texture without per-view colour gains")
      .Flag("--model", &model, "also reconstruct and texture both passes, and score them")
      .Option("--backdrop", &backdrop, "light, white, grey, green, black or #rrggbb")
      .Option("--mask-shots", &mask_shots, "none, or backlit")
      .Option("--keep", &keep, "keep the sessions in this folder");
  if (const std::optional<int> exit_code = flags.Parse(std::cout, std::cerr)) return *exit_code;

  const std::filesystem::path work =
      keep.empty() ? std::filesystem::temp_directory_path() / "registration_bench"
                   : std::filesystem::path(keep);
  std::filesystem::create_directories(work);
  Progress progress;
  std::vector<double> rotation_errors, displacement_errors, times;
  for (const int seed : seeds) {
    studio::SimCaptureOptions capture;
    capture.scene = scene;
    capture.data_dir = DataDir();
    capture.stops = views;
    studio::ParseImageSize(size, "size", &capture.rig.width, &capture.rig.height);
    capture.orientations = 2;
    capture.second_pose = pose;
    capture.pose_seed = static_cast<std::uint64_t>(seed);
    capture.render.seed = static_cast<std::uint64_t>(seed);
    capture.eval_below = model ? 4 : 0;
    capture.overwrite = true;
    capture.mask_shots = mask_shots;
    capture.render.lit = !unlit;
    SetOptionText(studio::SimCaptureOptions::Fields().Find("backdrop"), capture, backdrop);
    std::string case_name = scene;
    case_name += '_';
    case_name += pose;
    case_name += '_';
    case_name += std::to_string(seed);
    const std::filesystem::path folder = work / case_name;
    studio::SimulateCapture(capture, folder, progress);
    studio::Session session = studio::ReadSession(folder);
    const Mesh truth = ReadMesh(folder / session.ground_truth.mesh);
    const Rigid3d true_pose = session.ground_truth.table_from_object.at(1);

    recon::RegistrationResult found;
    double seconds = 0.0;
    std::string status = "registered";
    if (!truth_masks || model) {
      studio::ReconstructOptions options;
      Stopwatch watch;
      try {
        const studio::ReconstructResult result =
            studio::ReconstructSession(folder, session, options, progress);
        if (!result.passes.empty() && result.passes[0].registration)
          found = *result.passes[0].registration;
        status = result.passes.empty() ? "none" : result.passes[0].status;
        seconds = result.seconds_registration;
      } catch (const Error& e) {
        std::printf("%s seed %d: reconstruct failed: %s\n", scene.c_str(), seed, e.what());
        continue;
      }
    } else {
      Stopwatch watch;
      found = recon::RegisterPass(PassViews(folder, session, 0, true),
                                  PassViews(folder, session, 1, true), {}, progress);
      seconds = watch.ElapsedSeconds();
      status = !found.matches ? "failed" : found.ambiguous ? "ambiguous" : "registered";
    }
    const double rotation_deg =
        recon::RotationDistanceDeg(found.table_from_object.rotation, true_pose.rotation);
    const double displacement_mm = 1e3 * Displacement(truth, found.table_from_object, true_pose);
    rotation_errors.push_back(rotation_deg);
    displacement_errors.push_back(displacement_mm);
    times.push_back(seconds);
    std::printf(
        "%s %s seed %d: %s, rotation error %.3f deg, surface moved %.3f mm, residual %.2f px "
        "(%.3f mm), %.1f%% inconsistent, runner-up %.2fx at %.1f deg; %.2f s (hulls %.2f, search "
        "%.2f, refine %.2f)\n",
        scene.c_str(), pose.c_str(), seed, status.c_str(), rotation_deg, displacement_mm,
        found.residual_px, 1e3 * found.residual_m, 100.0 * found.inconsistent_fraction,
        found.runner_up_ratio, found.runner_up_deg, seconds, found.seconds_hulls,
        found.seconds_search, found.seconds_refine);
    if (found.colour_points > 0)
      std::printf(
          "  colour: %s, correlation %.2f at the pose against %.2f at the other tied "
          "one, %d points; %.2f s\n",
          found.colour_decided ? "decided the pose" : "undecided", found.colour_correlation,
          found.runner_up_colour_correlation, found.colour_points, found.seconds_colour);
    if (status == "ambiguous") {
      // The operator looks at the pictures and chooses; here: the pose offered nearest the truth.
      const studio::Session listed = studio::ReadSession(folder);
      const std::vector<Rigid3d>& choices = listed.passes.at(1).pose_choices;
      std::size_t nearest = 0;
      for (std::size_t k = 1; k < choices.size(); ++k)
        if (recon::RotationDistanceDeg(choices[k].rotation, true_pose.rotation) <
            recon::RotationDistanceDeg(choices[nearest].rotation, true_pose.rotation))
          nearest = k;
      studio::ReconstructOptions options;
      options.choose_pose = "2:" + std::to_string(nearest + 1);
      studio::Session again = studio::ReadSession(folder);
      const studio::ReconstructResult chosen =
          studio::ReconstructSession(folder, again, options, progress);
      if (!choices.empty() && !chosen.passes.empty() && chosen.passes[0].registration) {
        const recon::RegistrationResult& from = *chosen.passes[0].registration;
        std::printf(
            "  the operator's choice: pose %zu of %zu (%.1f deg off): %s, rotation error %.3f "
            "deg, surface moved %.3f mm; %.2f s\n",
            nearest + 1, choices.size(),
            recon::RotationDistanceDeg(choices[nearest].rotation, true_pose.rotation),
            chosen.passes[0].status.c_str(),
            recon::RotationDistanceDeg(from.table_from_object.rotation, true_pose.rotation),
            1e3 * Displacement(truth, from.table_from_object, true_pose),
            chosen.seconds_registration);
        if (chosen.passes[0].status == "registered") {
          found = from;
          status = "registered";
        }
      }
    }
    std::fflush(stdout);
    if (model && status == "registered") {
      const double truth_volume = SignedVolume(truth);
      const std::filesystem::path one = FirstPassOnly(folder);
      studio::ReconstructSession(one, studio::ReconstructOptions(), progress);
      const ModelFigures single = ScoreModel(one, !no_gain, progress);
      const ModelFigures both = ScoreModel(folder, !no_gain, progress);
      struct Model {
        const char* name;
        const ModelFigures& f;
        std::filesystem::path folder;
      };
      for (const auto& [name, f, from] :
           {Model{"one pass", single, one}, Model{"two passes", both, folder}}) {
        std::printf(
            "  %s: hull volume %.1f cm3 (%+.1f%% vs the true mesh's %.1f cm3), %d of %zu faces "
            "(%.2f%%) seen by no view, held-out side views %.2f dB, views from below %.2f dB\n",
            name, f.hull_volume_m3 * 1e6, 100.0 * (f.hull_volume_m3 / truth_volume - 1.0),
            truth_volume * 1e6, f.unseen_faces, f.faces,
            100.0 * f.unseen_faces / std::max<std::size_t>(1, f.faces), f.held_out_psnr,
            f.below_psnr);
        for (const char* file : {"recon/hull.ply", "recon/mesh.ply"}) {
          const std::vector<PassAgreement> agreement =
              TrueSilhouetteAgreement(ReadMesh(from / file), folder, session);
          std::printf("    %s vs the true silhouettes:", file);
          for (std::size_t p = 0; p < agreement.size(); ++p)
            std::printf(" pass %zu IoU %.4f, %.2f px;", p + 1, agreement[p].iou,
                        agreement[p].deviation_px);
          std::printf("\n");
        }
      }
      std::fflush(stdout);
    }
  }
  if (!rotation_errors.empty()) {
    auto summary = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      char text[96];
      std::snprintf(text, sizeof text, "min %.3f median %.3f max %.3f", v.front(), v[v.size() / 2],
                    v.back());
      return std::string(text);
    };
    std::printf("rotation error deg: %s\nsurface moved mm: %s\nseconds: %s\n",
                summary(rotation_errors).c_str(), summary(displacement_errors).c_str(),
                summary(times).c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "registration_bench: %s\n", e.what());
    return 1;
  }
}
