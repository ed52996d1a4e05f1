// The simulated rig's camera: a deterministic, multithreaded CPU renderer that turns a Scene
// (turntable frame) into the photo a real camera with the given CameraModel would take, plus
// the exact ground truth (silhouette mask and depth).
//
// Geometry: vertices are projected through CameraModel::Project (lens distortion included);
// triangles whose edges the lens bends by more than `max_edge_error_px` are subdivided, so
// straight 3D edges come out as the curves a real lens draws. Z-buffer with n x n samples per
// pixel: anti-aliased edges; each pixel is shaded once per covering triangle at the centroid
// of its covered samples, with perspective-correct texture coordinates and trilinear
// mip-mapped texture filtering. Lighting in linear RGB: ambient plus soft (wrapped) directional
// lights fixed in the studio (they do not turn with the table), Blinn-Phong highlights,
// see-through materials (the backdrop behind them, tinted, with a Fresnel falloff). Backdrop: a
// vertical gradient in image space with the backdrop light's falloff, and the turntable plate
// (a disc at z = 0, not part of the mask); the key light's soft cast shadow on the plate and on
// the sweep (a wall and a floor in the studio), the object's contact shadow on the plate; lens
// vignetting over the whole photo. The backlit shot (a mask shot) lights the backdrop and the
// plate from behind instead.
// Determinism: the same inputs give byte-identical images regardless of thread count; noise
// comes from a hash of (seed, pixel, channel).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/sim/scene.h"

namespace carousel::sim {

struct DirectionalLight {
  Eigen::Vector3d direction_studio{0.0, 0.0, 1.0};  // towards the light, studio frame (= table
                                                    // frame at angle 0), need not be unit
  double intensity = 1.0;                           // >= 0, linear
  double wrap = 0.5;  // softness 0..1: 0 = hard Lambert, 1 = light wraps fully around
};

struct RenderOptions {
  // Samples per pixel along each axis (1..4): n x n samples anti-alias edges.
  int samples_per_axis = 2;
  // Shade with lights (false: albedo only, "unlit").
  bool lit = true;
  // Exposure: linear gain on the shaded object and plate (a camera's ISO x shutter / f-number^2
  // relative to its reference), > 0. The backdrop is lit separately and not scaled.
  double exposure = 1.0;
  // Ambient light, linear, >= 0.
  double ambient = 0.45;
  // Studio lights; default: a key light above-front-left and a fill from the right.
  std::vector<DirectionalLight> lights = {{{-0.5, -1.0, 1.2}, 0.75, 0.5},
                                          {{1.0, -0.4, 0.4}, 0.25, 0.8}};
  // Backdrop colours (sRGB, 0..1, RGB order) at the top and bottom of the image.
  Eigen::Vector3d backdrop_top{0.96, 0.96, 0.96};
  Eigen::Vector3d backdrop_bottom{0.86, 0.86, 0.86};
  // Turntable plate: a disc of this radius (metres) at z = 0; 0 = no plate.
  double plate_radius_m = 0.2;
  Eigen::Vector3d plate_color{0.55, 0.55, 0.57};  // sRGB, RGB order
  // Contact shadow on the plate (the object's base occluding its light): the plate's colour
  // falls by this fraction at the object's footprint, fading as exp(-distance / radius); the
  // footprint is what of the object lies within the radius of the table. 0 = none.
  double contact_shadow = 0.0;
  double contact_shadow_radius_m = 0.015;
  // The key light's cast shadow (lights[0], soft: the light spans key_light_size_deg, so the
  // penumbra widens with the distance from the object) on the plate and on the sweep: the
  // fraction of the key light a full shadow takes away, 0..1 (0 = none).
  double cast_shadow = 0.0;
  double key_light_size_deg = 12.0;  // (0, 90)
  // The sweep the backdrop colours belong to, in the studio frame, for the cast shadow: a wall
  // at y = sweep_distance_m (behind the table as the cameras see it) on a floor at
  // z = sweep_floor_m (the plate stands above it). Its colours stay the backdrop gradient.
  double sweep_distance_m = 0.8;  // > 0
  double sweep_floor_m = -0.08;   // <= 0
  // The backdrop light's falloff: the fraction darker in the frame's corners than at its
  // centre (a light aimed at the middle of the sweep; quadratic), 0..0.9.
  double backdrop_falloff = 0.0;
  // Lens vignetting: the fraction of light lost in the frame's corners (the cos^4 law's
  // profile from the principal point), 0..0.9; everything in the photo darkens with it.
  double vignetting = 0.0;
  // The backlit shot (a mask shot, the backlight on): the backdrop panel and the plate (a
  // light table) glow at `backlight` (linear, falling off like the backdrop), the front lights
  // dimmed to `backlit_front` of their power. The product shows dark against the lit panel,
  // its outline faintly lit by the light wrapping round it, see-through parts bright.
  bool backlit = false;
  double backlight = 0.8;       // (0, 1]
  double backlit_front = 0.08;  // 0..1
  // Gaussian sensor noise, standard deviation in 8-bit levels (0 = none).
  double noise_sigma = 0.0;
  // Seed of the noise.
  std::uint64_t seed = 0;
  // Largest distance, in pixels, between a projected 3D edge and its straight-line image
  // before the triangle is subdivided (lens distortion curves edges).
  double max_edge_error_px = 0.02;
  // Worker threads; 0 = one per hardware thread.
  int threads = 0;
  // Near plane, metres: triangles with a vertex closer to the camera are skipped.
  double near_m = 0.01;

  void Validate() const;
};

struct RenderResult {
  cv::Mat image;  // CV_8UC3, BGR
  cv::Mat mask;   // CV_8UC1, 255 where the object covers at least half of the pixel's samples
  cv::Mat depth;  // CV_32FC1, camera-frame z of the object in metres, 0 where none
  std::size_t triangles_rasterized = 0;  // after subdivision, object and plate
};

// Renders `scene` (turntable frame) through `camera` (cam_from_world already includes the
// table angle) with the studio lights turned by -table_angle_rad relative to the scene.
// \throw InvalidArgument for invalid camera, scene or options.
RenderResult Render(const Scene& scene, const CameraModel& camera, double table_angle_rad,
                    const RenderOptions& options);

}  // namespace carousel::sim
