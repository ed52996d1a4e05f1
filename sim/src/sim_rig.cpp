#include "carousel/sim/sim_rig.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/rig/camera_settings.h"

namespace carousel::sim {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

// Whether the simulated camera takes `value` for its setting `name`.
bool IsValidSetting(const std::string& name, const std::string& value) {
  try {
    if (name == rig::kSettingIso) {
      std::size_t used = 0;
      const int iso = std::stoi(value, &used);
      return used == value.size() && iso >= 50 && iso <= 102400;
    }
    if (name == rig::kSettingAperture) {
      const double f = rig::ParseApertureFNumber(value);
      return f >= 1.0 && f <= 64.0;
    }
    if (name == rig::kSettingShutterSpeed) {
      const double t = rig::ParseShutterSeconds(value);
      return t > 0 && t <= 30;
    }
  } catch (const std::logic_error&) {  // std::stoi
    return false;
  } catch (const InvalidArgument&) {  // the label parsers
    return false;
  }
  if (name == rig::kSettingImageFormat) return value == "jpeg";
  if (name == rig::kSettingCaptureTarget) return value == "card" || value == "ram";
  return true;
}

}  // namespace

void SimRigOptions::Validate() const {
  CAROUSEL_THROW_IF(elevations_deg.empty(), InvalidArgument,
                    "SimRigOptions.elevations_deg needs at least one camera");
  for (double elevation : elevations_deg) {
    CAROUSEL_THROW_IF(!(elevation >= -10 && elevation <= 85), InvalidArgument,
                      "SimRigOptions.elevations_deg: " << elevation << " is outside -10..85");
  }
  CAROUSEL_THROW_IF(width < 16 || height < 16 || width > 20000 || height > 20000, InvalidArgument,
                    "SimRigOptions image size " << width << "x" << height << " is out of range");
  CAROUSEL_THROW_IF(!(sensor_width_mm > 0) || !(focal_length_mm > 0), InvalidArgument,
                    "SimRigOptions.sensor_width_mm and focal_length_mm must be > 0");
  CAROUSEL_THROW_IF(!(distance_m >= 0), InvalidArgument, "SimRigOptions.distance_m must be >= 0");
  CAROUSEL_THROW_IF(!(fill > 0 && fill <= 1), InvalidArgument,
                    "SimRigOptions.fill must be in (0, 1], got " << fill);
}

std::vector<CameraModel> MakeSimRig(const SimRigOptions& options,
                                    const Eigen::AlignedBox3d& object_bounds) {
  options.Validate();
  CAROUSEL_THROW_IF(object_bounds.isEmpty(), InvalidArgument, "MakeSimRig: empty object");
  const double fx = options.focal_length_mm / options.sensor_width_mm * options.width;
  const Eigen::Vector3d target = object_bounds.center();
  const double radius = 0.5 * object_bounds.sizes().norm();
  double distance = options.distance_m;
  if (distance <= 0) {
    // The sphere's angular radius asin(r / d) spans `fill` of the half-size of the shorter side.
    const double half_fov = std::atan(0.5 * std::min(options.width, options.height) / fx);
    distance = radius / std::sin(options.fill * half_fov);
  }
  std::vector<CameraModel> cameras;
  for (double elevation_deg : options.elevations_deg) {
    const double e = elevation_deg * kDegToRad;
    CameraModel camera;
    camera.width = options.width;
    camera.height = options.height;
    camera.fx = camera.fy = fx;
    camera.cx = 0.5 * (options.width - 1);
    camera.cy = 0.5 * (options.height - 1);
    camera.distortion = options.distortion;
    const Eigen::Vector3d eye = target + distance * Eigen::Vector3d(0.0, -std::cos(e), std::sin(e));
    camera.cam_from_world = Rigid3d::LookAt(eye, target);
    camera.Validate();
    cameras.push_back(camera);
  }
  return cameras;
}

CameraModel CameraAtTableAngle(const CameraModel& at_zero, double table_angle_rad) {
  CameraModel camera = at_zero;
  camera.cam_from_world = at_zero.cam_from_world * Rigid3d::RotationZ(table_angle_rad);
  return camera;
}

// ---- SimTurntable ---------------------------------------------------------------------------

void SimTurntableOptions::Validate() const {
  CAROUSEL_THROW_IF(!(max_speed_deg_s > 0) || !(acceleration_deg_s2 > 0), InvalidArgument,
                    "SimTurntableOptions: speed and acceleration must be > 0");
  CAROUSEL_THROW_IF(!(time_scale >= 0), InvalidArgument,
                    "SimTurntableOptions.time_scale must be >= 0");
}

SimTurntable::SimTurntable(SimTurntableOptions options) : options_(options) {
  options_.Validate();
  start_time_ = std::chrono::steady_clock::now();
}

rig::TurntableInfo SimTurntable::Identify() {
  return {"Carousel simulated turntable", "sim-1", "sim:turntable"};
}

double SimTurntable::MoveSeconds(double distance_rad) const {
  // Trapezoidal profile; triangular when the top speed is never reached.
  const double d = std::abs(distance_rad) / kDegToRad;
  const double v = options_.max_speed_deg_s, a = options_.acceleration_deg_s2;
  const double ramp = v * v / a;  // distance spent accelerating plus decelerating
  return d >= ramp ? d / v + v / a : 2.0 * std::sqrt(d / a);
}

// Distance covered and speed after `t` simulated seconds of the current move.
void SimTurntable::Profile(double t, double* distance, double* speed) const {
  const double d = std::abs(target_rad_ - start_rad_);
  const double a = options_.acceleration_deg_s2 * kDegToRad;
  if (brake_speed_ > 0) {  // decelerating from brake_speed_ to rest
    const double tt = std::min(t, brake_speed_ / a);
    *distance = std::min(d, brake_speed_ * tt - 0.5 * a * tt * tt);
    *speed = std::max(0.0, brake_speed_ - a * tt);
    return;
  }
  const double v = std::min(options_.max_speed_deg_s * kDegToRad, std::sqrt(d * a));
  const double ramp = v / a;
  const double total = v > 0 ? d / v + ramp : 0.0;
  if (t >= total) {
    *distance = d;
    *speed = 0.0;
  } else if (t < ramp) {
    *distance = 0.5 * a * t * t;
    *speed = a * t;
  } else if (t < total - ramp) {
    *distance = 0.5 * a * ramp * ramp + v * (t - ramp);
    *speed = v;
  } else {
    *distance = d - 0.5 * a * (total - t) * (total - t);
    *speed = a * (total - t);
  }
  *distance = std::clamp(*distance, 0.0, d);
}

double SimTurntable::AngleAt(std::chrono::steady_clock::time_point now, double* speed) const {
  double s = 0.0, v = 0.0;
  if (duration_s_ <= 0 || options_.time_scale <= 0) {
    s = std::abs(target_rad_ - start_rad_);
  } else {
    const double t = std::chrono::duration<double>(now - start_time_).count() / options_.time_scale;
    Profile(t, &s, &v);
  }
  if (speed != nullptr) *speed = v;
  return start_rad_ + (target_rad_ >= start_rad_ ? s : -s);
}

void SimTurntable::Home(std::chrono::milliseconds timeout) {
  StartMoveTo(0.0);
  WaitUntilStopped(timeout);
  std::lock_guard<std::mutex> lock(mutex_);
  homed_ = true;
}

void SimTurntable::StartMoveTo(double angle_rad) {
  CAROUSEL_THROW_IF(!std::isfinite(angle_rad), InvalidArgument,
                    "SimTurntable: target angle is not finite");
  std::lock_guard<std::mutex> lock(mutex_);
  const auto now = std::chrono::steady_clock::now();
  start_rad_ = AngleAt(now);
  target_rad_ = angle_rad;
  brake_speed_ = 0;
  start_time_ = now;
  duration_s_ = MoveSeconds(target_rad_ - start_rad_) * options_.time_scale;
}

void SimTurntable::WaitUntilStopped(std::chrono::milliseconds timeout) {
  std::chrono::steady_clock::time_point end;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    end = start_time_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(duration_s_));
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  if (end > deadline) {
    std::this_thread::sleep_until(deadline);
    throw DeviceError("sim:turntable",
                      "move did not finish within " + std::to_string(timeout.count()) + " ms");
  }
  std::this_thread::sleep_until(end);
}

rig::TurntableStatus SimTurntable::Status() {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto now = std::chrono::steady_clock::now();
  rig::TurntableStatus status;
  status.angle_rad = AngleAt(now);
  status.target_rad = target_rad_;
  status.moving = status.angle_rad != target_rad_;
  status.homed = homed_;
  status.backlight = backlight_;
  return status;
}

void SimTurntable::SetBacklight(bool on) {
  std::lock_guard<std::mutex> lock(mutex_);
  backlight_ = on;
}

void SimTurntable::Stop(bool emergency) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto now = std::chrono::steady_clock::now();
  double speed = 0.0;
  const double here = AngleAt(now, &speed);
  const double direction = target_rad_ >= start_rad_ ? 1.0 : -1.0;
  start_rad_ = target_rad_ = here;
  start_time_ = now;
  duration_s_ = 0;
  brake_speed_ = 0;
  if (emergency || speed <= 0) return;
  // Decelerate from the current speed at the configured rate.
  const double a = options_.acceleration_deg_s2 * kDegToRad;
  target_rad_ = here + direction * speed * speed / (2 * a);
  brake_speed_ = speed;
  duration_s_ = speed / a * options_.time_scale;
}

// ---- SimCamera ------------------------------------------------------------------------------

void SimCameraOptions::Validate() const {
  CAROUSEL_THROW_IF(jpeg_quality < 1 || jpeg_quality > 100, InvalidArgument,
                    "SimCameraOptions.jpeg_quality must be in 1..100");
  render.Validate();
}

SimCamera::SimCamera(std::shared_ptr<const Scene> scene, CameraModel cam_from_studio,
                     std::shared_ptr<SimTurntable> turntable, SimCameraOptions options)
    : scene_(std::move(scene)),
      cam_from_studio_(std::move(cam_from_studio)),
      turntable_(std::move(turntable)),
      options_(std::move(options)) {
  CAROUSEL_THROW_IF(!scene_ || !turntable_, InvalidArgument,
                    "SimCamera needs a scene and a turntable");
  cam_from_studio_.Validate();
  options_.Validate();
  settings_ = {{rig::kSettingIso, "100"},
               {rig::kSettingAperture, "f/8"},
               {rig::kSettingShutterSpeed, "1/125"},
               {rig::kSettingWhiteBalance, "daylight"},
               {rig::kSettingImageFormat, "jpeg"},
               {rig::kSettingCaptureTarget, "card"}};
}

rig::CameraInfo SimCamera::Identify() {
  return {"Carousel", "Simulated DSLR", options_.serial, "sim:" + options_.serial, "simulated"};
}

std::map<std::string, std::string> SimCamera::Settings(std::chrono::milliseconds) {
  std::lock_guard<std::mutex> lock(mutex_);
  return settings_;
}

void SimCamera::SetSetting(const std::string& name, const std::string& value,
                           std::chrono::milliseconds) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = settings_.find(name);
  CAROUSEL_THROW_IF(it == settings_.end(), InvalidArgument,
                    "camera " << options_.serial << ": unknown setting '" << name << "'");
  CAROUSEL_THROW_IF(
      !IsValidSetting(name, value), InvalidArgument,
      "camera " << options_.serial << ": '" << value << "' is not a valid value for " << name);
  it->second = value;
}

double SimCamera::ExposureGain() const {
  std::lock_guard<std::mutex> lock(mutex_);
  const double iso = std::stod(settings_.at(rig::kSettingIso));
  const double f = rig::ParseApertureFNumber(settings_.at(rig::kSettingAperture));
  const double t = rig::ParseShutterSeconds(settings_.at(rig::kSettingShutterSpeed));
  return (iso / 100.0) * (t * 125.0) * (64.0 / (f * f));
}

std::vector<std::uint8_t> SimCamera::Shoot() {
  const rig::TurntableStatus table = turntable_->Status();
  const double angle = table.angle_rad;
  RenderOptions render = options_.render;
  render.backlit = table.backlight;
  render.exposure = std::clamp(ExposureGain(), 1e-3, 999.0);
  std::shared_ptr<const Scene> scene;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    render.seed = options_.render.seed ^ (0x51ed27ULL * static_cast<std::uint64_t>(shots_));
    ++shots_;
    scene = scene_;
  }
  const RenderResult result =
      Render(*scene, CameraAtTableAngle(cam_from_studio_, angle), angle, render);
  std::vector<std::uint8_t> jpeg;
  cv::imencode(".jpg", result.image, jpeg, {cv::IMWRITE_JPEG_QUALITY, options_.jpeg_quality});
  return jpeg;
}

rig::CapturedPhoto SimCamera::Capture(std::chrono::milliseconds) {
  const auto triggered = std::chrono::steady_clock::now();
  std::vector<std::uint8_t> jpeg = Shoot();
  std::lock_guard<std::mutex> lock(mutex_);
  // Like a camera: IMG_0001..IMG_9999 per folder, then the next folder (100SIMCA, 101SIMCA).
  const int folder = 100 + (next_photo_ - 1) / 9999;
  const int number = (next_photo_ - 1) % 9999 + 1;
  const std::string path = "/store_00010001/DCIM/" + std::to_string(folder) + "SIMCA/IMG_" +
                           std::to_string(10000 + number).substr(1) + ".JPG";
  ++next_photo_;
  const std::uint64_t size = jpeg.size();
  card_[path] = std::move(jpeg);
  return {path, size, triggered};
}

void SimCamera::Download(const rig::CapturedPhoto& photo, const std::filesystem::path& destination,
                         bool delete_from_camera, std::chrono::milliseconds) {
  std::vector<std::uint8_t> bytes;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = card_.find(photo.camera_path);
    if (it == card_.end()) {
      throw DeviceError("sim:" + options_.serial, "no photo " + photo.camera_path + " on the card");
    }
    bytes = it->second;
  }
  // Deleted from the card only once it is safely on disk.
  WriteFileAtomic(destination, bytes, {.overwrite = false});
  if (delete_from_camera) {
    std::lock_guard<std::mutex> lock(mutex_);
    card_.erase(photo.camera_path);
  }
}

cv::Mat SimCamera::PreviewFrame(std::chrono::milliseconds) {
  const rig::TurntableStatus table = turntable_->Status();
  const double angle = table.angle_rad;
  const double factor = 640.0 / cam_from_studio_.width;
  RenderOptions render = options_.render;
  render.backlit = table.backlight;
  render.samples_per_axis = 1;
  render.exposure = std::clamp(ExposureGain(), 1e-3, 999.0);
  std::shared_ptr<const Scene> scene;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    scene = scene_;
  }
  return Render(*scene, CameraAtTableAngle(cam_from_studio_.Scaled(factor), angle), angle, render)
      .image;
}

void SimCamera::SetScene(std::shared_ptr<const Scene> scene) {
  CAROUSEL_THROW_IF(!scene, InvalidArgument, "SimCamera::SetScene: no scene");
  std::lock_guard<std::mutex> lock(mutex_);
  scene_ = std::move(scene);
}

}  // namespace carousel::sim
