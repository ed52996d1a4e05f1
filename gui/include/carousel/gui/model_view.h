// The model view's data and camera, without OpenGL: the textured model (model/model.glb, read
// by texture/'s reader: turntable frame, metres, +Z up) laid out as flat-shaded triangles with
// what each display mode colours them by, and the orbit camera the mouse drives.
//
// Modes: textured (as a viewer shows it, unlit), wireframe, charts (one colour per UV island:
// triangles sharing a vertex of the GLB, which splits vertices along seams) and texel density
// (texels per millimetre of surface, blue = the sparsest tenth, red = the densest).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "carousel/texture/textured_model.h"

namespace carousel::gui {

enum class ModelMode { kTextured = 0, kWireframe, kCharts, kDensity };
inline constexpr int kModelModes = 4;
const char* ModelModeName(ModelMode mode);

// Three corners per triangle (flat normals, per-face colours), float for the GPU.
struct ModelMesh {
  std::vector<float> positions;    // xyz per corner, metres
  std::vector<float> normals;      // xyz per corner, the face's
  std::vector<float> uvs;          // uv per corner, image convention (v down)
  std::vector<float> chart_rgb;    // rgb per corner, the face's chart colour
  std::vector<float> density_rgb;  // rgb per corner, the face's texel-density colour
  cv::Mat texture_rgba;            // CV_8UC4, rows top first (v = 0 is row 0)
  // Its mip levels 1, 2, ... down to 1 x 1 (area-averaged), made here rather than by the GPU
  // driver so that showing a model costs the window no frame time (Mesa's llvmpipe builds
  // mip-maps on the CPU, in the drawing thread).
  std::vector<cv::Mat> texture_mips;
  Eigen::Vector3f center{0, 0, 0};
  float radius = 0.0f;  // of the bounding sphere around center, metres
  int triangles = 0;
  int charts = 0;
  // Texels per millimetre of surface over the faces: 10th percentile, median, 90th.
  double density_p10 = 0.0, density_median = 0.0, density_p90 = 0.0;
};

// \throw InvalidArgument for a model that fails Validate().
ModelMesh PrepareModelMesh(const texture::TexturedModel& model);

// Reads <session>/model/model.glb and prepares it. \throw IoError/FormatError naming the file.
ModelMesh LoadSessionModel(const std::filesystem::path& session);

// A held-out view as the Model panel compares it: the photo beside the model rendered through
// the photo's camera (texture/'s renderer, as the report scores it), both at most `max_side`
// pixels on the longer side, and the scores the texture stage recorded.
struct HeldOutComparison {
  int view = -1;
  std::string photo;                 // the photo's file, relative to the session
  cv::Mat photo_rgba, render_rgba;   // CV_8UC4, the same size
  double psnr_db = 0.0, ssim = 0.0;  // from model/report.json
};
// The views model/report.json scored (none when it holds none or is missing).
// \throw FormatError naming report.json when it is malformed.
std::vector<int> HeldOutViews(const std::filesystem::path& session);
// \throw IoError/FormatError naming the file (session.json, report.json, the GLB, the photo),
// InvalidArgument for a view the session does not have.
HeldOutComparison CompareHeldOutView(const std::filesystem::path& session, int view,
                                     int max_side = 1024);

// Chart (UV island) of each triangle: triangles sharing a vertex index are one chart.
std::vector<int> TriangleCharts(const texture::TexturedModel& model, int* chart_count);

// Orbit camera around a target in the turntable frame (+Z up): yaw about Z, pitch above the
// horizon, distance; pan moves the target in the view plane.
struct OrbitCamera {
  Eigen::Vector3f target{0, 0, 0};
  float yaw_deg = 30.0f, pitch_deg = 20.0f;
  float distance = 1.0f;  // metres
  float fov_y_deg = 35.0f;

  // Frames a bounding sphere: the target at its centre, the sphere filling ~80 % of the height.
  void Frame(const Eigen::Vector3f& center, float radius);
  // Mouse drags in pixels of a view `height` pixels tall.
  void Orbit(float dx_px, float dy_px);
  void Pan(float dx_px, float dy_px, float height_px);
  // Wheel steps: > 0 moves closer.
  void Zoom(float steps);
  Eigen::Vector3f Eye() const;
  // OpenGL's column-major matrices (right-handed, camera looking down -Z).
  Eigen::Matrix4f ViewMatrix() const;
  Eigen::Matrix4f ProjectionMatrix(float aspect, float near_m, float far_m) const;
};

}  // namespace carousel::gui
