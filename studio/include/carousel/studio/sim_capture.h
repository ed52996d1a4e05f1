// `carousel sim capture`: a whole capture session on the simulated rig, written as a session
// folder (session.h) with the exact calibration of every photo and a ground-truth folder.
//
// The folder appears atomically: everything is written into a hidden staging folder beside
// the target and renamed into place at the end, so a failed or cancelled run never leaves a
// valid-looking half session. An existing session is never replaced unless `overwrite`.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"

namespace carousel::studio {

// The simulated capture's fields that a one-button session records in its run.json (so a
// resume photographs the same scene the same way): what `carousel run --sim` offers.
const std::vector<std::string>& RunSimFieldNames();

// "5184x3456" -> width, height. \throw InvalidArgument naming `flag`.
void ParseImageSize(const std::string& text, const std::string& flag, int* width, int* height);
// "white", "grey", "green", "black" or "#rrggbb" -> sRGB 0..1 (RGB). \throw InvalidArgument.
Eigen::Vector3d ParseBackdropColour(const std::string& text, const std::string& flag);

struct SimCaptureOptions {
  // A model name (shoe, bottle, avocado, duck: the glTF models in the shared data) or a path to
  // a .gltf, .glb or .obj file.
  std::string scene = "shoe";
  // The shared test data folder, for model names.
  std::filesystem::path data_dir;
  sim::PlacementOptions placement;
  sim::SimRigOptions rig;
  // Turntable stops per turn (photos per camera), evenly spaced from 0 deg; >= 1.
  int stops = 16;
  // Renderer settings; by default what a real studio shows: sensor noise, the key light's soft
  // cast shadow on the plate and the sweep, the backdrop light's falloff and mild vignetting.
  sim::RenderOptions render = [] {
    sim::RenderOptions options;
    options.noise_sigma = 1.5;
    options.cast_shadow = 0.4;
    options.backdrop_falloff = 0.2;
    options.vignetting = 0.1;
    return options;
  }();
  int jpeg_quality = 95;  // 1..100
  // Every material of the model made white, black, glossy or see-through
  // (sim::Scene::OverrideMaterials).
  sim::MaterialOverride material = sim::MaterialOverride::kNone;
  // "none", or "backlit": beside every photo a backlit mask shot (the backlight on), which the
  // silhouettes are taken from (CapturePlan::mask_shots).
  std::string mask_shots = "none";
  // Passes of the turntable, each with the product lying another way (1 or 2): the second
  // lies as `second_pose` says, "side" (on its side: turned 90 deg about its longest
  // horizontal axis), "upside-down", or "random" (any rotation, from `pose_seed`, and off the
  // plate's centre by up to 1 cm).
  int orientations = 1;
  std::string second_pose = "side";
  std::uint64_t pose_seed = 1;
  // How far off the plate's centre (along +x) the product lies in the second pass, metres:
  // laid down carelessly, out of the frame.
  double second_offset_m = 0.0;
  // Photos for evaluation only (ground_truth/eval/, never read by the pipeline): this many
  // from below the product (elevation -30 deg in the object frame, evenly round it), rendered
  // without the plate, the product lit as in the last pass.
  int eval_below = 0;
  // The product name recorded in the manifest; empty = the scene's name.
  std::string product;
  // Replace an existing session folder (after the new one is complete).
  bool overwrite = false;
  // Every field a person sets (core/options.h); `run` offers the ones its run.json keeps
  // (RunSimFieldNames()).
  static const OptionTable<SimCaptureOptions>& Fields();
  void Validate() const;
};

// The file a scene name stands for. \throw InvalidArgument for an unknown name, IoError if the
// file is missing.
std::filesystem::path ResolveScene(const std::string& scene, const std::filesystem::path& data_dir);

// How the product lies in the second pass (`pose` as SimCaptureOptions::second_pose; `bounds`
// its box in the object frame): the rotation from the object frame, and how far off the
// plate's centre it lies (x, y). SimulateCapture then centres the turned product on the
// table's axis, plus that offset, and sets it on the plate.
// \throw InvalidArgument for an unknown pose.
Rigid3d SecondPassRotation(const std::string& pose, const Eigen::AlignedBox3d& bounds,
                           std::uint64_t seed);

// The product (`scene`, placed in the object frame) laid down for the second pass as
// `options` say (second_pose, pose_seed): turned, centred on the table's axis (plus the
// pose's offset) and set on the plate. `table_from_object` receives where it went.
sim::Scene LaidDownScene(const sim::Scene& scene, const SimCaptureOptions& options,
                         Rigid3d* table_from_object);

// Whether `scene` is a file path rather than one of the model names.
bool IsSceneFile(const std::string& scene);

struct SimCaptureResult {
  std::filesystem::path session;
  int views = 0;
  double render_seconds = 0.0;  // total time in the renderer
};

// \throw IoError (target exists, cannot write), InvalidArgument, FormatError (scene file),
//        Cancelled; the target is untouched in every case.
SimCaptureResult SimulateCapture(const SimCaptureOptions& options,
                                 const std::filesystem::path& session_folder, Progress& progress);

}  // namespace carousel::studio
