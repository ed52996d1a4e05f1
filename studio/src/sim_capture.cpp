#include "carousel/studio/sim_capture.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <random>

#include <opencv2/core.hpp>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/timer.h"
#include "carousel/studio/capture.h"
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

void ParseImageSize(const std::string& text, const std::string& flag, int* width, int* height) {
  const std::size_t x = text.find('x');
  try {
    std::size_t used_w = 0, used_h = 0;
    const int w = std::stoi(text.substr(0, x), &used_w);
    const std::string rest = x == std::string::npos ? "" : text.substr(x + 1);
    const int h = std::stoi(rest, &used_h);
    if (used_w != x || used_h != rest.size() || w < 1 || h < 1) throw std::invalid_argument(text);
    *width = w;
    *height = h;
  } catch (const std::logic_error&) {
    throw InvalidArgument("--" + flag + " must look like 5184x3456, got '" + text + "'");
  }
}

Eigen::Vector3d ParseBackdropColour(const std::string& text, const std::string& flag) {
  if (text == "white") return {0.96, 0.96, 0.96};
  if (text == "grey" || text == "gray") return {0.5, 0.5, 0.5};
  if (text == "green") return {0.1, 0.65, 0.25};
  if (text == "black") return {0.03, 0.03, 0.03};
  if (text.size() == 7 && text[0] == '#') {
    try {
      Eigen::Vector3d colour;
      for (int c = 0; c < 3; ++c) {
        std::size_t used = 0;
        colour[c] = std::stoi(text.substr(1 + 2 * c, 2), &used, 16) / 255.0;
        if (used != 2) throw std::invalid_argument(text);
      }
      return colour;
    } catch (const std::logic_error&) {
    }
  }
  throw InvalidArgument("--" + flag + " must be white, grey, green, black or #rrggbb, got '" +
                        text + "'");
}

const std::vector<std::string>& RunSimFieldNames() {
  static const std::vector<std::string> names = {
      "scene",      "data",       "views",    "size",           "elevations",    "focal-mm",
      "distance",   "noise",      "seed",     "jpeg-quality",   "target-height", "scale",
      "yaw-deg",    "material",   "exposure", "contact-shadow", "cast-shadow",   "backdrop-falloff",
      "vignetting", "mask-shots", "backdrop", "orientations",   "second-pose",   "pose-seed"};
  return names;
}

const OptionTable<SimCaptureOptions>& SimCaptureOptions::Fields() {
  using O = SimCaptureOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::scene,
          {.name = "scene", .help = "shoe, bottle, avocado, duck, or a .gltf/.glb/.obj file"});
    t.Add(&O::data_dir, {.name = "data", .help = "shared test data folder (for model names)"});
    t.Add(&O::stops,
          {.name = "views", .help = "turntable stops per camera", .min = 1, .max = 3600});
    t.AddText(
        {.name = "size", .help = "image size WxH", .unit = "px"},
        [](const O& o) { return std::to_string(o.rig.width) + "x" + std::to_string(o.rig.height); },
        [](O& o, const std::string& text) {
          ParseImageSize(text, "size", &o.rig.width, &o.rig.height);
        });
    t.Add({.name = "elevations",
           .help = "camera elevations, one camera each (e.g. 15,35,60)",
           .unit = "deg",
           .min = -10,
           .max = 85},
          [](O& o) -> OptionRef { return &o.rig.elevations_deg; });
    t.Add({.name = "focal-mm",
           .help = "lens focal length (APS-C sensor)",
           .unit = "mm",
           .min = 0,
           .min_exclusive = true},
          [](O& o) -> OptionRef { return &o.rig.focal_length_mm; });
    t.Add({.name = "distance",
           .help = "camera distance to the object's centre",
           .unit = "m",
           .min = 0,
           .min_exclusive = true,
           .special = 0,
           .special_meaning = "frame the object"},
          [](O& o) -> OptionRef { return &o.rig.distance_m; });
    t.Add({.name = "noise", .help = "sensor noise", .unit = "8-bit levels", .min = 0, .max = 64},
          [](O& o) -> OptionRef { return &o.render.noise_sigma; });
    t.Add({.name = "seed", .help = "noise seed", .advanced = true},
          [](O& o) -> OptionRef { return &o.render.seed; });
    t.Add(&O::jpeg_quality,
          {.name = "jpeg-quality", .help = "JPEG quality of the photos", .min = 1, .max = 100});
    t.Add({.name = "samples",
           .help = "anti-aliasing samples per pixel and axis",
           .min = 1,
           .max = 4,
           .advanced = true},
          [](O& o) -> OptionRef { return &o.render.samples_per_axis; });
    t.AddText(
        {.name = "backdrop",
         .help = "light (the default sweep, lighter at the top), white, grey, green, black or "
                 "#rrggbb (10% darker at the bottom)"},
        [](const O& o) {
          const sim::RenderOptions defaults;
          if (o.render.backdrop_top == defaults.backdrop_top &&
              o.render.backdrop_bottom == defaults.backdrop_bottom)
            return std::string("light");
          char text[8];
          std::snprintf(text, sizeof text, "#%02x%02x%02x",
                        static_cast<int>(std::lround(255.0 * o.render.backdrop_top.x())),
                        static_cast<int>(std::lround(255.0 * o.render.backdrop_top.y())),
                        static_cast<int>(std::lround(255.0 * o.render.backdrop_top.z())));
          return std::string(text);
        },
        [](O& o, const std::string& text) {
          if (text == "light") {
            const sim::RenderOptions defaults;
            o.render.backdrop_top = defaults.backdrop_top;
            o.render.backdrop_bottom = defaults.backdrop_bottom;
            return;
          }
          const Eigen::Vector3d colour = ParseBackdropColour(text, "backdrop");
          o.render.backdrop_top = colour;
          o.render.backdrop_bottom = 0.9 * colour;
        });
    t.Add({.name = "exposure",
           .help = "exposure: a linear gain on the object and the plate (the backdrop is lit on "
                   "its own)",
           .min = 0,
           .max = 16,
           .min_exclusive = true},
          [](O& o) -> OptionRef { return &o.render.exposure; });
    t.Add({.name = "contact-shadow",
           .help = "the object's contact shadow on the plate: how much darker at its base",
           .min = 0,
           .max = 1},
          [](O& o) -> OptionRef { return &o.render.contact_shadow; });
    t.Add({.name = "cast-shadow",
           .help = "the key light's soft shadow on the plate and the sweep: the fraction of the "
                   "key light it takes away",
           .min = 0,
           .max = 1},
          [](O& o) -> OptionRef { return &o.render.cast_shadow; });
    t.Add({.name = "backdrop-falloff",
           .help = "the backdrop light's falloff: how much darker the frame's corners are",
           .min = 0,
           .max = 0.9},
          [](O& o) -> OptionRef { return &o.render.backdrop_falloff; });
    t.Add({.name = "vignetting",
           .help = "lens vignetting: the fraction of light lost in the frame's corners",
           .min = 0,
           .max = 0.9},
          [](O& o) -> OptionRef { return &o.render.vignetting; });
    t.AddChoice(&O::material,
                {.name = "material",
                 .help = "every material of the model made white, black, glossy or see-through "
                         "(what studios find hard)"},
                {{"none", sim::MaterialOverride::kNone},
                 {"white", sim::MaterialOverride::kWhite},
                 {"black", sim::MaterialOverride::kBlack},
                 {"glossy", sim::MaterialOverride::kGlossy},
                 {"see-through", sim::MaterialOverride::kSeeThrough}});
    t.AddText(
        {.name = "mask-shots",
         .help = "backlit: a second photo per stop with the backlight on, which the silhouettes "
                 "are taken from",
         .choices = {"none", "backlit"}},
        [](const O& o) { return o.mask_shots; },
        [](O& o, const std::string& text) {
          CheckOptionChoice({.name = "mask-shots", .choices = {"none", "backlit"}}, text);
          o.mask_shots = text;
        });
    t.Add({.name = "plate-radius",
           .help = "turntable plate radius",
           .unit = "m",
           .min = 0,
           .special = 0,
           .special_meaning = "no plate"},
          [](O& o) -> OptionRef { return &o.render.plate_radius_m; });
    t.Add({.name = "target-height",
           .help = "scale the model to this height",
           .unit = "m",
           .min = 0,
           .min_exclusive = true,
           .special = 0,
           .special_meaning = "as authored"},
          [](O& o) -> OptionRef { return &o.placement.target_height_m; });
    t.Add({.name = "scale",
           .help = "scale factor when no --target-height",
           .min = 0,
           .min_exclusive = true},
          [](O& o) -> OptionRef { return &o.placement.scale; });
    t.AddText(
        {.name = "yaw-deg", .help = "turn the model on the plate first", .unit = "deg"},
        [](const O& o) { return OptionNumberText(o.placement.yaw_rad * 180.0 / std::numbers::pi); },
        [](O& o, const std::string& text) {
          try {
            std::size_t used = 0;
            const double deg = std::stod(text, &used);
            if (used != text.size() || !std::isfinite(deg)) throw std::invalid_argument(text);
            o.placement.yaw_rad = deg * std::numbers::pi / 180.0;
          } catch (const std::logic_error&) {
            throw InvalidArgument("--yaw-deg must be a number of degrees, got '" + text + "'");
          }
        });
    t.Add({.name = "lit",
           .help = "light the scene (off: render the albedo)",
           .negative_name = "unlit"},
          [](O& o) -> OptionRef { return &o.render.lit; });
    t.Add(&O::orientations,
          {.name = "orientations",
           .help = "passes of the turntable, the product lying another way in each (2: the "
                   "second as --second-pose says)",
           .min = 1,
           .max = 2});
    t.AddText(
        {.name = "second-pose",
         .help = "how the product lies in the second pass: side, upside-down, or random (any "
                 "rotation from --pose-seed)",
         .choices = {"side", "upside-down", "random"}},
        [](const O& o) { return o.second_pose; },
        [](O& o, const std::string& text) {
          CheckOptionChoice({.name = "second-pose", .choices = {"side", "upside-down", "random"}},
                            text);
          o.second_pose = text;
        });
    t.Add(&O::pose_seed,
          {.name = "pose-seed", .help = "seed of the random second pose", .advanced = true});
    t.Add(&O::second_offset_m, {.name = "second-offset",
                                .help = "how far off the plate's centre the product lies in the "
                                        "second pass",
                                .unit = "m",
                                .advanced = true});
    t.Add(&O::eval_below,
          {.name = "eval-below",
           .help = "evaluation photos from below the product (ground truth only, never used)",
           .min = 0,
           .max = 64,
           .advanced = true});
    t.Add(&O::product, {.name = "product", .help = "product name for the manifest"});
    return t;
  }();
  return table;
}

void SimCaptureOptions::Validate() const {
  CAROUSEL_THROW_IF(scene.empty(), InvalidArgument, "--scene is empty");
  Fields().Check(*this);
  placement.Validate();
  rig.Validate();
  render.Validate();
}

Rigid3d SecondPassRotation(const std::string& pose, const Eigen::AlignedBox3d& bounds,
                           std::uint64_t seed) {
  Eigen::Matrix3d rotation;
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();
  if (pose == "side") {
    // About the longest horizontal axis: a shoe lies on its side, a bottle on its flank.
    const Eigen::Vector3d axis = bounds.sizes().x() >= bounds.sizes().y()
                                     ? Eigen::Vector3d::UnitX()
                                     : Eigen::Vector3d::UnitY();
    rotation = Eigen::AngleAxisd(0.5 * std::numbers::pi, axis).toRotationMatrix();
  } else if (pose == "upside-down") {
    rotation = Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()).toRotationMatrix();
  } else if (pose == "random") {
    std::mt19937_64 random(seed);
    std::normal_distribution<double> normal;
    Eigen::Quaterniond q(normal(random), normal(random), normal(random), normal(random));
    rotation = q.normalized().toRotationMatrix();
    std::uniform_real_distribution<double> offset(-0.01, 0.01);
    shift = Eigen::Vector3d(offset(random), offset(random), 0.0);
  } else {
    throw InvalidArgument("--second-pose must be side, upside-down or random, got '" + pose + "'");
  }
  return Rigid3d(rotation, shift);
}

sim::Scene LaidDownScene(const sim::Scene& scene, const SimCaptureOptions& options,
                         Rigid3d* table_from_object) {
  const Rigid3d turn = SecondPassRotation(options.second_pose, scene.Bounds(), options.pose_seed);
  sim::Scene turned = scene;
  turned.Transform(Rigid3d(turn.rotation, Eigen::Vector3d::Zero()));
  // Centred on the table's axis and set on the plate as the first pass was, then moved off the
  // centre as the pose says.
  const sim::Placement placed = sim::PlaceOnTurntable(turned, {});
  const Rigid3d off_centre(
      Eigen::Matrix3d::Identity(),
      Eigen::Vector3d(turn.translation.x() + options.second_offset_m, turn.translation.y(), 0.0));
  turned.Transform(off_centre);
  *table_from_object =
      off_centre * placed.transform * Rigid3d(turn.rotation, Eigen::Vector3d::Zero());
  return turned;
}

bool IsSceneFile(const std::string& scene) {
  return !SceneNames().contains(scene) &&
         (scene.find('/') != std::string::npos || scene.find('.') != std::string::npos);
}

std::filesystem::path ResolveScene(const std::string& scene,
                                   const std::filesystem::path& data_dir) {
  std::filesystem::path path;
  if (const auto it = SceneNames().find(scene); it != SceneNames().end()) {
    CAROUSEL_THROW_IF(data_dir.empty(), InvalidArgument,
                      "scene '" << scene << "' needs the shared data folder (--data)");
    path = data_dir / it->second;
  } else if (IsSceneFile(scene)) {
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
  scene.OverrideMaterials(options.material);
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
  // The passes: the product as placed, then (orientations 2) laid down another way.
  std::vector<sim::Scene> poses = {scene};
  std::vector<Rigid3d> table_from_object = {Rigid3d()};
  if (options.orientations > 1) {
    Rigid3d laid;
    poses.push_back(LaidDownScene(scene, options, &laid));
    table_from_object.push_back(laid);
    session.passes = {{.orientation = "upright"}, {.orientation = options.second_pose}};
    session.ground_truth.table_from_object = table_from_object;
  }
  const int total = options.stops * static_cast<int>(rig.size() * poses.size());
  progress.BeginStage("render views");
  int done = 0;
  for (int pass = 0; pass < static_cast<int>(poses.size()); ++pass) {
    for (int stop = 0; stop < options.stops; ++stop) {
      const double angle_deg = 360.0 * stop / options.stops;
      const double angle = angle_deg * std::numbers::pi / 180.0;
      for (int c = 0; c < static_cast<int>(rig.size()); ++c) {
        progress.CheckCancelled();
        const CameraModel camera = sim::CameraAtTableAngle(rig[c], angle);
        sim::RenderOptions render = options.render;
        render.seed = options.render.seed * 1000003ULL + static_cast<std::uint64_t>(done);
        Stopwatch watch;
        const sim::RenderResult rendered = sim::Render(poses[pass], camera, angle, render);
        result.render_seconds += watch.ElapsedSeconds();
        const std::string stem = ViewStem(c, stop, pass);
        SessionView view;
        view.image = "images/" + stem + ".jpg";
        view.camera = c;
        view.stop = stop;
        view.pass = pass;
        view.table_angle_deg = angle_deg;
        view.camera_model = camera;
        WriteImage(staging / view.image, rendered.image,
                   {.jpeg_quality = options.jpeg_quality, .overwrite = false});
        if (options.mask_shots == "backlit") {
          // The same stop with the backlight on (another shot: its own noise).
          sim::RenderOptions backlit = render;
          backlit.backlit = true;
          backlit.seed = render.seed ^ 0x6a09e667f3bcc909ULL;
          watch.Restart();
          const cv::Mat shot = sim::Render(poses[pass], camera, angle, backlit).image;
          result.render_seconds += watch.ElapsedSeconds();
          view.mask_shot = "images/" + stem + kMaskShotSuffix + ".jpg";
          WriteImage(staging / view.mask_shot, shot,
                     {.jpeg_quality = options.jpeg_quality, .overwrite = false});
        }
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
  }
  // Evaluation photos from below (object frame), of the product as the last pass lays it and
  // lit as it is there, without the plate: what no camera of the first pass sees.
  if (options.eval_below > 0) {
    folder.CreateFolder("ground_truth/eval");
    const Eigen::Vector3d target = scene.Bounds().center();
    const double distance = (rig.front().Centre() - target).norm();
    const Rigid3d& last = table_from_object.back();
    sim::RenderOptions render = options.render;
    render.plate_radius_m = 0.0;
    render.contact_shadow = 0.0;
    render.cast_shadow = 0.0;
    for (int k = 0; k < options.eval_below; ++k) {
      const double azimuth = 2.0 * std::numbers::pi * (k + 0.5) / options.eval_below;
      const double elevation = -30.0 * std::numbers::pi / 180.0;
      const Eigen::Vector3d eye =
          target + distance * Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth),
                                              std::cos(elevation) * std::sin(azimuth),
                                              std::sin(elevation));
      EvalView view;
      view.camera_model = rig.front();
      view.camera_model.cam_from_world = Rigid3d::LookAt(eye, target);
      view.name = "below";
      CameraModel in_pass = view.camera_model;
      in_pass.cam_from_world = view.camera_model.cam_from_world * last.Inverse();
      render.seed = options.render.seed * 1000003ULL + 777777ULL + static_cast<std::uint64_t>(k);
      // Lit as a photo from that side is: the table turned so that the camera stands where
      // the rig's cameras do (at -90 deg azimuth in the studio).
      const Eigen::Vector3d centre = in_pass.Centre();
      const double table_angle = -0.5 * std::numbers::pi - std::atan2(centre.y(), centre.x());
      const sim::RenderResult rendered = sim::Render(poses.back(), in_pass, table_angle, render);
      char stem[32];
      std::snprintf(stem, sizeof stem, "below%02d", k);
      view.image = std::string("ground_truth/eval/") + stem + ".jpg";
      view.mask = std::string("ground_truth/eval/") + stem + "_mask.png";
      WriteImage(staging / view.image, rendered.image,
                 {.jpeg_quality = options.jpeg_quality, .overwrite = false});
      WriteImage(staging / view.mask, rendered.mask, {.overwrite = false});
      session.ground_truth.eval_views.push_back(view);
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
