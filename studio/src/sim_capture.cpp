#include "carousel/studio/sim_capture.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>

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
      "vignetting", "mask-shots", "backdrop"};
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
      if (options.mask_shots == "backlit") {
        // The same stop with the backlight on (another shot: its own noise).
        sim::RenderOptions backlit = render;
        backlit.backlit = true;
        backlit.seed = render.seed ^ 0x6a09e667f3bcc909ULL;
        watch.Restart();
        const cv::Mat shot = sim::Render(scene, camera, angle, backlit).image;
        result.render_seconds += watch.ElapsedSeconds();
        view.mask_shot = MaskShotPath(c, stop);
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
