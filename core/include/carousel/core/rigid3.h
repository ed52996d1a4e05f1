// Rigid3d: a rotation and a translation, the type of every pose in Carousel.
//
// Poses are named `b_from_a` (COLMAP's convention): `cam_from_world * p_world == p_cam`, and
// composition reads right to left: cam_from_table = cam_from_world * world_from_table.
// Units: metres and radians.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace carousel {

struct Rigid3d {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // orthonormal, det +1
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();   // metres

  Rigid3d() = default;
  Rigid3d(const Eigen::Matrix3d& rotation_in, const Eigen::Vector3d& translation_in)
      : rotation(rotation_in), translation(translation_in) {}

  // Applies the transform to a point.
  Eigen::Vector3d operator*(const Eigen::Vector3d& point) const {
    return rotation * point + translation;
  }
  // Composition: (a * b) * p == a * (b * p).
  Rigid3d operator*(const Rigid3d& other) const {
    return {rotation * other.rotation, rotation * other.translation + translation};
  }
  Rigid3d Inverse() const {
    const Eigen::Matrix3d rt = rotation.transpose();
    return {rt, -(rt * translation)};
  }
  Eigen::Matrix<double, 3, 4> ToMatrix3x4() const {
    Eigen::Matrix<double, 3, 4> m;
    m << rotation, translation;
    return m;
  }

  // A rotation by angle_rad about the +Z axis (counter-clockwise seen from +Z): the turntable.
  static Rigid3d RotationZ(double angle_rad) {
    return {Eigen::AngleAxisd(angle_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
            Eigen::Vector3d::Zero()};
  }
  // The pose of a camera at `eye` looking at `target`, with image "up" as close to `up` as
  // possible. Returns cam_from_world in OpenCV's camera frame (x right, y down, z forward).
  // \throw InvalidArgument if eye == target or the viewing direction is parallel to `up`.
  static Rigid3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                        const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

  // True when `rotation` is orthonormal with determinant +1 (to `tolerance`) and all finite.
  bool IsValid(double tolerance = 1e-6) const;
};

}  // namespace carousel
