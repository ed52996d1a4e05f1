#include "carousel/studio/simulated_studio.h"

#include <cmath>
#include <mutex>
#include <numbers>

#include "carousel/core/error.h"
#include "carousel/sim/avr_turntable.h"
#include "carousel/sim/ptpip_camera.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/studio/defaults.h"

namespace carousel::studio {

const OptionTable<SimulatedStudioOptions>& SimulatedStudioOptions::Fields() {
  using O = SimulatedStudioOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Include(&O::sim, SimCaptureOptions::Fields(),
              {"scene", "data", "views", "size", "elevations", "material", "noise", "seed",
               "jpeg-quality"});
    t.Add(&O::cameras, {.name = "cameras",
                        .help = "cameras, spread over 15..45 deg of elevation (0 = one per "
                                "--elevations)",
                        .min = 1,
                        .max = 8,
                        .special = 0,
                        .special_meaning = "one per --elevations"});
    t.Add(&O::time_scale, {.name = "time-scale",
                           .help = "simulated seconds per second while the firmware "
                                   "waits",
                           .min = 1,
                           .max = 1000});
    t.Add(&O::settle_ms,
          {.name = "settle-ms", .help = "the capture plan's settle time", .unit = "ms", .min = 0});
    t.Add(&O::firmware, {.name = "firmware",
                         .help = "turntable firmware ELF (default: this "
                                 "build's)"});
    return t;
  }();
  return table;
}

void SimulatedStudioOptions::Validate() const {
  Fields().Check(*this);
  sim.Validate();
  CAROUSEL_THROW_IF(folder.empty(), InvalidArgument,
                    "the simulated studio needs a folder for its turntable's PTY link");
}

struct SimulatedStudio::State {
  SimulatedStudioOptions options;
  std::shared_ptr<sim::Scene> scene;
  std::shared_ptr<sim::SimTurntable> table;
  std::vector<CameraModel> models;
  std::vector<std::shared_ptr<sim::SimCamera>> sim_cameras;
  std::vector<std::uint16_t> ports;
  std::unique_ptr<sim::AvrTurntable> controller;
  std::mutex shoot_mutex;  // one simulated table: one camera moves it at a time
  std::vector<std::unique_ptr<sim::PtpIpCamera>> emulators;  // destroyed before the controller

  std::unique_ptr<sim::PtpIpCamera> Emulator(std::size_t c, std::uint16_t port) {
    sim::PtpIpCameraOptions options;
    options.serial = "EMU" + std::to_string(c);
    options.model = "PTP/IP Emulator (simulated studio)";
    options.port = port;
    return std::make_unique<sim::PtpIpCamera>(
        [this, c](const std::map<std::string, std::string>& settings) {
          std::lock_guard<std::mutex> lock(shoot_mutex);
          // The angle the motor has turned the table to, from the firmware's zero.
          sim::AvrTurntableOptions avr;
          const auto steps = static_cast<double>(avr.steps_per_rev);
          const double position = std::fmod(
              static_cast<double>(controller->table_position() - avr.sensor_width), steps);
          table->StartMoveTo(2.0 * std::numbers::pi * position / steps);
          table->WaitUntilStopped(std::chrono::seconds(1));
          table->SetBacklight(controller->backlight_on());
          for (const auto& [name, value] : settings)
            sim_cameras[c]->SetSetting(name, value, std::chrono::milliseconds(0));
          return sim_cameras[c]->Shoot();
        },
        options);
  }
};

SimulatedStudio::SimulatedStudio(const SimulatedStudioOptions& requested)
    : state_(std::make_unique<State>()) {
  State& s = *state_;
  s.options = requested;
  SimulatedStudioOptions& o = s.options;
  if (o.sim.data_dir.empty()) o.sim.data_dir = DefaultDataDir();
  if (o.firmware.empty()) o.firmware = DefaultFirmwarePath();
  if (o.cameras > 0) {
    o.sim.rig.elevations_deg.clear();
    for (int c = 0; c < o.cameras; ++c)
      o.sim.rig.elevations_deg.push_back(o.cameras == 1 ? 20.0 : 15.0 + 30.0 * c / (o.cameras - 1));
  }
  o.Validate();
  // The firmware's defaults (9600 microsteps per table turn, the home sensor) are the
  // simulated controller's; sim::AvrTurntableOptions says so.
  sim::AvrTurntableOptions avr;
  avr.firmware = o.firmware;
  avr.time_scale = o.time_scale;
  avr.link = o.folder / "turntable";
  s.controller = std::make_unique<sim::AvrTurntable>(avr);

  s.scene = std::make_shared<sim::Scene>(sim::LoadScene(ResolveScene(o.sim.scene, o.sim.data_dir)));
  if (o.sim.material != sim::MaterialOverride::kNone) s.scene->OverrideMaterials(o.sim.material);
  sim::PlaceOnTurntable(*s.scene, o.sim.placement);
  s.models = sim::MakeSimRig(o.sim.rig, s.scene->Bounds());
  s.table = std::make_shared<sim::SimTurntable>(sim::SimTurntableOptions{.time_scale = 0.0});
  for (std::size_t c = 0; c < s.models.size(); ++c) {
    sim::SimCameraOptions camera_options;
    camera_options.jpeg_quality = o.sim.jpeg_quality;
    camera_options.render = o.sim.render;
    camera_options.render.seed = o.sim.render.seed * 1000003ULL + c;
    s.sim_cameras.push_back(
        std::make_shared<sim::SimCamera>(s.scene, s.models[c], s.table, camera_options));
    s.emulators.push_back(s.Emulator(c, 0));
    s.ports.push_back(s.emulators.back()->port());
  }
}

SimulatedStudio::~SimulatedStudio() {
  state_->emulators.clear();
  state_->controller.reset();
}

RigConfig SimulatedStudio::Config() const {
  const State& s = *state_;
  RigConfig config;
  config.turntable.port = s.controller->port();
  for (std::size_t c = 0; c < s.models.size(); ++c) {
    RigCameraConfig camera;
    camera.port =
        "ptpip:127.0.0.1:" + std::to_string(s.ports[c]) + ":" + std::to_string(s.ports[c]);
    camera.serial = "EMU" + std::to_string(c);
    camera.calibration = s.models[c];
    config.cameras.push_back(camera);
  }
  config.capture.stops = s.options.sim.stops;
  config.capture.settle_ms = s.options.settle_ms;
  return config;
}

int SimulatedStudio::cameras() const { return static_cast<int>(state_->models.size()); }

void SimulatedStudio::UnplugCamera(int index) {
  state_->emulators.at(static_cast<std::size_t>(index)).reset();
}

void SimulatedStudio::PlugInCamera(int index) {
  const auto c = static_cast<std::size_t>(index);
  if (state_->emulators.at(c)) return;
  state_->emulators[c] = state_->Emulator(c, state_->ports[c]);
}

sim::PtpIpCamera* SimulatedStudio::camera(int index) {
  return state_->emulators.at(static_cast<std::size_t>(index)).get();
}

sim::AvrTurntable& SimulatedStudio::turntable() { return *state_->controller; }

}  // namespace carousel::studio
