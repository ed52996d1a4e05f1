// The one rig factory: the devices a session captures with, whatever their backend — the
// simulated rig (a product model, or a calibration board, on the simulated turntable; sim/) or
// a rig file's hardware (the serial turntable controller and libgphoto2 cameras; rig/). The
// capture loop (capture.h), `carousel run` and the window all open their rig here.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "carousel/core/camera_model.h"
#include "carousel/rig/camera.h"
#include "carousel/rig/turntable.h"
#include "carousel/studio/calibrate_session.h"
#include "carousel/studio/rig_config.h"
#include "carousel/studio/sim_capture.h"

namespace carousel::studio {

// The devices a session captures with.
struct RigBackends {
  std::shared_ptr<rig::Turntable> turntable;
  std::vector<std::unique_ptr<rig::Camera>> cameras;
  std::vector<CameraModel> cam_from_table;  // per camera: cam_from_world at table angle 0
  CapturePlan plan;
  // With plan.shutter == "controller": pulses the shutter outputs of these cameras at once.
  std::function<void(const std::vector<int>& cameras)> release;
  // Calibration sessions: puts the board in placement `index` (the simulated rig moves its
  // board; hardware asks the operator).
  std::function<void(int index)> place_board;
  // Product sessions of plan.orientations > 1 passes: lays the product down for pass `pass`
  // (the simulated rig turns its scene; hardware asks the operator), before its first photo.
  std::function<void(int pass)> turn_product;
  // How the product lies in each pass, for the manifest ("upright", "side", "laid down").
  std::vector<std::string> orientation_names;
};

// What to open.
struct RigRequest {
  SimCaptureOptions sim;              // the simulated backend (scene, rig, stops, renderer)
  std::optional<RigConfig> hardware;  // set: this rig file's devices instead
  // Set: a calibration session's board (the simulated rig stands it on its table itself).
  std::optional<CalibrationPlan> calibration;
  // Hardware calibration: asks the operator to place the board for placement `index`.
  std::function<void(int index, int placements)> place_board;
  // Hardware product passes: asks the operator to lay the product down for pass `pass` (of
  // `passes`); returns once it lies so.
  std::function<void(int pass, int passes)> turn_product;
  // A rig calibration file whose cameras replace the rig's own (empty: none).
  std::filesystem::path calibration_file;
};

// Opens the request's rig; with a calibration file, its cameras are the photos' cameras.
// \throw DeviceError naming the device that is missing or wrong (before anything is captured),
// FormatError naming a calibration file that does not fit the rig, IoError.
RigBackends OpenRig(const RigRequest& request);

// Opens the turntable controller (serial) and the cameras (libgphoto2), checks the serial
// numbers, applies the controller gear and the camera settings. \throw DeviceError.
RigBackends OpenHardwareRig(const RigConfig& config);

// The simulated rig: the product model (or the calibration board) on the simulated turntable,
// one simulated camera per elevation, framed for the product. \throw IoError/FormatError for
// the scene file.
RigBackends OpenSimRig(const SimCaptureOptions& sim, const std::optional<CalibrationPlan>& plan);

// The simulated calibration board's origin height above the plate in its first placement (the
// simulated rig knows it exactly).
double SimBoardOriginHeight(const CalibrationPlan& plan);

}  // namespace carousel::studio
