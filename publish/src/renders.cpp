#include "carousel/publish/renders.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "carousel/core/error.h"
#include "carousel/texture/held_out.h"

namespace carousel::publish {

CameraModel PinholeLookingAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                             double fov_deg, int width, int height) {
  CAROUSEL_THROW_IF(width <= 0 || height <= 0, InvalidArgument,
                    "camera: image size must be positive");
  CAROUSEL_THROW_IF(!(fov_deg > 1.0 && fov_deg < 170.0), InvalidArgument,
                    "camera: field of view must be in (1, 170) degrees, got " << fov_deg);
  CAROUSEL_THROW_IF(!((target - eye).norm() > 0.0), InvalidArgument,
                    "camera: the eye is at the target");
  constexpr double kDeg = std::numbers::pi / 180.0;
  CameraModel camera;
  camera.width = width;
  camera.height = height;
  camera.fy = 0.5 * height / std::tan(0.5 * fov_deg * kDeg);
  camera.fx = camera.fy;
  // The image's centre in OpenCV's pixel-centre convention.
  camera.cx = 0.5 * width - 0.5;
  camera.cy = 0.5 * height - 0.5;
  const Eigen::Vector3d forward = (target - eye).normalized();
  Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ());
  if (right.norm() < 1e-9) right = Eigen::Vector3d::UnitX();
  right.normalize();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d world_from_cam;
  world_from_cam.col(0) = right;
  world_from_cam.col(1) = down;
  world_from_cam.col(2) = forward;
  camera.cam_from_world.rotation = world_from_cam.transpose();
  camera.cam_from_world.translation = -(world_from_cam.transpose() * eye);
  return camera;
}

CameraModel OrbitCamera(const texture::TexturedModel& model, const OrbitShot& shot) {
  CAROUSEL_THROW_IF(model.positions.empty(), InvalidArgument, "orbit camera: the model is empty");
  CAROUSEL_THROW_IF(!(shot.fill > 0.0 && shot.fill <= 1.0), InvalidArgument,
                    "orbit camera: fill must be in (0, 1]");
  CAROUSEL_THROW_IF(!(shot.fov_deg > 1.0 && shot.fov_deg < 170.0), InvalidArgument,
                    "orbit camera: field of view must be in (1, 170) degrees");
  Eigen::AlignedBox3d box;
  for (const Eigen::Vector3d& p : model.positions) box.extend(p);
  const Eigen::Vector3d centre = box.center();
  const double radius = std::max(0.5 * box.diagonal().norm(), 1e-6);
  constexpr double kDeg = std::numbers::pi / 180.0;
  const double fy = 0.5 * std::max(shot.height, 1) / std::tan(0.5 * shot.fov_deg * kDeg);
  // The sphere's angular radius fills `fill` of the shorter half-side.
  const double half_side_px = 0.5 * std::min(shot.width, shot.height) * shot.fill;
  const double distance = radius / std::sin(std::atan(half_side_px / fy));
  const double az = shot.azimuth_deg * kDeg, el = shot.elevation_deg * kDeg;
  if (shot.framing != OrbitShot::Framing::kSphere) {
    // The cylinder: radius about the vertical axis through the box's centre, and height.
    double r = 1e-6;
    for (const Eigen::Vector3d& p : model.positions)
      r = std::max(r, std::hypot(p.x() - centre.x(), p.y() - centre.y()));
    const double height = box.sizes().z();
    const double fx = fy;  // square pixels
    const double tan_h = 0.5 * std::max(shot.width, 1) * shot.fill / fx;
    const double tan_v = 0.5 * std::max(shot.height, 1) * shot.fill / fy;
    const double vertical = 0.5 * height * std::cos(el) + r * std::abs(std::sin(el));
    // The nearest point of the cylinder is r closer than its axis.
    const double tight_distance = r + std::max(r / tan_h, vertical / tan_v);
    const Eigen::Vector3d tight_eye =
        centre + tight_distance * Eigen::Vector3d(std::cos(el) * std::cos(az),
                                                  std::cos(el) * std::sin(az), std::sin(el));
    CameraModel camera = PinholeLookingAt(tight_eye, centre, shot.fov_deg, shot.width, shot.height);
    if (shot.framing == OrbitShot::Framing::kCylinder) return camera;
    // kFit: the outline's extent from the centre, as a fraction of the half-image, scales the
    // distance from the centre (exact for the centre's depth; three rounds settle the rest).
    double d = tight_distance;
    for (int round = 0; round < 3; ++round) {
      double extent = 1e-9;
      for (const Eigen::Vector3d& p : model.positions) {
        const Eigen::Vector3d c =
            camera.cam_from_world.rotation * p + camera.cam_from_world.translation;
        if (c.z() <= 1e-9) continue;
        extent = std::max({extent, std::abs(camera.fx * c.x() / c.z()) / (0.5 * shot.width),
                           std::abs(camera.fy * c.y() / c.z()) / (0.5 * shot.height)});
      }
      d *= extent / shot.fill;
      const Eigen::Vector3d eye =
          centre + d * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                       std::sin(el));
      camera = PinholeLookingAt(eye, centre, shot.fov_deg, shot.width, shot.height);
    }
    return camera;
  }
  const Eigen::Vector3d eye =
      centre + distance * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                          std::sin(el));
  return PinholeLookingAt(eye, centre, shot.fov_deg, shot.width, shot.height);
}

cv::Mat RenderShot(const texture::TexturedModel& model, const OrbitShot& shot) {
  texture::ModelRenderOptions options;
  options.backdrop_top_bgr = {255, 255, 255};
  options.backdrop_bottom_bgr = {255, 255, 255};
  options.samples_per_axis = 2;
  return texture::RenderTexturedModel(model, OrbitCamera(model, shot), options).image;
}

}  // namespace carousel::publish
