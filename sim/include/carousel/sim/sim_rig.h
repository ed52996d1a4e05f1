// The default simulated studio and the simulated devices that implement carousel_rig_api.
//
// Studio geometry: the turntable at the origin (+Z up), cameras on one arm at the azimuth of
// studio -Y (they look along +Y at table angle 0), each at its own elevation, aimed at the
// object's centre. Intrinsics like a real APS-C DSLR: 5184x3456 pixels on a 22.3 mm sensor
// with a 50 mm lens and mild barrel distortion. The distance frames the object so that its
// bounding sphere fills `fill` of the shorter image side.
// A photo at table angle theta has cam_from_world = cam_from_studio * Rz(theta) (world =
// turntable frame; DESIGN.md).
#pragma once

#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "carousel/core/camera_model.h"
#include "carousel/rig/camera.h"
#include "carousel/rig/turntable.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/scene.h"

namespace carousel::sim {

struct SimRigOptions {
  // One camera per entry, degrees above the plate (-10..85).
  std::vector<double> elevations_deg = {20.0};
  int width = 5184;               // pixels
  int height = 3456;              // pixels
  double sensor_width_mm = 22.3;  // APS-C
  double focal_length_mm = 50.0;  // > 0
  // Camera-to-object-centre distance, metres; 0 = frame the object (see `fill`).
  double distance_m = 0.0;
  // Fraction of the shorter image side the object's bounding sphere spans when framing (0..1).
  double fill = 0.75;
  Distortion distortion{-0.04, 0.015, 0.0, 0.0, 0.0};
  void Validate() const;
};

// cam_from_studio of each camera (= cam_from_world at table angle 0).
std::vector<CameraModel> MakeSimRig(const SimRigOptions& options,
                                    const Eigen::AlignedBox3d& object_bounds);

// The camera of a photo taken at `table_angle_rad`.
CameraModel CameraAtTableAngle(const CameraModel& at_zero, double table_angle_rad);

// ---- simulated devices ---------------------------------------------------------------------

struct SimTurntableOptions {
  double max_speed_deg_s = 60.0;       // > 0
  double acceleration_deg_s2 = 180.0;  // > 0
  // Wall-clock time per simulated second: 1 = real time, 0 = moves finish at once.
  double time_scale = 1.0;
  void Validate() const;
};

// Angle state with trapezoidal moves; thread-safe.
class SimTurntable : public rig::Turntable {
 public:
  explicit SimTurntable(SimTurntableOptions options = {});
  rig::TurntableInfo Identify() override;
  void Home(std::chrono::milliseconds timeout) override;
  void StartMoveTo(double angle_rad) override;
  void WaitUntilStopped(std::chrono::milliseconds timeout) override;
  rig::TurntableStatus Status() override;
  void Stop(bool emergency) override;
  // The studio's backlight (SimCamera renders a backlit shot while it is on).
  void SetBacklight(bool on) override;
  // Simulated seconds a move of `distance_rad` takes.
  double MoveSeconds(double distance_rad) const;

 private:
  // The angle (and speed, rad/s) at `now`; the caller holds mutex_.
  double AngleAt(std::chrono::steady_clock::time_point now, double* speed = nullptr) const;
  void Profile(double t, double* distance, double* speed) const;
  SimTurntableOptions options_;
  mutable std::mutex mutex_;
  double start_rad_ = 0.0;
  double target_rad_ = 0.0;
  std::chrono::steady_clock::time_point start_time_{};
  double duration_s_ = 0.0;   // wall-clock seconds of the current move
  double brake_speed_ = 0.0;  // > 0: the move is a stop decelerating from this speed, rad/s
  bool homed_ = false;
  bool backlight_ = false;
};

struct SimCameraOptions {
  std::string serial = "SIM0000";
  int jpeg_quality = 95;  // photos are JPEGs like a camera's
  RenderOptions render;   // noise, lights, backdrop; exposure is set from the settings
  void Validate() const;
};

// A camera that photographs the scene on a SimTurntable from its place in the studio (a backlit
// shot while the table's backlight is on).
// Settings (iso, aperture, shutterspeed) change the exposure like a real camera's, relative to
// ISO 100, f/8, 1/125 s.
class SimCamera : public rig::Camera {
 public:
  SimCamera(std::shared_ptr<const Scene> scene, CameraModel cam_from_studio,
            std::shared_ptr<SimTurntable> turntable, SimCameraOptions options = {});
  rig::CameraInfo Identify() override;
  std::map<std::string, std::string> Settings(std::chrono::milliseconds timeout) override;
  void SetSetting(const std::string& name, const std::string& value,
                  std::chrono::milliseconds timeout) override;
  rig::CapturedPhoto Capture(std::chrono::milliseconds timeout) override;
  void Download(const rig::CapturedPhoto& photo, const std::filesystem::path& destination,
                bool delete_from_camera, std::chrono::milliseconds timeout) override;
  cv::Mat PreviewFrame(std::chrono::milliseconds timeout) override;

  // The exposure gain the current settings give (1 at ISO 100, f/8, 1/125 s).
  double ExposureGain() const;
  // What is on the table from now on (e.g. the calibration board moved to a new placement).
  void SetScene(std::shared_ptr<const Scene> scene);
  // Renders a photo at the table's current angle with the current settings: JPEG bytes
  // (what Capture() stores on the card; the PTP/IP emulator serves these).
  std::vector<std::uint8_t> Shoot();

 private:
  std::shared_ptr<const Scene> scene_;
  CameraModel cam_from_studio_;
  std::shared_ptr<SimTurntable> turntable_;
  SimCameraOptions options_;
  mutable std::mutex mutex_;
  std::map<std::string, std::string> settings_;
  std::map<std::string, std::vector<std::uint8_t>> card_;  // camera path -> JPEG bytes
  int next_photo_ = 1;
  std::uint64_t shots_ = 1;  // noise seed per shot
};

}  // namespace carousel::sim
