#include "carousel/gui/model_view.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/json.h"
#include "carousel/studio/session.h"
#include "carousel/texture/held_out.h"

namespace carousel::gui {
namespace {

constexpr float kPi = 3.14159265358979f;

float Radians(float deg) { return deg * kPi / 180.0f; }

int Find(std::vector<int>& parent, int x) {
  while (parent[x] != x) {
    parent[x] = parent[parent[x]];
    x = parent[x];
  }
  return x;
}

// Distinct, saturated colours for neighbouring chart indices (golden-ratio hue steps).
Eigen::Vector3f ChartColour(int chart) {
  const float hue = std::fmod(static_cast<float>(chart) * 0.618034f, 1.0f) * 6.0f;
  const float x = 1.0f - std::fabs(std::fmod(hue, 2.0f) - 1.0f);
  Eigen::Vector3f rgb;
  switch (static_cast<int>(hue)) {
    case 0:
      rgb = {1, x, 0};
      break;
    case 1:
      rgb = {x, 1, 0};
      break;
    case 2:
      rgb = {0, 1, x};
      break;
    case 3:
      rgb = {0, x, 1};
      break;
    case 4:
      rgb = {x, 0, 1};
      break;
    default:
      rgb = {1, 0, x};
      break;
  }
  return 0.25f * Eigen::Vector3f::Ones() + 0.7f * rgb;
}

// Blue (t = 0) through green to red (t = 1).
Eigen::Vector3f HeatColour(double t) {
  const float s = static_cast<float>(std::clamp(t, 0.0, 1.0));
  if (s < 0.5f) return {0.0f, 2.0f * s, 1.0f - 2.0f * s};
  return {2.0f * s - 1.0f, 2.0f - 2.0f * s, 0.0f};
}

double Percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  const auto k = static_cast<std::size_t>(std::lround(p * static_cast<double>(values.size() - 1)));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

void Push(std::vector<float>* out, const Eigen::Vector3f& v) {
  out->insert(out->end(), {v.x(), v.y(), v.z()});
}

}  // namespace

const char* ModelModeName(ModelMode mode) {
  switch (mode) {
    case ModelMode::kTextured:
      return "textured";
    case ModelMode::kWireframe:
      return "wireframe";
    case ModelMode::kCharts:
      return "charts";
    case ModelMode::kDensity:
      return "texel density";
  }
  return "?";
}

std::vector<int> TriangleCharts(const texture::TexturedModel& model, int* chart_count) {
  std::vector<int> parent(model.positions.size());
  std::iota(parent.begin(), parent.end(), 0);
  for (const Eigen::Vector3i& t : model.triangles) {
    const int a = Find(parent, t[0]);
    parent[Find(parent, t[1])] = a;
    parent[Find(parent, t[2])] = a;
  }
  std::vector<int> label(parent.size(), -1);
  std::vector<int> charts(model.triangles.size());
  int count = 0;
  for (std::size_t i = 0; i < model.triangles.size(); ++i) {
    const int root = Find(parent, model.triangles[i][0]);
    if (label[root] < 0) label[root] = count++;
    charts[i] = label[root];
  }
  if (chart_count != nullptr) *chart_count = count;
  return charts;
}

ModelMesh PrepareModelMesh(const texture::TexturedModel& model) {
  model.Validate();
  ModelMesh out;
  const std::size_t n = model.triangles.size();
  out.triangles = static_cast<int>(n);
  const std::vector<int> charts = TriangleCharts(model, &out.charts);
  const double texels = static_cast<double>(model.texture.cols) * model.texture.rows;

  // Texel density per face: sqrt(texels covered / surface area in mm^2).
  std::vector<double> density(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3i& t = model.triangles[i];
    const Eigen::Vector3d e1 = model.positions[t[1]] - model.positions[t[0]];
    const Eigen::Vector3d e2 = model.positions[t[2]] - model.positions[t[0]];
    const double area_mm2 = 0.5 * e1.cross(e2).norm() * 1e6;
    const Eigen::Vector2f u1 = model.uvs[t[1]] - model.uvs[t[0]];
    const Eigen::Vector2f u2 = model.uvs[t[2]] - model.uvs[t[0]];
    const double uv_area = 0.5 * std::fabs(static_cast<double>(u1.x() * u2.y() - u1.y() * u2.x()));
    density[i] = area_mm2 > 0.0 ? std::sqrt(uv_area * texels / area_mm2) : 0.0;
  }
  out.density_p10 = Percentile(density, 0.1);
  out.density_median = Percentile(density, 0.5);
  out.density_p90 = Percentile(density, 0.9);
  const double lo = out.density_p10, hi = std::max(out.density_p90, lo + 1e-9);

  Eigen::Vector3d min = Eigen::Vector3d::Constant(1e30), max = -min;
  for (const Eigen::Vector3d& p : model.positions) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
  const Eigen::Vector3d center = 0.5 * (min + max);
  out.center = center.cast<float>();
  double radius = 0.0;
  for (const Eigen::Vector3d& p : model.positions) radius = std::max(radius, (p - center).norm());
  out.radius = static_cast<float>(radius);

  for (auto* v : {&out.positions, &out.normals, &out.chart_rgb, &out.density_rgb})
    v->reserve(9 * n);
  out.uvs.reserve(6 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3i& t = model.triangles[i];
    const Eigen::Vector3d e1 = model.positions[t[1]] - model.positions[t[0]];
    const Eigen::Vector3d e2 = model.positions[t[2]] - model.positions[t[0]];
    const Eigen::Vector3f normal = e1.cross(e2).normalized().cast<float>();
    const Eigen::Vector3f chart = ChartColour(charts[i]);
    const Eigen::Vector3f heat = HeatColour((density[i] - lo) / (hi - lo));
    for (int c = 0; c < 3; ++c) {
      Push(&out.positions, model.positions[t[c]].cast<float>());
      Push(&out.normals, normal.allFinite() ? normal : Eigen::Vector3f::UnitZ());
      out.uvs.insert(out.uvs.end(), {model.uvs[t[c]].x(), model.uvs[t[c]].y()});
      Push(&out.chart_rgb, chart);
      Push(&out.density_rgb, heat);
    }
  }
  cv::cvtColor(model.texture, out.texture_rgba, cv::COLOR_BGR2RGBA);
  cv::Mat level = out.texture_rgba;
  while (level.cols > 1 || level.rows > 1) {
    cv::Mat next;
    cv::resize(level, next, cv::Size(std::max(1, level.cols / 2), std::max(1, level.rows / 2)), 0,
               0, cv::INTER_AREA);
    out.texture_mips.push_back(next);
    level = next;
  }
  return out;
}

ModelMesh LoadSessionModel(const std::filesystem::path& session) {
  return PrepareModelMesh(texture::ReadTexturedModel(session / "model" / "model.glb"));
}

namespace {

nlohmann::json ReadReport(const std::filesystem::path& session) {
  const std::filesystem::path file = session / "model" / "report.json";
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) return nlohmann::json::object();
  return ParseJsonFile(file);
}

}  // namespace

std::vector<int> HeldOutViews(const std::filesystem::path& session) {
  const std::filesystem::path file = session / "model" / "report.json";
  const nlohmann::json report = ReadReport(session);
  std::vector<int> views;
  try {
    if (report.contains("held_out"))
      for (const auto& v : report.at("held_out").at("views")) views.push_back(v.at("view"));
  } catch (const nlohmann::json::exception& e) {
    throw FormatError(file, std::string("held_out: ") + e.what());
  }
  return views;
}

HeldOutComparison CompareHeldOutView(const std::filesystem::path& session, int view, int max_side) {
  const studio::Session manifest = studio::ReadSession(session);
  CAROUSEL_THROW_IF(view < 0 || view >= static_cast<int>(manifest.views.size()), InvalidArgument,
                    "view " << view << " is not one of the session's " << manifest.views.size());
  const studio::SessionView& sv = manifest.views[static_cast<std::size_t>(view)];
  HeldOutComparison out;
  out.view = view;
  out.photo = sv.image;
  const nlohmann::json report = ReadReport(session);
  if (report.contains("held_out")) {
    for (const auto& v : report["held_out"]["views"]) {
      if (v.value("view", -1) != view) continue;
      out.psnr_db = v.value("psnr_db", 0.0);
      out.ssim = v.value("ssim", 0.0);
    }
  }
  // In the object frame (a registered later pass's own table frame is not).
  const std::vector<View> views = studio::SessionViews(session, manifest);
  CAROUSEL_THROW_IF(view >= static_cast<int>(views.size()), InvalidArgument,
                    "view " << view << " belongs to a pass the model was not made from");
  const CameraModel camera = views[static_cast<std::size_t>(view)].camera();
  const double scale =
      std::min(1.0, static_cast<double>(max_side) / std::max(camera.width, camera.height));
  const CameraModel scaled = scale < 1.0 ? camera.Scaled(scale) : camera;
  const texture::TexturedModel model = texture::ReadTexturedModel(session / "model" / "model.glb");
  const texture::ModelRendering rendering = texture::RenderTexturedModel(model, scaled);
  cv::Mat photo = ReadImage(session / sv.image);
  if (photo.size() != rendering.image.size())
    cv::resize(photo, photo, rendering.image.size(), 0, 0, cv::INTER_AREA);
  cv::cvtColor(photo, out.photo_rgba, cv::COLOR_BGR2RGBA);
  cv::cvtColor(rendering.image, out.render_rgba, cv::COLOR_BGR2RGBA);
  return out;
}

void OrbitCamera::Frame(const Eigen::Vector3f& center, float radius) {
  target = center;
  const float half = Radians(fov_y_deg) * 0.5f;
  distance = std::max(radius, 1e-3f) / (0.8f * std::sin(half));
}

void OrbitCamera::Orbit(float dx_px, float dy_px) {
  yaw_deg = std::fmod(yaw_deg - 0.4f * dx_px, 360.0f);
  pitch_deg = std::clamp(pitch_deg + 0.4f * dy_px, -89.0f, 89.0f);
}

void OrbitCamera::Pan(float dx_px, float dy_px, float height_px) {
  const Eigen::Matrix4f view = ViewMatrix();
  const Eigen::Vector3f right = view.block<1, 3>(0, 0).transpose();
  const Eigen::Vector3f up = view.block<1, 3>(1, 0).transpose();
  // Metres per pixel at the target's depth.
  const float scale =
      2.0f * distance * std::tan(Radians(fov_y_deg) * 0.5f) / std::max(height_px, 1.0f);
  target += (-dx_px * right + dy_px * up) * scale;
}

void OrbitCamera::Zoom(float steps) {
  distance = std::clamp(distance * std::pow(0.9f, steps), 1e-3f, 1e3f);
}

Eigen::Vector3f OrbitCamera::Eye() const {
  const float yaw = Radians(yaw_deg), pitch = Radians(pitch_deg);
  return target + distance * Eigen::Vector3f(std::cos(pitch) * std::cos(yaw),
                                             std::cos(pitch) * std::sin(yaw), std::sin(pitch));
}

Eigen::Matrix4f OrbitCamera::ViewMatrix() const {
  const Eigen::Vector3f eye = Eye();
  const Eigen::Vector3f forward = (target - eye).normalized();
  Eigen::Vector3f right = forward.cross(Eigen::Vector3f::UnitZ());
  if (right.norm() < 1e-6f) right = Eigen::Vector3f::UnitX();
  right.normalize();
  const Eigen::Vector3f up = right.cross(forward);
  Eigen::Matrix4f m = Eigen::Matrix4f::Identity();
  m.block<1, 3>(0, 0) = right.transpose();
  m.block<1, 3>(1, 0) = up.transpose();
  m.block<1, 3>(2, 0) = -forward.transpose();
  m(0, 3) = -right.dot(eye);
  m(1, 3) = -up.dot(eye);
  m(2, 3) = forward.dot(eye);
  return m;
}

Eigen::Matrix4f OrbitCamera::ProjectionMatrix(float aspect, float near_m, float far_m) const {
  const float f = 1.0f / std::tan(Radians(fov_y_deg) * 0.5f);
  Eigen::Matrix4f p = Eigen::Matrix4f::Zero();
  p(0, 0) = f / aspect;
  p(1, 1) = f;
  p(2, 2) = (far_m + near_m) / (near_m - far_m);
  p(2, 3) = 2.0f * far_m * near_m / (near_m - far_m);
  p(3, 2) = -1.0f;
  return p;
}

}  // namespace carousel::gui
