// A studio in a box: the hardware path with every device real except the hardware itself.
// The turntable controller's firmware runs in simavr behind a PTY (sim/avr_turntable.h) and each
// camera is a PTP/IP camera emulator (sim/ptpip_camera.h) on 127.0.0.1, which photographs the
// simulated product at the angle the simulated motor has really turned to. Config() is the
// rig.json that drives it: `carousel run --rig` and the window's hardware mode then go through
// real termios and real, unmodified libgphoto2 end to end (`carousel sim rig` runs one).
//
// Angles: the firmware's zero is where homing leaves the home sensor (the sensor's far edge,
// sensor_width microsteps after the table's position 0), so a photo at firmware angle a shows
// the product turned by a, as the cameras' calibration (the simulator's own, in Config())
// expects.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "carousel/core/options.h"
#include "carousel/studio/rig_config.h"
#include "carousel/studio/sim_capture.h"

namespace carousel::sim {
class AvrTurntable;
class PtpIpCamera;
}  // namespace carousel::sim

namespace carousel::studio {

struct SimulatedStudioOptions {
  // The product, the cameras' elevations and image size, the stops of the capture plan and
  // the renderer (what `carousel run --sim` photographs, here behind real device paths).
  SimCaptureOptions sim = [] {
    SimCaptureOptions o;
    o.rig.width = 1296;
    o.rig.height = 864;
    return o;
  }();
  // Cameras, spread over 15..45 degrees of elevation; 0 = one per sim.rig.elevations_deg.
  int cameras = 2;
  // Simulated seconds per wall second while the firmware waits (a move of 22.5 degrees takes
  // about 1 s of simulated time).
  double time_scale = 20.0;
  int settle_ms = 50;  // the capture plan's settle time
  // The firmware ELF; empty = this build's (DefaultFirmwarePath()).
  std::filesystem::path firmware;
  // Where the turntable's PTY link ("turntable") is made; it must exist.
  std::filesystem::path folder;
  static const OptionTable<SimulatedStudioOptions>& Fields();
  void Validate() const;
};

class SimulatedStudio {
 public:
  // Starts the firmware and the cameras. \throw DeviceError (a port that cannot be opened),
  // IoError/FormatError (the scene or the firmware file), InvalidArgument.
  explicit SimulatedStudio(const SimulatedStudioOptions& options);
  ~SimulatedStudio();
  SimulatedStudio(const SimulatedStudio&) = delete;
  SimulatedStudio& operator=(const SimulatedStudio&) = delete;

  // The rig file that drives this studio: the turntable's PTY, each camera's PTP/IP port and
  // serial with its exact calibration, the capture plan.
  RigConfig Config() const;
  int cameras() const;
  // Pulls camera `index`'s plug: its emulator closes (a session using it gets a device
  // error). PlugInCamera brings it back on the same port, with the photos on its card lost.
  void UnplugCamera(int index);
  void PlugInCamera(int index);
  sim::PtpIpCamera* camera(int index);  // nullptr while unplugged
  sim::AvrTurntable& turntable();

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace carousel::studio
