// The rig configuration file (rig.json): which turntable controller and cameras a studio has,
// each camera's calibration (its pose relative to the turntable), the settings the cameras get
// at the start of a session and the capture plan defaults. `carousel run --rig rig.json` runs
// the same one-button session as `--sim`, on hardware.
//
//   {
//     "format": "carousel-rig", "version": 1,
//     "turntable": {"port": "/dev/serial/by-id/usb-Carousel_TT-328-if00",
//                   "steps_per_rev": 200, "microsteps": 16, "gear": "1:3"},   (gear optional)
//     "calibration_file": "rig_calibration.json",   (optional: carousel calibrate rig's file;
//                                                    camera i is the file's camera i)
//     "cameras": [{"port": "usb:001,005", "model": "", "serial": "032021001234",
//                  "settings": {"iso": "100", "aperture": "f/11"},
//                  "calibration": { camera model: intrinsics, distortion, cam_from_world =
//                                   cam_from_table at table angle 0, as in session.json;
//                                   not needed with a calibration_file }}],
//     "capture": {"stops": 16, "settle_ms": 300, "delete_from_camera": true,
//                 "shutter": "camera" | "controller", "shutter_pulse_ms": 100,
//                 "mask_shots": "none" | "backlit", "backlight_settle_ms": 50,
//                 "move_timeout_s": 60, "camera_timeout_s": 60},
//     "backdrop": "key" | "difference",   (how silhouettes are found; default key)
//     "backgrounds": "plates/"             (difference: cam<C>.jpg, the empty turntable
//                                           photographed by camera C; relative to the file)
//   }
#pragma once

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "carousel/core/camera_model.h"
#include "carousel/core/options.h"

namespace carousel::studio {

struct RigTurntableConfig {
  std::string port;  // serial device of the controller
  // Applied to the controller at the start of a session when set.
  std::optional<int> steps_per_rev, microsteps, gear_num, gear_den;
};

struct RigCameraConfig {
  std::string port;    // libgphoto2 port
  std::string model;   // libgphoto2 model; empty = detected
  std::string serial;  // when set, the camera on `port` must have this serial
  std::map<std::string, std::string> settings;  // applied at the start of a session
  CameraModel calibration;                      // cam_from_world at table angle 0
};

struct CapturePlan {
  int stops = 16;                  // turntable stops per turn (as the paper)
  int settle_ms = 300;             // wait after a move before firing (vibration)
  bool delete_from_camera = true;  // once the photo is safely on disk
  // Who releases the shutters: "camera" (libgphoto2 triggers each camera) or "controller" (the
  // turntable controller's shutter outputs, camera i wired to output i: all fire together).
  std::string shutter = "camera";
  int shutter_pulse_ms = 100;  // controller: how long the release is held
  // Mask shots: "none", or "backlit": at every stop a second photo per camera with the
  // backlight on (the turntable controller's light output), which the silhouettes are taken
  // from (the product dark against the lit panel, whatever its colours); the texture still
  // comes from the first.
  std::string mask_shots = "none";
  int backlight_settle_ms = 50;  // wait after switching the backlight before firing
  // Passes of the turntable, the product lying another way in each (1..4): after each pass the
  // operator is asked to lay it down another way (on its side, upside down); the later passes
  // show its underside and are registered to the first by the reconstruct stage.
  int orientations = 1;
  double move_timeout_s = 60.0;
  double camera_timeout_s = 60.0;
  // Every field a person sets (core/options.h): the window's capture-plan panel in hardware
  // mode. Its names are flag names; rig.json keeps its own ("settle_ms").
  static const OptionTable<CapturePlan>& Fields();
  void Validate() const;
};

struct RigConfig {
  RigTurntableConfig turntable;
  std::vector<RigCameraConfig> cameras;
  CapturePlan capture;
  // How the silhouettes are found: "key" (keying against the backdrop) or "difference"
  // (differencing against background plates of the empty turntable, one per camera).
  std::string backdrop = "key";
  // With "difference": the folder holding cam<C>.jpg (or .png) per camera; a session copies
  // them into its backgrounds/ folder when it starts.
  std::filesystem::path backgrounds;
  // The rig calibration file the cameras' calibration came from ("calibration_file" in the
  // rig file, relative to it), when they did.
  std::filesystem::path calibration_file;
  void Validate() const;
};

// \throw IoError (missing, unreadable) or FormatError naming the file and the field.
RigConfig ReadRigConfig(const std::filesystem::path& path);
// Atomic write. \throw IoError.
void WriteRigConfig(const std::filesystem::path& path, const RigConfig& config);
// The JSON text of a config (what WriteRigConfig writes), and back (`source` names it in errors).
std::string RigConfigToJsonText(const RigConfig& config);
RigConfig RigConfigFromJsonText(const std::string& text, const std::filesystem::path& source);

}  // namespace carousel::studio
