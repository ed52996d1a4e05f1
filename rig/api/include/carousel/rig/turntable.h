// Turntable: the interface every turntable backend implements (the serial controller in
// carousel_rig, the simulated table in sim/). Part of carousel_rig_api.
//
// Angles are radians in code (degrees only in files and flags), measured counter-clockwise
// seen from above (+Z), i.e. a view at angle theta sees the object rotated by +theta.
// Every blocking call takes a timeout and throws DeviceError naming the port on expiry or
// failure. Moves to absolute angles take the short way unless the backend documents
// otherwise; angles are not wrapped (720 deg means two turns from home).
#pragma once

#include <chrono>
#include <string>

#include "carousel/core/error.h"

namespace carousel::rig {

struct TurntableInfo {
  std::string model;
  std::string firmware;  // version string
  std::string port;      // "/dev/ttyACM0", "sim:table"
};

struct TurntableStatus {
  double angle_rad = 0.0;   // current position
  double target_rad = 0.0;  // last commanded position
  bool moving = false;
  bool homed = false;
  bool backlight = false;  // the backlight output is on
  std::string fault;       // empty when healthy
};

class Turntable {
 public:
  virtual ~Turntable() = default;

  virtual TurntableInfo Identify() = 0;
  // Finds the home position and sets the angle to 0 there.
  virtual void Home(std::chrono::milliseconds timeout) = 0;
  // Starts a move to an absolute angle and returns at once.
  virtual void StartMoveTo(double angle_rad) = 0;
  // Waits until the table is at rest. \throw DeviceError on timeout or fault.
  virtual void WaitUntilStopped(std::chrono::milliseconds timeout) = 0;
  // StartMoveTo + WaitUntilStopped.
  void MoveTo(double angle_rad, std::chrono::milliseconds timeout) {
    StartMoveTo(angle_rad);
    WaitUntilStopped(timeout);
  }
  virtual TurntableStatus Status() = 0;
  // Decelerates to a stop (emergency: at once).
  virtual void Stop(bool emergency) = 0;
  // Switches the backlight (the panel behind the product and the light table under the plate,
  // powered through the controller's light output) on or off; returns once it is switched.
  // Mask shots are taken with it on: the product dark against a lit backdrop, whatever its
  // colours. \throw DeviceError naming the port when the controller has no backlight output.
  virtual void SetBacklight(bool /*on*/) {
    throw DeviceError(Identify().port, "this turntable controller has no backlight output");
  }
};

}  // namespace carousel::rig
