#include "carousel/studio/rig_config.h"

#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "carousel/calib/rig_calibration.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/json.h"
#include "carousel/core/logging.h"

namespace carousel::studio {
namespace {

using nlohmann::json;

}  // namespace

const OptionTable<CapturePlan>& CapturePlan::Fields() {
  using P = CapturePlan;
  static const OptionTable<P> table = [] {
    OptionTable<P> t;
    t.Add(&P::stops, {.name = "stops", .help = "turntable stops per turn", .min = 1, .max = 720});
    t.Add(&P::settle_ms, {.name = "settle-ms",
                          .help = "wait after a move before firing (vibration)",
                          .unit = "ms",
                          .min = 0,
                          .max = 60000});
    t.Add(&P::shutter, {.name = "shutter",
                        .help = "who releases the shutters: libgphoto2 (camera) or the "
                                "controller's shutter outputs, all at once (controller)",
                        .choices = {"camera", "controller"}});
    t.Add(&P::shutter_pulse_ms, {.name = "shutter-pulse-ms",
                                 .help = "controller shutter: how long the release is held",
                                 .unit = "ms",
                                 .min = 1,
                                 .max = 10000,
                                 .advanced = true});
    t.Add(&P::mask_shots, {.name = "mask-shots",
                           .help = "a backlit mask shot beside every photo (the silhouettes "
                                   "come from it)",
                           .choices = {"none", "backlit"}});
    t.Add(&P::orientations, {.name = "orientations",
                             .help = "passes, the product laid down another way for each "
                                     "(the operator is asked between them)",
                             .min = 1,
                             .max = 4});
    t.Add(&P::backlight_settle_ms, {.name = "backlight-settle-ms",
                                    .help = "wait after switching the backlight",
                                    .unit = "ms",
                                    .min = 0,
                                    .max = 10000,
                                    .advanced = true});
    t.Add(&P::delete_from_camera, {.name = "delete-from-camera",
                                   .help = "delete each photo from the card once it is safely "
                                           "on disk",
                                   .advanced = true,
                                   .negative_name = "keep-on-camera"});
    t.Add(&P::move_timeout_s, {.name = "move-timeout",
                               .help = "longest a turntable move may take",
                               .unit = "s",
                               .min = 0,
                               .min_exclusive = true,
                               .advanced = true});
    t.Add(&P::camera_timeout_s, {.name = "camera-timeout",
                                 .help = "longest a camera operation may take",
                                 .unit = "s",
                                 .min = 0,
                                 .min_exclusive = true,
                                 .advanced = true});
    return t;
  }();
  return table;
}

void CapturePlan::Validate() const {
  CAROUSEL_THROW_IF(stops < 1 || stops > 720, InvalidArgument,
                    "capture.stops must be 1..720, not " << stops);
  CAROUSEL_THROW_IF(settle_ms < 0 || settle_ms > 60000, InvalidArgument,
                    "capture.settle_ms must be 0..60000");
  CAROUSEL_THROW_IF(!(move_timeout_s > 0) || !(camera_timeout_s > 0), InvalidArgument,
                    "capture timeouts must be > 0");
  CAROUSEL_THROW_IF(
      shutter != "camera" && shutter != "controller", InvalidArgument,
      "capture.shutter must be \"camera\" or \"controller\", not \"" << shutter << "\"");
  CAROUSEL_THROW_IF(shutter_pulse_ms < 1 || shutter_pulse_ms > 10000, InvalidArgument,
                    "capture.shutter_pulse_ms must be 1..10000");
  CAROUSEL_THROW_IF(
      mask_shots != "none" && mask_shots != "backlit", InvalidArgument,
      "capture.mask_shots must be \"none\" or \"backlit\", not \"" << mask_shots << "\"");
  CAROUSEL_THROW_IF(backlight_settle_ms < 0 || backlight_settle_ms > 10000, InvalidArgument,
                    "capture.backlight_settle_ms must be 0..10000");
  CAROUSEL_THROW_IF(orientations < 1 || orientations > 4, InvalidArgument,
                    "capture.orientations must be 1..4, not " << orientations);
}

void RigConfig::Validate() const {
  CAROUSEL_THROW_IF(turntable.port.empty(), InvalidArgument, "the rig has no turntable port");
  CAROUSEL_THROW_IF(cameras.empty(), InvalidArgument, "the rig has no cameras");
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    CAROUSEL_THROW_IF(cameras[i].port.empty(), InvalidArgument, "camera " << i << " has no port");
    for (std::size_t j = 0; j < i; ++j) {
      CAROUSEL_THROW_IF(cameras[i].port == cameras[j].port, InvalidArgument,
                        "cameras " << j << " and " << i << " share the port " << cameras[i].port);
    }
    cameras[i].calibration.Validate();
  }
  CAROUSEL_THROW_IF((turntable.gear_num.has_value()) != (turntable.gear_den.has_value()),
                    InvalidArgument, "the turntable gear needs both NUM and DEN");
  capture.Validate();
  CAROUSEL_THROW_IF(backdrop != "key" && backdrop != "difference", InvalidArgument,
                    "backdrop must be \"key\" or \"difference\", not \"" << backdrop << "\"");
  CAROUSEL_THROW_IF(backdrop == "difference" && backgrounds.empty(), InvalidArgument,
                    "backdrop \"difference\" needs \"backgrounds\": a folder with cam<C>.jpg, a "
                    "photo of the empty turntable by each camera");
  CAROUSEL_THROW_IF(capture.shutter == "controller" && cameras.size() > 4, InvalidArgument,
                    "the turntable controller has 4 shutter outputs; the rig has " << cameras.size()
                                                                                   << " cameras");
}

std::string RigConfigToJsonText(const RigConfig& config) {
  json turntable = {{"port", config.turntable.port}};
  if (config.turntable.steps_per_rev) turntable["steps_per_rev"] = *config.turntable.steps_per_rev;
  if (config.turntable.microsteps) turntable["microsteps"] = *config.turntable.microsteps;
  if (config.turntable.gear_num && config.turntable.gear_den) {
    turntable["gear"] = std::to_string(*config.turntable.gear_num) + ":" +
                        std::to_string(*config.turntable.gear_den);
  }
  json cameras = json::array();
  for (const RigCameraConfig& c : config.cameras) {
    cameras.push_back({{"port", c.port},
                       {"model", c.model},
                       {"serial", c.serial},
                       {"settings", c.settings},
                       {"calibration", CameraModelToJson(c.calibration)}});
  }
  json j = {{"format", "carousel-rig"},
            {"version", 1},
            {"turntable", turntable},
            {"cameras", cameras},
            {"capture",
             {{"stops", config.capture.stops},
              {"settle_ms", config.capture.settle_ms},
              {"delete_from_camera", config.capture.delete_from_camera},
              {"shutter", config.capture.shutter},
              {"shutter_pulse_ms", config.capture.shutter_pulse_ms},
              {"mask_shots", config.capture.mask_shots},
              {"backlight_settle_ms", config.capture.backlight_settle_ms},
              {"orientations", config.capture.orientations},
              {"move_timeout_s", config.capture.move_timeout_s},
              {"camera_timeout_s", config.capture.camera_timeout_s}}},
            {"backdrop", config.backdrop}};
  if (!config.backgrounds.empty()) j["backgrounds"] = config.backgrounds.string();
  // The cameras above carry the calibration; the file is named for the record.
  if (!config.calibration_file.empty()) j["calibration_from"] = config.calibration_file.string();
  return j.dump(2) + "\n";
}

RigConfig RigConfigFromJsonText(const std::string& text, const std::filesystem::path& source) {
  const json j = ParseJsonText(text, source);
  const JsonReader rig(j, source);
  if (!j.is_object() || rig.OptionalString("format") != "carousel-rig") {
    rig.Fail("not a Carousel rig file (format is not \"carousel-rig\")");
  }
  if (rig.Int("version") != 1) {
    rig.Fail("unsupported rig file version (this build reads version 1)");
  }
  RigConfig config;
  const JsonReader turntable = rig.ObjectOrEmpty("turntable");
  config.turntable.port = turntable.String("port");
  config.turntable.steps_per_rev = turntable.OptionalInt("steps_per_rev");
  config.turntable.microsteps = turntable.OptionalInt("microsteps");
  if (const std::optional<std::string> gear = turntable.OptionalString("gear")) {
    const std::size_t colon = gear->find(':');
    try {
      if (colon == std::string::npos) throw std::invalid_argument("gear");
      config.turntable.gear_num = std::stoi(gear->substr(0, colon));
      config.turntable.gear_den = std::stoi(gear->substr(colon + 1));
    } catch (const std::logic_error&) {
      turntable.Fail(turntable.FieldPath("gear") + " must be \"NUM:DEN\", not \"" + *gear + "\"");
    }
  }
  const std::vector<JsonReader> cameras = rig.Array("cameras");
  // The cameras' calibration from a rig calibration file (carousel calibrate rig), camera i
  // of the rig being camera i of the file; or per camera in the rig file itself.
  std::optional<calib::RigCalibration> calibration;
  if (const std::optional<std::string> name = rig.OptionalString("calibration_file")) {
    std::filesystem::path file = *name;
    if (file.is_relative() && !source.empty()) file = source.parent_path() / file;
    calibration = calib::ReadRigCalibration(file);
    config.calibration_file = file;
    if (calibration->cameras.size() != cameras.size()) {
      rig.Fail("calibration_file " + file.string() + " calibrates " +
               std::to_string(calibration->cameras.size()) + " camera(s), the rig has " +
               std::to_string(cameras.size()));
    }
  }
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    const JsonReader& c = cameras[i];
    RigCameraConfig camera;
    camera.port = c.String("port");
    camera.model = c.OptionalString("model").value_or("");
    camera.serial = c.OptionalString("serial").value_or("");
    camera.settings = c.OptionalStringMap("settings").value_or(camera.settings);
    if (calibration) {
      const calib::RigCameraCalibration& calibrated = calibration->cameras[i];
      if (!camera.serial.empty() && !calibrated.serial.empty() &&
          camera.serial != calibrated.serial) {
        c.Fail(c.where() + " is the camera " + camera.serial + ", the calibration file's camera " +
               std::to_string(i) + " is " + calibrated.serial);
      }
      camera.calibration = calibrated.camera;
    } else if (!c.Has("calibration")) {
      c.Fail(c.where() +
             " has no calibration (run `carousel run --calibration` and name its result in "
             "\"calibration_file\")");
    } else {
      camera.calibration = CameraModelFromJson(c.Object("calibration"));
    }
    config.cameras.push_back(std::move(camera));
  }
  const JsonReader capture = rig.ObjectOrEmpty("capture");
  CapturePlan& plan = config.capture;
  plan.stops = capture.OptionalInt("stops").value_or(plan.stops);
  plan.settle_ms = capture.OptionalInt("settle_ms").value_or(plan.settle_ms);
  plan.delete_from_camera =
      capture.OptionalBool("delete_from_camera").value_or(plan.delete_from_camera);
  plan.shutter = capture.OptionalString("shutter").value_or(plan.shutter);
  plan.shutter_pulse_ms = capture.OptionalInt("shutter_pulse_ms").value_or(plan.shutter_pulse_ms);
  plan.mask_shots = capture.OptionalString("mask_shots").value_or(plan.mask_shots);
  plan.backlight_settle_ms =
      capture.OptionalInt("backlight_settle_ms").value_or(plan.backlight_settle_ms);
  plan.orientations = capture.OptionalInt("orientations").value_or(plan.orientations);
  plan.move_timeout_s = capture.OptionalNumber("move_timeout_s").value_or(plan.move_timeout_s);
  plan.camera_timeout_s =
      capture.OptionalNumber("camera_timeout_s").value_or(plan.camera_timeout_s);
  config.backdrop = rig.OptionalString("backdrop").value_or(config.backdrop);
  config.backgrounds = rig.OptionalString("backgrounds").value_or("");
  // Relative to the rig file.
  if (!config.backgrounds.empty() && config.backgrounds.is_relative() && !source.empty())
    config.backgrounds = source.parent_path() / config.backgrounds;
  try {
    config.Validate();
  } catch (const InvalidArgument& e) {
    throw FormatError(source, e.what());
  }
  return config;
}

RigConfig ReadRigConfig(const std::filesystem::path& path) {
  const std::vector<std::uint8_t> bytes = ReadFileBytes(path);
  return RigConfigFromJsonText(std::string(bytes.begin(), bytes.end()), path);
}

void WriteRigConfig(const std::filesystem::path& path, const RigConfig& config) {
  WriteFileAtomic(path, RigConfigToJsonText(config));
}

}  // namespace carousel::studio
