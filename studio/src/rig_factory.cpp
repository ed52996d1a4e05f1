#include "carousel/studio/rig_factory.h"

#include <chrono>
#include <utility>

#include "carousel/calib/board.h"
#include "carousel/calib/rig_calibration.h"
#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/rig/gphoto_camera.h"
#include "carousel/rig/serial_turntable.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/sim/test_scenes.h"

namespace carousel::studio {
namespace {

// The board placements of a simulated calibration session: the board drawn, standing on the
// table at each lean; table_from_board per placement.
std::vector<std::pair<std::shared_ptr<sim::Scene>, Rigid3d>> SimBoardPlacements(
    const CalibrationPlan& plan) {
  const calib::BoardImage drawn = calib::DrawBoard(calib::BoardSpec::Parse(plan.board), 100, 50);
  std::vector<std::pair<std::shared_ptr<sim::Scene>, Rigid3d>> placements;
  for (int p = 0; p < plan.placements; ++p) {
    const Rigid3d pose =
        sim::StandCardOnTable(drawn.board_from_pixel, drawn.image.size(),
                              plan.sim_leans_deg[static_cast<std::size_t>(p)], 0.0);
    placements.emplace_back(std::make_shared<sim::Scene>(sim::MakePrintedCardScene(
                                drawn.image, drawn.board_from_pixel, pose)),
                            pose);
  }
  return placements;
}

// The photos' cameras from a rig calibration file instead of the rig's own.
void ApplyCalibrationFile(const std::filesystem::path& calibration, RigBackends* rig) {
  const calib::RigCalibration file = calib::ReadRigCalibration(calibration);
  if (file.cameras.size() != rig->cameras.size()) {
    throw FormatError(calibration, "calibrates " + std::to_string(file.cameras.size()) +
                                       " camera(s), the rig has " +
                                       std::to_string(rig->cameras.size()));
  }
  for (std::size_t c = 0; c < rig->cameras.size(); ++c) {
    const CameraModel& calibrated = file.cameras[c].camera;
    const CameraModel& own = rig->cam_from_table[c];
    if (calibrated.width != own.width || calibrated.height != own.height) {
      throw FormatError(calibration, "camera " + std::to_string(c) + " was calibrated for " +
                                         std::to_string(calibrated.width) + "x" +
                                         std::to_string(calibrated.height) + " photos, it takes " +
                                         std::to_string(own.width) + "x" +
                                         std::to_string(own.height));
    }
    rig->cam_from_table[c] = calibrated;
  }
}

}  // namespace

double SimBoardOriginHeight(const CalibrationPlan& plan) {
  return (SimBoardPlacements(plan).front().second * Eigen::Vector3d::Zero()).z();
}

RigBackends OpenSimRig(const SimCaptureOptions& sim, const std::optional<CalibrationPlan>& plan) {
  auto scene = std::make_shared<sim::Scene>(sim::LoadScene(ResolveScene(sim.scene, sim.data_dir)));
  sim::PlaceOnTurntable(*scene, sim.placement);
  RigBackends rig;
  rig.cam_from_table = sim::MakeSimRig(sim.rig, scene->Bounds());
  std::vector<std::pair<std::shared_ptr<sim::Scene>, Rigid3d>> boards;
  if (plan) {
    boards = SimBoardPlacements(*plan);
    scene = boards.front().first;
  }
  auto turntable = std::make_shared<sim::SimTurntable>(sim::SimTurntableOptions{.time_scale = 0.0});
  std::vector<sim::SimCamera*> cameras;
  for (std::size_t c = 0; c < rig.cam_from_table.size(); ++c) {
    sim::SimCameraOptions camera_options;
    camera_options.serial = "SIM" + std::to_string(1000 + c);
    camera_options.jpeg_quality = sim.jpeg_quality;
    camera_options.render = sim.render;
    camera_options.render.seed = sim.render.seed * 1000003ULL + c;
    auto camera =
        std::make_unique<sim::SimCamera>(scene, rig.cam_from_table[c], turntable, camera_options);
    cameras.push_back(camera.get());
    rig.cameras.push_back(std::move(camera));
  }
  if (plan) {
    rig.place_board = [cameras, boards](int index) {
      for (sim::SimCamera* camera : cameras)
        camera->SetScene(boards.at(static_cast<std::size_t>(index)).first);
    };
  }
  if (!plan && sim.orientations > 1) {
    // The product laid down for the second pass: the simulated rig turns it itself.
    Rigid3d laid;
    auto turned = std::make_shared<sim::Scene>(LaidDownScene(*scene, sim, &laid));
    rig.turn_product = [cameras, scene, turned](int pass) {
      for (sim::SimCamera* camera : cameras) camera->SetScene(pass == 0 ? scene : turned);
    };
    rig.orientation_names = {"upright", sim.second_pose};
  }
  rig.turntable = turntable;
  rig.plan.orientations = plan ? 1 : sim.orientations;
  rig.plan.stops = sim.stops;
  rig.plan.settle_ms = 0;
  rig.plan.mask_shots = sim.mask_shots;
  rig.plan.backlight_settle_ms = 0;
  return rig;
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
  // Mask shots need the controller's backlight output: named before anything is captured.
  if (config.capture.mask_shots == "backlit") table->SetBacklight(false);
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

RigBackends OpenRig(const RigRequest& request) {
  RigBackends rig = request.hardware ? OpenHardwareRig(*request.hardware)
                                     : OpenSimRig(request.sim, request.calibration);
  if (request.hardware && request.calibration) {
    rig.place_board = [place = request.place_board,
                       count = request.calibration->placements](int index) {
      if (place) place(index, count);
    };
  }
  if (request.hardware && !request.calibration && rig.plan.orientations > 1) {
    rig.turn_product = [ask = request.turn_product, passes = rig.plan.orientations](int pass) {
      if (ask) ask(pass, passes);
    };
    rig.orientation_names = {"upright"};
    for (int pass = 1; pass < rig.plan.orientations; ++pass)
      rig.orientation_names.push_back("laid down " + std::to_string(pass));
  }
  if (!request.calibration_file.empty()) ApplyCalibrationFile(request.calibration_file, &rig);
  return rig;
}

}  // namespace carousel::studio
