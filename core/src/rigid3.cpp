#include "carousel/core/rigid3.h"

#include <cmath>

#include "carousel/core/error.h"

namespace carousel {

Rigid3d Rigid3d::LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                        const Eigen::Vector3d& up) {
  const Eigen::Vector3d forward = target - eye;
  CAROUSEL_THROW_IF(forward.norm() < 1e-12, InvalidArgument,
                    "Rigid3d::LookAt: eye and target coincide");
  const Eigen::Vector3d z = forward.normalized();
  // Image x points right (forward x up); image y points down (forward x right).
  Eigen::Vector3d x = z.cross(up);
  CAROUSEL_THROW_IF(x.norm() < 1e-9, InvalidArgument,
                    "Rigid3d::LookAt: viewing direction is parallel to the up vector");
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d world_from_cam_rotation;
  world_from_cam_rotation << x, y, z;
  const Eigen::Matrix3d rotation = world_from_cam_rotation.transpose();
  return {rotation, -(rotation * eye)};
}

bool Rigid3d::IsValid(double tolerance) const {
  if (!rotation.allFinite() || !translation.allFinite()) return false;
  const double orthonormality =
      (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  return orthonormality <= tolerance && std::abs(rotation.determinant() - 1.0) <= tolerance;
}

}  // namespace carousel
