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
