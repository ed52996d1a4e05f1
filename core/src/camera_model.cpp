#include "carousel/core/camera_model.h"

#include <cmath>

#include <opencv2/calib3d.hpp>

#include "carousel/core/error.h"

namespace carousel {

Eigen::Vector2d Distortion::Apply(const Eigen::Vector2d& xy, Eigen::Matrix2d* jacobian) const {
  const double x = xy.x();
  const double y = xy.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  // d(radial)/d(r2); d(r2)/dx = 2x.
  const double dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
  const double dradial_dx = 2.0 * x * dradial_dr2;
  const double dradial_dy = 2.0 * y * dradial_dr2;
  (*jacobian)(0, 0) = radial + x * dradial_dx + 2.0 * p1 * y + 6.0 * p2 * x;
  (*jacobian)(0, 1) = x * dradial_dy + 2.0 * p1 * x + 2.0 * p2 * y;
  (*jacobian)(1, 0) = y * dradial_dx + 2.0 * p1 * x + 2.0 * p2 * y;
  (*jacobian)(1, 1) = radial + y * dradial_dy + 6.0 * p1 * y + 2.0 * p2 * x;
  return Apply(xy);
}

std::optional<Eigen::Vector2d> Distortion::Remove(const Eigen::Vector2d& distorted_xy) const {
  if (IsZero()) return distorted_xy;
  if (!distorted_xy.allFinite()) return std::nullopt;
  // Damped Newton: minimise |Apply(u) - target|^2 starting from the distorted point.
  Eigen::Vector2d u = distorted_xy;
  Eigen::Matrix2d jacobian;
  Eigen::Vector2d residual = Apply(u, &jacobian) - distorted_xy;
  double error = residual.squaredNorm();
  constexpr int kMaxIterations = 100;
  for (int iteration = 0; iteration < kMaxIterations && error > 0.0; ++iteration) {
    const double det = jacobian.determinant();
    if (!std::isfinite(det) || std::abs(det) < 1e-15) return std::nullopt;
    const Eigen::Vector2d step = jacobian.inverse() * residual;
    double scale = 1.0;
    bool improved = false;
    for (int halving = 0; halving < 30; ++halving, scale *= 0.5) {
      const Eigen::Vector2d candidate = u - scale * step;
      Eigen::Matrix2d candidate_jacobian;
      const Eigen::Vector2d candidate_residual =
          Apply(candidate, &candidate_jacobian) - distorted_xy;
      const double candidate_error = candidate_residual.squaredNorm();
      if (candidate_error < error) {
        u = candidate;
        jacobian = candidate_jacobian;
        residual = candidate_residual;
        error = candidate_error;
        improved = true;
        break;
      }
    }
    if (!improved || (scale * step).norm() <= 1e-16 * (1.0 + u.norm())) break;
  }
  // Converged when the residual is at the level of rounding error of the coordinates.
  if (!(std::sqrt(error) <= 1e-11 * (1.0 + distorted_xy.norm()))) return std::nullopt;
  return u;
}

void CameraModel::Validate() const {
  CAROUSEL_THROW_IF(width <= 0, InvalidArgument, "CameraModel.width must be > 0, got " << width);
  CAROUSEL_THROW_IF(height <= 0, InvalidArgument, "CameraModel.height must be > 0, got " << height);
  CAROUSEL_THROW_IF(!(std::isfinite(fx) && fx > 0), InvalidArgument,
                    "CameraModel.fx must be a finite value > 0, got " << fx);
  CAROUSEL_THROW_IF(!(std::isfinite(fy) && fy > 0), InvalidArgument,
                    "CameraModel.fy must be a finite value > 0, got " << fy);
  CAROUSEL_THROW_IF(!std::isfinite(cx), InvalidArgument, "CameraModel.cx must be finite");
  CAROUSEL_THROW_IF(!std::isfinite(cy), InvalidArgument, "CameraModel.cy must be finite");
  const Distortion& d = distortion;
  CAROUSEL_THROW_IF(!(std::isfinite(d.k1) && std::isfinite(d.k2) && std::isfinite(d.p1) &&
                      std::isfinite(d.p2) && std::isfinite(d.k3)),
                    InvalidArgument, "CameraModel.distortion has a non-finite coefficient");
  CAROUSEL_THROW_IF(!cam_from_world.IsValid(), InvalidArgument,
                    "CameraModel.cam_from_world is not a rigid transform (rotation not "
                    "orthonormal with determinant +1, or not finite)");
}

std::optional<Eigen::Vector2d> CameraModel::Project(const Eigen::Vector3d& point_world) const {
  const Eigen::Vector3d point_cam = cam_from_world * point_world;
  if (!(point_cam.z() > 0.0)) return std::nullopt;
  return ProjectFromCam(point_cam);
}

std::optional<Eigen::Vector2d> CameraModel::NormalizedFromPixel(
    const Eigen::Vector2d& pixel) const {
  return distortion.Remove({(pixel.x() - cx) / fx, (pixel.y() - cy) / fy});
}

std::optional<Eigen::Vector3d> CameraModel::Unproject(const Eigen::Vector2d& pixel,
                                                      double depth) const {
  const std::optional<Eigen::Vector2d> xy = NormalizedFromPixel(pixel);
  if (!xy) return std::nullopt;
  const Eigen::Vector3d point_cam(xy->x() * depth, xy->y() * depth, depth);
  return cam_from_world.Inverse() * point_cam;
}

std::optional<Ray> CameraModel::RayThrough(const Eigen::Vector2d& pixel) const {
  const std::optional<Eigen::Vector2d> xy = NormalizedFromPixel(pixel);
  if (!xy) return std::nullopt;
  const Eigen::Vector3d direction_cam(xy->x(), xy->y(), 1.0);
  return Ray{Centre(), (cam_from_world.rotation.transpose() * direction_cam).normalized()};
}

Eigen::Vector3d CameraModel::Centre() const {
  return -(cam_from_world.rotation.transpose() * cam_from_world.translation);
}

Eigen::Vector3d CameraModel::ViewingDirection() const {
  return cam_from_world.rotation.row(2).transpose();
}

bool CameraModel::InImage(const Eigen::Vector2d& pixel, double margin) const {
  return pixel.x() >= -0.5 + margin && pixel.y() >= -0.5 + margin &&
         pixel.x() <= width - 0.5 - margin && pixel.y() <= height - 0.5 - margin;
}

Eigen::Matrix3d CameraModel::K() const {
  Eigen::Matrix3d k;
  k << fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0;
  return k;
}

CameraModel CameraModel::Scaled(double factor) const {
  CAROUSEL_THROW_IF(!(factor > 0.0 && std::isfinite(factor)), InvalidArgument,
                    "CameraModel::Scaled: factor must be > 0, got " << factor);
  CameraModel scaled = *this;
  scaled.width = static_cast<int>(std::lround(width * factor));
  scaled.height = static_cast<int>(std::lround(height * factor));
  // Pixel edges scale; centres sit half a pixel inside them.
  const double sx = static_cast<double>(scaled.width) / width;
  const double sy = static_cast<double>(scaled.height) / height;
  scaled.fx = fx * sx;
  scaled.fy = fy * sy;
  scaled.cx = (cx + 0.5) * sx - 0.5;
  scaled.cy = (cy + 0.5) * sy - 0.5;
  return scaled;
}

cv::Matx33d CameraModel::CvCameraMatrix() const {
  return {fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0};
}

cv::Vec<double, 5> CameraModel::CvDistCoeffs() const {
  return {distortion.k1, distortion.k2, distortion.p1, distortion.p2, distortion.k3};
}

void CameraModel::CvPose(cv::Vec3d* rvec, cv::Vec3d* tvec) const {
  cv::Matx33d rotation;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) rotation(r, c) = cam_from_world.rotation(r, c);
  }
  cv::Rodrigues(rotation, *rvec);
  *tvec = cv::Vec3d(cam_from_world.translation.x(), cam_from_world.translation.y(),
                    cam_from_world.translation.z());
}

}  // namespace carousel
