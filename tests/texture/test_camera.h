// A camera for the texture tests' small scenes.
#pragma once

#include <Eigen/Core>

#include "carousel/core/camera_model.h"

namespace carousel::texture::test_support {

// A 1600 x 1200 camera (fx = fy = 2000 px) at `centre` looking at the origin, image rows going
// towards -Y. \pre `centre` has a non-zero X or Z (rows stay perpendicular to the view).
inline CameraModel CameraLookingAtOrigin(const Eigen::Vector3d& centre) {
  CameraModel camera;
  camera.width = 1600;
  camera.height = 1200;
  camera.fx = camera.fy = 2000.0;
  camera.cx = 799.5;
  camera.cy = 599.5;
  const Eigen::Vector3d forward = -centre.normalized();
  const Eigen::Vector3d down(0.0, -1.0, 0.0);
  Eigen::Matrix3d rotation;
  rotation.row(0) = down.cross(forward).transpose();
  rotation.row(1) = down.transpose();
  rotation.row(2) = forward.transpose();
  camera.cam_from_world = Rigid3d(rotation, -(rotation * centre));
  return camera;
}

}  // namespace carousel::texture::test_support
