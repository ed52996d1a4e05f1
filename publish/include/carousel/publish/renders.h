// Renders of a textured model from an orbit around it, on a plain backdrop: the viewer page's
// poster (the hero shot). Turntable frame (DESIGN.md): azimuth about +Z from +X, elevation
// above the plate's plane.
#pragma once

#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/texture/textured_model.h"

namespace carousel::publish {

struct OrbitShot {
  double azimuth_deg = 30.0;
  double elevation_deg = 20.0;
  double fov_deg = 30.0;  // vertical
  int width = 1024, height = 1024;
  double fill = 0.85;  // the bounding sphere's diameter over the shorter image side, (0, 1]
  // How the model is framed: kSphere, its bounding sphere's diameter is `fill` of the shorter
  // side (any direction, loose for a long product); kCylinder, its bounding cylinder about
  // the vertical axis through its box's centre fits `fill` of the image at any azimuth, so the
  // frames of a spin keep one scale; kFit, the model's own outline from this direction fills
  // `fill` of the image along its tighter axis (the hero shot).
  enum class Framing { kSphere, kCylinder, kFit };
  Framing framing = Framing::kSphere;
};

// A distortion-free pinhole camera at `eye` looking at `target` (turntable frame, metres), no
// roll (+Z up in the image), vertical field of view `fov_deg`, principal point at the image
// centre: what a web viewer's perspective camera is. \throw InvalidArgument.
CameraModel PinholeLookingAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                             double fov_deg, int width, int height);

// A distortion-free pinhole camera looking at the centre of `model`'s bounding box, framed so
// that its bounding sphere fills `shot.fill` of the image. \throw InvalidArgument.
CameraModel OrbitCamera(const texture::TexturedModel& model, const OrbitShot& shot);

// The model rendered unlit (texture/held_out.h) on a white backdrop. \throw InvalidArgument.
cv::Mat RenderShot(const texture::TexturedModel& model, const OrbitShot& shot);

}  // namespace carousel::publish
