// CameraModel: a pinhole camera with OpenCV's lens distortion and its pose.
//
// Frames and units (DESIGN.md): world = turntable frame (metres, +Z up along the rotation
// axis); camera frame = OpenCV's (x right, y down, z forward); pose stored as `cam_from_world`.
// Pixels follow OpenCV: integer coordinates are pixel centres, (0,0) is the centre of the
// top-left pixel, so the image covers [-0.5, width-0.5] x [-0.5, height-0.5].
// Distortion is OpenCV's five-parameter model (k1, k2, p1, p2, k3), applied to normalised
// coordinates (x/z, y/z) before the intrinsics; Project() agrees with cv::projectPoints.
#pragma once

#include <optional>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "carousel/core/rigid3.h"

namespace carousel {

// OpenCV's lens distortion of undistorted normalised coordinates (x, y) -> (*xd, *yd), for any
// scalar type (calibration differentiates it automatically with Ceres' Jets).
template <typename T>
void DistortNormalized(const T& k1, const T& k2, const T& p1, const T& p2, const T& k3, const T& x,
                       const T& y, T* xd, T* yd) {
  const T r2 = x * x + y * y;
  const T radial = T(1.0) + r2 * (k1 + r2 * (k2 + r2 * k3));
  *xd = x * radial + T(2.0) * p1 * x * y + p2 * (r2 + T(2.0) * x * x);
  *yd = y * radial + p1 * (r2 + T(2.0) * y * y) + T(2.0) * p2 * x * y;
}

// OpenCV's distortion coefficients, in OpenCV's order.
struct Distortion {
  double k1 = 0.0;  // radial, r^2
  double k2 = 0.0;  // radial, r^4
  double p1 = 0.0;  // tangential
  double p2 = 0.0;  // tangential
  double k3 = 0.0;  // radial, r^6

  bool IsZero() const { return k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0 && k3 == 0; }
  // Distorted normalised coordinates of undistorted normalised coordinates `xy`.
  Eigen::Vector2d Apply(const Eigen::Vector2d& xy) const;
  // As Apply(), with the 2x2 Jacobian d(Apply)/d(xy).
  Eigen::Vector2d Apply(const Eigen::Vector2d& xy, Eigen::Matrix2d* jacobian) const;
  // Inverse of Apply() by damped Newton iteration, accurate to ~1e-14 in normalised units
  // where the distortion is invertible. Returns nullopt where it does not converge (outside
  // the region where the lens model is one-to-one).
  std::optional<Eigen::Vector2d> Remove(const Eigen::Vector2d& distorted_xy) const;
};

// A viewing ray in world coordinates.
struct Ray {
  Eigen::Vector3d origin;     // the camera centre, metres
  Eigen::Vector3d direction;  // unit length
};

struct CameraModel {
  int width = 0;    // image width, pixels (> 0)
  int height = 0;   // image height, pixels (> 0)
  double fx = 0.0;  // focal length in pixels along x (> 0)
  double fy = 0.0;  // focal length in pixels along y (> 0)
  double cx = 0.0;  // principal point x, pixels (OpenCV convention)
  double cy = 0.0;  // principal point y, pixels
  Distortion distortion;
  Rigid3d cam_from_world;

  // Checks every field; \throw InvalidArgument naming the field that is wrong.
  void Validate() const;

  // Projects a world point to pixel coordinates, with distortion. nullopt when the point is
  // not in front of the camera (camera-frame z <= 0). The pixel may lie outside the image.
  std::optional<Eigen::Vector2d> Project(const Eigen::Vector3d& point_world) const;
  // Projects a point given in the camera frame. \pre point_cam.z() > 0 (not checked).
  Eigen::Vector2d ProjectFromCam(const Eigen::Vector3d& point_cam) const;
  // Pixel of undistorted normalised coordinates (x/z, y/z).
  Eigen::Vector2d PixelFromNormalized(const Eigen::Vector2d& xy) const;
  // Undistorted normalised coordinates of a pixel; nullopt where the distortion cannot be
  // inverted (far outside the image for strong distortion).
  std::optional<Eigen::Vector2d> NormalizedFromPixel(const Eigen::Vector2d& pixel) const;
  // The world point that projects to `pixel` at camera-frame depth `depth` (metres, > 0).
  std::optional<Eigen::Vector3d> Unproject(const Eigen::Vector2d& pixel, double depth) const;
  // The viewing ray through `pixel`.
  std::optional<Ray> RayThrough(const Eigen::Vector2d& pixel) const;

  // The camera centre in world coordinates.
  Eigen::Vector3d Centre() const;
  // The optical axis (camera +z) in world coordinates, unit length.
  Eigen::Vector3d ViewingDirection() const;
  // True when `pixel` lies inside the image, shrunk by `margin` pixels on every side.
  bool InImage(const Eigen::Vector2d& pixel, double margin = 0.0) const;

  // The 3x3 intrinsic matrix K.
  Eigen::Matrix3d K() const;
  // The same camera for an image resized by `factor` (e.g. 0.25 for a quarter-size preview),
  // keeping OpenCV's pixel-centre convention. \throw InvalidArgument if factor <= 0.
  CameraModel Scaled(double factor) const;

  // OpenCV interop: K, the 5 distortion coefficients, and the pose as rvec/tvec.
  cv::Matx33d CvCameraMatrix() const;
  cv::Vec<double, 5> CvDistCoeffs() const;
  void CvPose(cv::Vec3d* rvec, cv::Vec3d* tvec) const;
};

// Inline: the visual hull and the priors project millions of points.
inline Eigen::Vector2d Distortion::Apply(const Eigen::Vector2d& xy) const {
  Eigen::Vector2d distorted;
  DistortNormalized(k1, k2, p1, p2, k3, xy.x(), xy.y(), &distorted.x(), &distorted.y());
  return distorted;
}

inline Eigen::Vector2d CameraModel::PixelFromNormalized(const Eigen::Vector2d& xy) const {
  const Eigen::Vector2d distorted = distortion.Apply(xy);
  return {fx * distorted.x() + cx, fy * distorted.y() + cy};
}

inline Eigen::Vector2d CameraModel::ProjectFromCam(const Eigen::Vector3d& point_cam) const {
  return PixelFromNormalized(point_cam.head<2>() / point_cam.z());
}

}  // namespace carousel
