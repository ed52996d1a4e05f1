#include "carousel/studio/rig_config.h"

#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "carousel/calib/rig_calibration.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/logging.h"
#include "carousel/rig/gphoto_camera.h"
#include "carousel/rig/serial_turntable.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

using nlohmann::json;

template <typename T>
T Get(const json& object, const char* key, const std::filesystem::path& source,
      const std::string& where) {
  if (!object.is_object() || !object.contains(key)) {
    throw FormatError(source, where + " has no field '" + key + "'");
  }
  try {
    return object.at(key).get<T>();
  } catch (const json::exception&) {
    throw FormatError(source, where + "." + key + " has the wrong type");
  }
}

template <typename T>
T GetOr(const json& object, const char* key, T fallback, const std::filesystem::path& source,
        const std::string& where) {
  return object.is_object() && object.contains(key) ? Get<T>(object, key, source, where) : fallback;
}

}  // namespace

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
              {"move_timeout_s", config.capture.move_timeout_s},
              {"camera_timeout_s", config.capture.camera_timeout_s}}},
            {"backdrop", config.backdrop}};
  if (!config.backgrounds.empty()) j["backgrounds"] = config.backgrounds.string();
  // The cameras above carry the calibration; the file is named for the record.
  if (!config.calibration_file.empty()) j["calibration_from"] = config.calibration_file.string();
  return j.dump(2) + "\n";
}

RigConfig RigConfigFromJsonText(const std::string& text, const std::filesystem::path& source) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::parse_error& e) {
    throw FormatError(source, std::string("not valid JSON: ") + e.what());
  }
  if (GetOr<std::string>(j, "format", "", source, "rig") != "carousel-rig") {
    throw FormatError(source, "not a Carousel rig file (format is not \"carousel-rig\")");
  }
  if (Get<int>(j, "version", source, "rig") != 1) {
    throw FormatError(source, "unsupported rig file version (this build reads version 1)");
  }
  RigConfig config;
  const json& t = j.contains("turntable") ? j["turntable"] : json();
  config.turntable.port = Get<std::string>(t, "port", source, "turntable");
  if (t.contains("steps_per_rev")) {
    config.turntable.steps_per_rev = Get<int>(t, "steps_per_rev", source, "turntable");
  }
  if (t.contains("microsteps")) {
    config.turntable.microsteps = Get<int>(t, "microsteps", source, "turntable");
  }
  if (t.contains("gear")) {
    const std::string gear = Get<std::string>(t, "gear", source, "turntable");
    const std::size_t colon = gear.find(':');
    try {
      if (colon == std::string::npos) throw std::invalid_argument("gear");
      config.turntable.gear_num = std::stoi(gear.substr(0, colon));
      config.turntable.gear_den = std::stoi(gear.substr(colon + 1));
    } catch (const std::logic_error&) {
      throw FormatError(source, "turntable.gear must be \"NUM:DEN\", not \"" + gear + "\"");
    }
  }
  if (!j.contains("cameras") || !j["cameras"].is_array()) {
    throw FormatError(source, "rig has no \"cameras\" list");
  }
  // The cameras' calibration from a rig calibration file (carousel calibrate rig), camera i
  // of the rig being camera i of the file; or per camera in the rig file itself.
  std::optional<calib::RigCalibration> calibration;
  if (j.contains("calibration_file")) {
    std::filesystem::path file = Get<std::string>(j, "calibration_file", source, "rig");
    if (file.is_relative() && !source.empty()) file = source.parent_path() / file;
    calibration = calib::ReadRigCalibration(file);
    config.calibration_file = file;
    if (calibration->cameras.size() != j["cameras"].size()) {
      throw FormatError(source, "calibration_file " + file.string() + " calibrates " +
                                    std::to_string(calibration->cameras.size()) +
                                    " camera(s), the rig has " +
                                    std::to_string(j["cameras"].size()));
    }
  }
  for (std::size_t i = 0; i < j["cameras"].size(); ++i) {
    const json& c = j["cameras"][i];
    const std::string where = "cameras[" + std::to_string(i) + "]";
    RigCameraConfig camera;
    camera.port = Get<std::string>(c, "port", source, where);
    camera.model = GetOr<std::string>(c, "model", "", source, where);
    camera.serial = GetOr<std::string>(c, "serial", "", source, where);
    camera.settings = GetOr<std::map<std::string, std::string>>(c, "settings", {}, source, where);
    if (calibration) {
      const calib::RigCameraCalibration& calibrated = calibration->cameras[i];
      if (!camera.serial.empty() && !calibrated.serial.empty() &&
          camera.serial != calibrated.serial) {
        throw FormatError(source, where + " is the camera " + camera.serial +
                                      ", the calibration file's camera " + std::to_string(i) +
                                      " is " + calibrated.serial);
      }
      camera.calibration = calibrated.camera;
    } else if (!c.contains("calibration")) {
      throw FormatError(source, where +
                                    " has no calibration (run `carousel run --calibration` "
                                    "and name its result in \"calibration_file\")");
    } else {
      camera.calibration = CameraModelFromJson(c["calibration"], source, where + ".calibration");
    }
    config.cameras.push_back(std::move(camera));
  }
  const json& p = j.contains("capture") ? j["capture"] : json::object();
  config.capture.stops = GetOr<int>(p, "stops", config.capture.stops, source, "capture");
  config.capture.settle_ms =
      GetOr<int>(p, "settle_ms", config.capture.settle_ms, source, "capture");
  config.capture.delete_from_camera =
      GetOr<bool>(p, "delete_from_camera", config.capture.delete_from_camera, source, "capture");
  config.capture.shutter =
      GetOr<std::string>(p, "shutter", config.capture.shutter, source, "capture");
  config.capture.shutter_pulse_ms =
      GetOr<int>(p, "shutter_pulse_ms", config.capture.shutter_pulse_ms, source, "capture");
  config.capture.move_timeout_s =
      GetOr<double>(p, "move_timeout_s", config.capture.move_timeout_s, source, "capture");
  config.capture.camera_timeout_s =
      GetOr<double>(p, "camera_timeout_s", config.capture.camera_timeout_s, source, "capture");
  config.backdrop = GetOr<std::string>(j, "backdrop", config.backdrop, source, "rig");
  config.backgrounds = GetOr<std::string>(j, "backgrounds", "", source, "rig");
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

RigBackends OpenHardwareRig(const RigConfig& config) {
  config.Validate();
  RigBackends rig;
  rig.plan = config.capture;
  rig::SerialTurntableOptions table_options;
  table_options.port = config.turntable.port;
  auto table = std::make_shared<rig::SerialTurntable>(table_options);
  const RigTurntableConfig& t = config.turntable;
  if (t.steps_per_rev || t.microsteps || t.gear_num) {
    cp_config c = table->Config();
    if (t.steps_per_rev) c.steps_per_rev = static_cast<std::uint16_t>(*t.steps_per_rev);
    if (t.microsteps) c.microsteps = static_cast<std::uint16_t>(*t.microsteps);
    if (t.gear_num) c.gear_num = static_cast<std::uint16_t>(*t.gear_num);
    if (t.gear_den) c.gear_den = static_cast<std::uint16_t>(*t.gear_den);
    table->SetConfig(c);
  }
  rig.turntable = table;
  if (config.capture.shutter == "controller") {
    const auto pulse = static_cast<std::uint16_t>(config.capture.shutter_pulse_ms);
    rig.release = [table, pulse](const std::vector<int>& cameras) {
      std::uint8_t mask = 0;
      for (const int c : cameras) mask |= static_cast<std::uint8_t>(1u << c);
      table->Trigger(mask, CP_OUTPUT_SHUTTER, pulse);
    };
  }
  const auto timeout =
      std::chrono::milliseconds(static_cast<long long>(config.capture.camera_timeout_s * 1000));
  for (const RigCameraConfig& c : config.cameras) {
    rig::GPhotoCameraOptions options;
    options.port = c.port;
    options.model = c.model;
    auto camera = std::make_unique<rig::GPhotoCamera>(options);
    const rig::CameraInfo info = camera->Identify();
    if (!c.serial.empty() && info.serial != c.serial) {
      throw DeviceError("camera " + c.port, "has serial " + info.serial + ", the rig expects " +
                                                c.serial + " (cameras swapped?)");
    }
    for (const auto& [name, value] : c.settings) camera->SetSetting(name, value, timeout);
    CAROUSEL_LOG_INFO("camera " << info.serial << " (" << info.model << ") on " << c.port);
    rig.cameras.push_back(std::move(camera));
    rig.cam_from_table.push_back(c.calibration);
  }
  return rig;
}

}  // namespace carousel::studio
