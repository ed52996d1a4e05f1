#include "carousel/sim/renderer.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <exception>
#include <limits>
#include <mutex>
#include <numbers>
#include <thread>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/mesh_primitives.h"
#include "carousel/core/parallel.h"

namespace carousel::sim {
namespace {

constexpr int kTileSize = 32;
constexpr int kMaxSubdivision = 12;
// Edges shorter than this on screen are never split, however much the lens bends them.
constexpr double kMinSplitLengthPx = 0.25;
// A backlit shot's plate (a light table) glows this fraction of the panel's level.
constexpr float kPlateGlow = 0.95f;

// ---- colour ---------------------------------------------------------------------------------

float SrgbToLinear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}
float LinearToSrgb(float c) {
  return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

struct ColourTables {
  std::array<float, 256> to_linear{};
  static constexpr int kEncodeSize = 4096;
  std::array<float, kEncodeSize + 1> to_srgb255{};  // linear [0,1] -> sRGB 0..255 (unrounded)
  ColourTables() {
    for (int i = 0; i < 256; ++i) to_linear[i] = SrgbToLinear(i / 255.0f);
    for (int i = 0; i <= kEncodeSize; ++i) {
      to_srgb255[i] = 255.0f * LinearToSrgb(static_cast<float>(i) / kEncodeSize);
    }
  }
  float Encode(float linear) const {
    if (!(linear > 0.0f)) return 0.0f;  // also NaN
    const float x = std::min(linear, 1.0f) * kEncodeSize;
    const int i = std::min(static_cast<int>(x), kEncodeSize - 1);
    const float f = x - i;
    return to_srgb255[i] + f * (to_srgb255[i + 1] - to_srgb255[i]);
  }
};

const ColourTables& Tables() {
  static const ColourTables tables;
  return tables;
}

// ---- deterministic noise -----------------------------------------------------------------

std::uint64_t Mix(std::uint64_t x) {  // splitmix64 finaliser
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// Approximately standard-normal: the sum of three 21-bit uniforms from one hash of
// (seed, index), centred and scaled to unit variance (variance of the sum = 3/12).
float HashNormal(std::uint64_t mixed_seed, std::uint64_t index) {
  const std::uint64_t h = Mix(mixed_seed + index);
  constexpr float kScale = 1.0f / 2097151.0f;
  const float sum = static_cast<float>(h & 0x1fffff) * kScale +
                    static_cast<float>((h >> 21) & 0x1fffff) * kScale +
                    static_cast<float>((h >> 42) & 0x1fffff) * kScale;
  return (sum - 1.5f) * 2.0f;
}

// ---- texture sampling -------------------------------------------------------------------

Eigen::Vector3f Bilinear(const cv::Mat& level, float u, float v) {
  // u, v in image convention [0,1) with repeat wrapping; texel centres at (i + 0.5) / size.
  const float x = u * level.cols - 0.5f;
  const float y = v * level.rows - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const float ax = x - fx, ay = y - fy;
  auto wrap = [](int i, int n) { return ((i % n) + n) % n; };
  const int x0 = wrap(static_cast<int>(fx), level.cols), x1 = wrap(x0 + 1, level.cols);
  const int y0 = wrap(static_cast<int>(fy), level.rows), y1 = wrap(y0 + 1, level.rows);
  const auto& lin = Tables().to_linear;
  auto texel = [&](int tx, int ty) {
    const cv::Vec3b& p = level.at<cv::Vec3b>(ty, tx);
    return Eigen::Vector3f(lin[p[2]], lin[p[1]], lin[p[0]]);  // RGB
  };
  return (1 - ay) * ((1 - ax) * texel(x0, y0) + ax * texel(x1, y0)) +
         ay * ((1 - ax) * texel(x0, y1) + ax * texel(x1, y1));
}

Eigen::Vector3f SampleTexture(const Texture& texture, float u, float v, float lod) {
  const auto& levels = texture.levels();
  const int last = static_cast<int>(levels.size()) - 1;
  lod = std::clamp(lod, 0.0f, static_cast<float>(last));
  const int l0 = static_cast<int>(lod);
  const float f = lod - l0;
  const Eigen::Vector3f a = Bilinear(levels[l0], u, v);
  if (f < 1e-3f || l0 == last) return a;
  return (1 - f) * a + f * Bilinear(levels[l0 + 1], u, v);
}

// ---- geometry ------------------------------------------------------------------------------

// A vertex on its way to the screen: camera-frame position and the attributes to interpolate.
struct ClipVertex {
  Eigen::Vector3d cam;     // camera frame
  Eigen::Vector2f uv;      // image convention
  Eigen::Vector3f normal;  // world frame
};

struct ScreenTriangle {
  double x[3], y[3];     // pixel coordinates (distorted)
  float inv_z[3];        // 1 / camera z
  float u_z[3], v_z[3];  // uv / z
  float n_z[3][3];       // normal / z
  float cam[3][3];       // camera-frame position (for the view direction of highlights)
  double area2;          // twice the signed screen area (> 0 after orientation)
  int material;          // index into the scene's materials, or -1 for the plate
  float lod;             // mip level
  bool object;           // counts for the mask and depth
  bool flip_normal;      // back face seen: shade the other side
};

class TriangleSetup {
 public:
  TriangleSetup(const CameraModel& camera, const RenderOptions& options,
                std::vector<ScreenTriangle>& out)
      : camera_(camera), options_(options), out_(out) {}

  void Add(const std::array<ClipVertex, 3>& v, int material, bool object, bool flip_normal,
           const Texture* texture, int depth = 0) {
    for (const ClipVertex& vertex : v) {
      if (!(vertex.cam.z() > options_.near_m)) return;
    }
    std::array<Eigen::Vector2d, 3> p;
    for (int k = 0; k < 3; ++k) {
      p[k] = camera_.ProjectFromCam(v[k].cam);
      if (!p[k].allFinite()) return;  // far outside the lens model's range
    }
    // Cull what lies wholly outside the image.
    const double min_x = std::min({p[0].x(), p[1].x(), p[2].x()});
    const double max_x = std::max({p[0].x(), p[1].x(), p[2].x()});
    const double min_y = std::min({p[0].y(), p[1].y(), p[2].y()});
    const double max_y = std::max({p[0].y(), p[1].y(), p[2].y()});
    if (max_x < -0.5 || max_y < -0.5 || min_x > camera_.width - 0.5 ||
        min_y > camera_.height - 0.5) {
      return;
    }
    if (depth < kMaxSubdivision && !camera_.distortion.IsZero()) {
      // Each edge decides from its own endpoints, so the two triangles sharing it agree and
      // no T-junction (a crack) appears between them.
      bool split[3];
      int splits = 0;
      for (int k = 0; k < 3; ++k)
        splits += (split[k] = EdgeNeedsSplit(v[k].cam, v[(k + 1) % 3].cam));
      auto add = [&](const ClipVertex& a, const ClipVertex& b, const ClipVertex& c) {
        Add({a, b, c}, material, object, flip_normal, texture, depth + 1);
      };
      if (splits == 3) {
        std::array<ClipVertex, 3> m;
        for (int k = 0; k < 3; ++k) m[k] = Midpoint(v[k], v[(k + 1) % 3]);
        add(v[0], m[0], m[2]);
        add(m[0], v[1], m[1]);
        add(m[2], m[1], v[2]);
        add(m[0], m[1], m[2]);
        return;
      }
      if (splits == 1) {
        const int k = split[0] ? 0 : split[1] ? 1 : 2;
        const ClipVertex m = Midpoint(v[k], v[(k + 1) % 3]);
        add(v[k], m, v[(k + 2) % 3]);
        add(m, v[(k + 1) % 3], v[(k + 2) % 3]);
        return;
      }
      if (splits == 2) {
        const int u = !split[0] ? 0 : !split[1] ? 1 : 2;  // the edge kept whole
        const ClipVertex& a = v[u];
        const ClipVertex& b = v[(u + 1) % 3];
        const ClipVertex& c = v[(u + 2) % 3];
        const ClipVertex bc = Midpoint(b, c), ca = Midpoint(c, a);
        add(c, ca, bc);
        add(a, b, bc);
        add(a, bc, ca);
        return;
      }
    }
    ScreenTriangle t{};
    double area2 = (p[1].x() - p[0].x()) * (p[2].y() - p[0].y()) -
                   (p[2].x() - p[0].x()) * (p[1].y() - p[0].y());
    if (!(std::abs(area2) > 1e-12)) return;
    std::array<int, 3> order = {0, 1, 2};
    if (area2 < 0) {
      std::swap(order[1], order[2]);
      area2 = -area2;
    }
    for (int k = 0; k < 3; ++k) {
      const ClipVertex& s = v[order[k]];
      const float inv_z = static_cast<float>(1.0 / s.cam.z());
      t.x[k] = p[order[k]].x();
      t.y[k] = p[order[k]].y();
      t.inv_z[k] = inv_z;
      t.u_z[k] = s.uv.x() * inv_z;
      t.v_z[k] = s.uv.y() * inv_z;
      for (int c = 0; c < 3; ++c) t.n_z[k][c] = s.normal[c] * inv_z;
      for (int c = 0; c < 3; ++c) t.cam[k][c] = static_cast<float>(s.cam[c]);
    }
    t.area2 = area2;
    t.material = material;
    t.object = object;
    t.flip_normal = flip_normal;
    t.lod = 0.0f;
    if (texture != nullptr) {
      const Eigen::Vector2f e1 = v[1].uv - v[0].uv, e2 = v[2].uv - v[0].uv;
      const double uv_area2 =
          std::abs(static_cast<double>(e1.x()) * e2.y() - static_cast<double>(e2.x()) * e1.y());
      const double texels = uv_area2 * texture->width() * texture->height();
      if (texels > 0) t.lod = static_cast<float>(0.5 * std::log2(texels / area2));
    }
    out_.push_back(t);
  }

 private:
  static ClipVertex Midpoint(const ClipVertex& a, const ClipVertex& b) {
    return {0.5 * (a.cam + b.cam), 0.5f * (a.uv + b.uv), (0.5f * (a.normal + b.normal))};
  }

  // True when the lens moves the edge's 3D midpoint further than allowed from where the
  // rasteriser puts it (on the straight screen edge, at the perspective-correct parameter): the
  // bend across the edge and the stretch along it (a radial edge is straight but stretched,
  // which would shift the texture along it).
  // Computed in a canonical endpoint order: both triangles sharing the edge get the same answer.
  bool EdgeNeedsSplit(const Eigen::Vector3d& a_in, const Eigen::Vector3d& b_in) const {
    const bool swap =
        std::lexicographical_compare(b_in.data(), b_in.data() + 3, a_in.data(), a_in.data() + 3);
    const Eigen::Vector3d& a = swap ? b_in : a_in;
    const Eigen::Vector3d& b = swap ? a_in : b_in;
    const Eigen::Vector2d pa = camera_.ProjectFromCam(a), pb = camera_.ProjectFromCam(b);
    const Eigen::Vector2d mid = camera_.ProjectFromCam(0.5 * (a + b));
    const Eigen::Vector2d ab = pb - pa;
    const double length = ab.norm();
    if (!(length > kMinSplitLengthPx) || !mid.allFinite()) return false;
    // Perspective-correct interpolation reaches the 3D midpoint at t = z_b / (z_a + z_b).
    const double t = b.z() / (a.z() + b.z());
    const double distance = (mid - (pa + t * ab)).norm();
    return distance > options_.max_edge_error_px;
  }

  const CameraModel& camera_;
  const RenderOptions& options_;
  std::vector<ScreenTriangle>& out_;
};

// ---- rasterisation -------------------------------------------------------------------------

// Is the edge (a -> b) a top or left edge? Triangles are ordered so that
// cross(v1 - v0, v2 - v0) > 0, which in image coordinates (y down) runs clockwise on screen:
// the top edge runs to the right, left edges run upwards. Samples exactly on such edges
// belong to the triangle, so shared edges are covered exactly once.
bool TopLeft(double ax, double ay, double bx, double by) {
  const double dx = bx - ax, dy = by - ay;
  return (dy == 0 && dx > 0) || dy < 0;
}

struct Sample {
  float inv_z;
  int triangle;
};

// The contact shadow's source: per cell of a grid on the table (z = 0, turntable frame), the
// distance to the footprint of the object's base, metres.
struct ContactShadowMap {
  cv::Mat distance;     // CV_32FC1
  double origin = 0.0;  // x and y of the grid's first cell's corner
  double cell = 1.0;    // metres
  float At(double x, double y) const {
    const int i = static_cast<int>(std::floor((x - origin) / cell));
    const int j = static_cast<int>(std::floor((y - origin) / cell));
    if (i < 0 || j < 0 || i >= distance.cols || j >= distance.rows)
      return std::numeric_limits<float>::infinity();
    return distance.at<float>(j, i);
  }
};

// The footprint of what of the object lies within `height` of the table, grown into a distance
// map over the plate.
ContactShadowMap MakeContactShadowMap(const Scene& scene, double plate_radius, double height) {
  constexpr int kCells = 512;
  ContactShadowMap map;
  map.origin = -plate_radius;
  map.cell = 2.0 * plate_radius / kCells;
  cv::Mat free(kCells, kCells, CV_8UC1, cv::Scalar(255));
  for (const Eigen::Vector3i& tri : scene.triangles) {
    std::array<cv::Point, 3> corners;
    double lowest = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& p = scene.positions[tri[k]];
      lowest = std::min(lowest, p.z());
      corners[k] = cv::Point(static_cast<int>(std::floor((p.x() - map.origin) / map.cell)),
                             static_cast<int>(std::floor((p.y() - map.origin) / map.cell)));
    }
    if (lowest < height) cv::fillConvexPoly(free, corners.data(), 3, cv::Scalar(0));
  }
  cv::distanceTransform(free, map.distance, cv::DIST_L2, cv::DIST_MASK_5);
  map.distance *= map.cell;
  return map;
}

// The key light's cast shadow: the object seen from the light (an orthographic map across the
// light's direction) as a signed distance to its footprint, with the height (towards the light)
// of the occluder at or nearest each cell. A receiver behind an occluder is shadowed with a
// penumbra as wide as the light's apparent size makes it at that distance.
struct CastShadowMap {
  Eigen::Vector3f towards_light{0.0f, 0.0f, 1.0f};
  Eigen::Vector3f axis_u{1.0f, 0.0f, 0.0f}, axis_v{0.0f, 1.0f, 0.0f};
  float origin_u = 0.0f, origin_v = 0.0f, cell = 1.0f;
  float tan_radius = 0.1f;
  cv::Mat signed_distance;  // CV_32FC1, metres: > 0 outside the footprint, < 0 inside
  cv::Mat occluder_height;  // CV_32FC1, metres along towards_light

  // The fraction of the key light that `point` (world frame) does not see, 0..1.
  float Occlusion(const Eigen::Vector3f& point) const {
    const float u = (point.dot(axis_u) - origin_u) / cell;
    const float v = (point.dot(axis_v) - origin_v) / cell;
    if (!(u >= 0.0f && v >= 0.0f && u < signed_distance.cols && v < signed_distance.rows))
      return 0.0f;
    const int i = static_cast<int>(u), j = static_cast<int>(v);
    constexpr float kBias = 0.002f;  // metres: a receiver touching its occluder is lit
    const float gap = occluder_height.at<float>(j, i) - point.dot(towards_light);
    if (!(gap > kBias)) return 0.0f;
    const float half_width = std::max(cell, gap * tan_radius);
    const float t = std::clamp((signed_distance.at<float>(j, i) + half_width) / (2.0f * half_width),
                               0.0f, 1.0f);
    return 1.0f - t * t * (3.0f - 2.0f * t);
  }
};

CastShadowMap MakeCastShadowMap(const Scene& scene, const Eigen::Vector3f& towards_light,
                                double light_size_deg) {
  constexpr int kCells = 768;
  CastShadowMap map;
  map.towards_light = towards_light.normalized();
  const Eigen::Vector3f d = map.towards_light;
  const Eigen::Vector3f helper =
      std::abs(d.z()) < 0.9f ? Eigen::Vector3f::UnitZ() : Eigen::Vector3f::UnitX();
  map.axis_u = d.cross(helper).normalized();
  map.axis_v = d.cross(map.axis_u);
  map.tan_radius = static_cast<float>(std::tan(0.5 * light_size_deg * std::numbers::pi / 180.0));
  std::vector<Eigen::Vector3f> projected(scene.positions.size());
  Eigen::Vector2f lo = Eigen::Vector2f::Constant(std::numeric_limits<float>::infinity());
  Eigen::Vector2f hi = -lo;
  for (std::size_t i = 0; i < scene.positions.size(); ++i) {
    const Eigen::Vector3f p = scene.positions[i].cast<float>();
    projected[i] = {p.dot(map.axis_u), p.dot(map.axis_v), p.dot(d)};
    lo = lo.cwiseMin(projected[i].head<2>());
    hi = hi.cwiseMax(projected[i].head<2>());
  }
  const float extent = std::max(hi.x() - lo.x(), hi.y() - lo.y());
  const float margin = 0.5f * extent + 0.05f;
  map.cell = (extent + 2.0f * margin) / kCells;
  map.origin_u = 0.5f * (lo.x() + hi.x()) - 0.5f * kCells * map.cell;
  map.origin_v = 0.5f * (lo.y() + hi.y()) - 0.5f * kCells * map.cell;
  cv::Mat outside(kCells, kCells, CV_8UC1, cv::Scalar(255));
  cv::Mat height(kCells, kCells, CV_32FC1, cv::Scalar(-std::numeric_limits<float>::infinity()));
  for (const Eigen::Vector3i& tri : scene.triangles) {
    Eigen::Vector3f q[3];
    for (int k = 0; k < 3; ++k) {
      q[k] = projected[tri[k]];
      q[k].x() = (q[k].x() - map.origin_u) / map.cell;
      q[k].y() = (q[k].y() - map.origin_v) / map.cell;
    }
    const float area = (q[1].x() - q[0].x()) * (q[2].y() - q[0].y()) -
                       (q[2].x() - q[0].x()) * (q[1].y() - q[0].y());
    const int x0 =
        std::max(0, static_cast<int>(std::floor(std::min({q[0].x(), q[1].x(), q[2].x()}))));
    const int x1 = std::min(kCells - 1, static_cast<int>(std::max({q[0].x(), q[1].x(), q[2].x()})));
    const int y0 =
        std::max(0, static_cast<int>(std::floor(std::min({q[0].y(), q[1].y(), q[2].y()}))));
    const int y1 = std::min(kCells - 1, static_cast<int>(std::max({q[0].y(), q[1].y(), q[2].y()})));
    bool covered = false;
    if (std::abs(area) > 1e-12f) {
      for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
          const float px = x + 0.5f, py = y + 0.5f;
          float b[3];
          for (int k = 0; k < 3; ++k) {
            const Eigen::Vector3f& a = q[(k + 1) % 3];
            const Eigen::Vector3f& c = q[(k + 2) % 3];
            b[k] = ((c.x() - a.x()) * (py - a.y()) - (c.y() - a.y()) * (px - a.x())) / area;
          }
          if (b[0] < 0.0f || b[1] < 0.0f || b[2] < 0.0f) continue;
          covered = true;
          outside.at<std::uint8_t>(y, x) = 0;
          float& h = height.at<float>(y, x);
          h = std::max(h, b[0] * q[0].z() + b[1] * q[1].z() + b[2] * q[2].z());
        }
      }
    }
    if (!covered) {
      // Smaller than a cell: its centroid's cell.
      const Eigen::Vector3f c = (q[0] + q[1] + q[2]) / 3.0f;
      const int x = static_cast<int>(c.x()), y = static_cast<int>(c.y());
      if (x >= 0 && y >= 0 && x < kCells && y < kCells) {
        outside.at<std::uint8_t>(y, x) = 0;
        height.at<float>(y, x) =
            std::max(height.at<float>(y, x), std::max({q[0].z(), q[1].z(), q[2].z()}));
      }
    }
  }
  // Outside: the distance to, and the height of, the nearest footprint cell.
  cv::Mat distance_out, labels;
  cv::distanceTransform(outside, distance_out, labels, cv::DIST_L2, cv::DIST_MASK_5,
                        cv::DIST_LABEL_PIXEL);
  std::vector<float> height_of_label(1, -std::numeric_limits<float>::infinity());
  for (int y = 0; y < kCells; ++y) {
    for (int x = 0; x < kCells; ++x) {
      if (outside.at<std::uint8_t>(y, x)) continue;
      const auto label = static_cast<std::size_t>(labels.at<int>(y, x));
      if (label >= height_of_label.size())
        height_of_label.resize(label + 1, -std::numeric_limits<float>::infinity());
      height_of_label[label] = height.at<float>(y, x);
    }
  }
  cv::Mat distance_in;
  cv::distanceTransform(~outside, distance_in, cv::DIST_L2, cv::DIST_MASK_5);
  map.signed_distance.create(kCells, kCells, CV_32FC1);
  map.occluder_height.create(kCells, kCells, CV_32FC1);
  for (int y = 0; y < kCells; ++y) {
    for (int x = 0; x < kCells; ++x) {
      const bool out = outside.at<std::uint8_t>(y, x) != 0;
      map.signed_distance.at<float>(y, x) =
          map.cell * (out ? distance_out.at<float>(y, x) : 0.5f - distance_in.at<float>(y, x));
      const auto label = static_cast<std::size_t>(labels.at<int>(y, x));
      map.occluder_height.at<float>(y, x) =
          out ? (label < height_of_label.size() ? height_of_label[label]
                                                : -std::numeric_limits<float>::infinity())
              : height.at<float>(y, x);
    }
  }
  return map;
}

class Rasteriser {
 public:
  Rasteriser(const Scene& scene, const CameraModel& camera, double table_angle_rad,
             const RenderOptions& options, const std::vector<ScreenTriangle>& triangles,
             const std::vector<std::vector<std::uint32_t>>& bins, int tiles_x,
             const std::vector<Eigen::Vector3f>& lights_world, RenderResult& result)
      : scene_(scene),
        camera_(camera),
        options_(options),
        triangles_(triangles),
        bins_(bins),
        tiles_x_(tiles_x),
        lights_world_(lights_world),
        result_(result),
        n_(options.samples_per_axis),
        samples_(n_ * n_),
        world_from_cam_(camera.cam_from_world.rotation.transpose().cast<float>()) {
    for (int j = 0; j < n_; ++j) {
      for (int i = 0; i < n_; ++i) {
        offsets_.emplace_back((i + 0.5) / n_ - 0.5, (j + 0.5) / n_ - 0.5);
      }
    }
    const auto& lin = Tables().to_linear;
    auto linear = [&](const Eigen::Vector3d& srgb) {
      Eigen::Vector3f out;
      for (int c = 0; c < 3; ++c) {
        out[c] = lin[static_cast<int>(std::lround(std::clamp(srgb[c], 0.0, 1.0) * 255))];
      }
      return out;
    };
    plate_ = linear(options.plate_color);
    cam_translation_ = camera.cam_from_world.translation.cast<float>();
    // The backdrop is a vertical gradient: one colour per image row (the lit panel, uniform,
    // in a backlit shot).
    const Eigen::Vector3f top =
        options.backlit ? Eigen::Vector3f::Constant(static_cast<float>(options.backlight))
                        : linear(options.backdrop_top);
    const Eigen::Vector3f bottom = options.backlit ? top : linear(options.backdrop_bottom);
    backdrop_rows_.resize(camera.height);
    for (int y = 0; y < camera.height; ++y) {
      const float fy = camera.height > 1 ? static_cast<float>(y) / (camera.height - 1) : 0.0f;
      backdrop_rows_[y] = (1 - fy) * top + fy * bottom;
    }
    mixed_seed_ = Mix(options.seed);
    // Vignetting: gain 1 / (1 + a rho^2)^2 (the cos^4 law) with rho = 1 at the corner farthest
    // from the principal point, a chosen so that the gain there is 1 - vignetting.
    const double corner_x = std::max(camera.cx, camera.width - 1 - camera.cx);
    const double corner_y = std::max(camera.cy, camera.height - 1 - camera.cy);
    inv_corner_sq_ =
        static_cast<float>(1.0 / std::max(1.0, corner_x * corner_x + corner_y * corner_y));
    vignette_a_ = static_cast<float>(1.0 / std::sqrt(1.0 - options.vignetting) - 1.0);
    // The studio frame of backdrop rays: studio = Rz(angle) world.
    studio_from_world_ = Rigid3d::RotationZ(table_angle_rad).rotation.cast<float>();
    camera_centre_studio_ = studio_from_world_ * camera.Centre().cast<float>();
  }

  void SetContactShadow(const ContactShadowMap* shadow) { shadow_ = shadow; }
  void SetCastShadow(const CastShadowMap* shadow) { cast_ = shadow; }

  // Renders one tile; `buffer` is the calling worker's scratch space.
  void RenderTile(int tile, std::vector<Sample>& buffer) {
    const int tx = tile % tiles_x_, ty = tile / tiles_x_;
    const int x0 = tx * kTileSize, y0 = ty * kTileSize;
    const int x1 = std::min(x0 + kTileSize, camera_.width);
    const int y1 = std::min(y0 + kTileSize, camera_.height);
    const int w = x1 - x0;
    if (bins_[tile].empty()) {
      FillBackdrop(x0, y0, x1, y1);
      return;
    }
    buffer.assign(static_cast<std::size_t>(w) * (y1 - y0) * samples_, Sample{0.0f, -1});
    for (std::uint32_t index : bins_[tile]) {
      RasteriseTriangle(index, x0, y0, x1, y1, w, buffer);
    }
    Resolve(x0, y0, x1, y1, w, buffer);
  }

 private:
  void RasteriseTriangle(std::uint32_t index, int x0, int y0, int x1, int y1, int w,
                         std::vector<Sample>& buffer) const {
    const ScreenTriangle& t = triangles_[index];
    // Clamp in double before converting: vertices can project far outside the image.
    auto clamp_to = [](double value, int lo, int hi) {
      return static_cast<int>(std::clamp(value, static_cast<double>(lo), static_cast<double>(hi)));
    };
    const int bx0 = clamp_to(std::floor(std::min({t.x[0], t.x[1], t.x[2]})), x0, x1);
    const int bx1 = clamp_to(std::ceil(std::max({t.x[0], t.x[1], t.x[2]})), x0 - 1, x1 - 1);
    const int by0 = clamp_to(std::floor(std::min({t.y[0], t.y[1], t.y[2]})), y0, y1);
    const int by1 = clamp_to(std::ceil(std::max({t.y[0], t.y[1], t.y[2]})), y0 - 1, y1 - 1);
    if (bx0 > bx1 || by0 > by1) return;
    // Edge k is opposite vertex k, from vertex a = k+1 to b = k+2:
    // E_k(p) = cross(b - a, p - a), positive inside; E_k / area2 is the screen-space
    // barycentric of vertex k. Evaluated from the edge's endpoints in a canonical order and
    // negated when needed, so two triangles sharing an edge get exactly opposite values and
    // the top-left rule gives every sample on it to exactly one of them.
    double ox[3], oy[3], dx[3], dy[3], sign[3];
    bool top_left[3];
    for (int k = 0; k < 3; ++k) {
      int a = (k + 1) % 3, b = (k + 2) % 3;
      top_left[k] = TopLeft(t.x[a], t.y[a], t.x[b], t.y[b]);
      sign[k] = 1.0;
      if (t.x[b] < t.x[a] || (t.x[b] == t.x[a] && t.y[b] < t.y[a])) {
        std::swap(a, b);
        sign[k] = -1.0;
      }
      ox[k] = t.x[a];
      oy[k] = t.y[a];
      dx[k] = t.x[b] - t.x[a];
      dy[k] = t.y[b] - t.y[a];
    }
    const double inv_area = 1.0 / t.area2;
    for (int y = by0; y <= by1; ++y) {
      for (int x = bx0; x <= bx1; ++x) {
        Sample* pixel = &buffer[(static_cast<std::size_t>(y - y0) * w + (x - x0)) * samples_];
        for (int s = 0; s < samples_; ++s) {
          const double px = x + offsets_[s].x(), py = y + offsets_[s].y();
          double e[3];
          bool inside = true;
          for (int k = 0; k < 3 && inside; ++k) {
            e[k] = sign[k] * (dx[k] * (py - oy[k]) - dy[k] * (px - ox[k]));
            inside = e[k] > 0 || (e[k] == 0 && top_left[k]);
          }
          if (!inside) continue;
          const float inv_z = static_cast<float>(
              (e[0] * t.inv_z[0] + e[1] * t.inv_z[1] + e[2] * t.inv_z[2]) * inv_area);
          if (inv_z > pixel[s].inv_z) pixel[s] = {inv_z, static_cast<int>(index)};
        }
      }
    }
  }

  // Perspective-correct barycentrics of triangle t at (px, py).
  std::array<float, 3> Barycentric(const ScreenTriangle& t, double px, double py) const {
    double e[3];
    for (int k = 0; k < 3; ++k) {
      const int a = (k + 1) % 3, b = (k + 2) % 3;
      e[k] = (t.x[b] - t.x[a]) * (py - t.y[a]) - (t.y[b] - t.y[a]) * (px - t.x[a]);
    }
    const double total = e[0] + e[1] + e[2];
    std::array<float, 3> b{};
    if (std::abs(total) < 1e-300) return {1.0f / 3, 1.0f / 3, 1.0f / 3};
    double w[3], sum = 0;
    for (int k = 0; k < 3; ++k) {
      w[k] = std::clamp(e[k] / total, 0.0, 1.0) * t.inv_z[k];
      sum += w[k];
    }
    for (int k = 0; k < 3; ++k) b[k] = static_cast<float>(w[k] / sum);
    return b;
  }

  Eigen::Vector3f Shade(const ScreenTriangle& t, double px, double py, float* depth) const {
    const std::array<float, 3> b = Barycentric(t, px, py);
    // b are perspective-correct: attributes linear in 3D (uv, normal, z) combine with them.
    float z_interpolated = 0, u = 0, v = 0;
    Eigen::Vector3f n = Eigen::Vector3f::Zero();
    Eigen::Vector3f position = Eigen::Vector3f::Zero();  // camera frame
    for (int k = 0; k < 3; ++k) {
      const float z = 1.0f / t.inv_z[k];
      u += b[k] * t.u_z[k] * z;
      v += b[k] * t.v_z[k] * z;
      for (int c = 0; c < 3; ++c) n[c] += b[k] * t.n_z[k][c] * z;
      for (int c = 0; c < 3; ++c) position[c] += b[k] * t.cam[k][c];
      z_interpolated += b[k] * z;
    }
    *depth = z_interpolated;
    Eigen::Vector3f albedo;
    float specular = 0.0f, shininess = 1.0f;
    if (t.material < 0) {
      albedo = plate_;
    } else {
      const Material& material = scene_.materials[t.material];
      albedo = material.base_color;
      specular = material.specular;
      shininess = material.shininess;
      if (material.texture >= 0) {
        albedo = albedo.cwiseProduct(SampleTexture(*scene_.textures[material.texture],
                                                   u - std::floor(u), v - std::floor(v), t.lod));
      }
    }
    const float exposure = static_cast<float>(options_.exposure);
    const int ix = std::clamp(static_cast<int>(std::lround(px)), 0, camera_.width - 1);
    const int iy = std::clamp(static_cast<int>(std::lround(py)), 0, camera_.height - 1);
    if (t.material < 0 && options_.backlit) {
      // The plate is a light table: it glows like the panel.
      return Eigen::Vector3f::Constant(static_cast<float>(options_.backlight) * kPlateGlow *
                                       BackdropFalloff(ix, iy));
    }
    const Eigen::Vector3f world = world_from_cam_ * (position - cam_translation_);
    if (t.material < 0 && shadow_ != nullptr) {
      // The object's base occludes the plate's light near it.
      const float d = shadow_->At(world.x(), world.y());
      albedo *= 1.0f - static_cast<float>(options_.contact_shadow) *
                           std::exp(-d / static_cast<float>(options_.contact_shadow_radius_m));
    }
    // The front lights: dimmed for a backlit shot.
    const float front = options_.backlit ? static_cast<float>(options_.backlit_front) : 1.0f;
    if (!options_.lit) return albedo * (exposure * front);
    const float length = n.norm();
    n = length > 0 ? Eigen::Vector3f(n / length) : Eigen::Vector3f::UnitZ();
    if (t.flip_normal) n = -n;
    const float distance = position.norm();
    const Eigen::Vector3f to_eye = distance > 0
                                       ? Eigen::Vector3f(world_from_cam_ * (-position / distance))
                                       : Eigen::Vector3f::UnitZ();
    float light = static_cast<float>(options_.ambient);
    for (std::size_t i = 0; i < lights_world_.size(); ++i) {
      const float wrap = static_cast<float>(options_.lights[i].wrap);
      const float d = (n.dot(lights_world_[i]) + wrap) / (1.0f + wrap);
      float intensity = static_cast<float>(options_.lights[i].intensity);
      // The key light's cast shadow falls on the plate (the object shades itself already).
      if (i == 0 && t.material < 0 && cast_ != nullptr)
        intensity *= 1.0f - static_cast<float>(options_.cast_shadow) * cast_->Occlusion(world);
      light += intensity * std::max(d, 0.0f);
    }
    Eigen::Vector3f colour = albedo * (light * exposure * front);
    if (specular > 0.0f) {
      // Blinn-Phong highlights of the studio lights, white (a dielectric's).
      float highlight = 0.0f;
      for (std::size_t i = 0; i < lights_world_.size(); ++i) {
        if (n.dot(lights_world_[i]) <= 0.0f) continue;
        const Eigen::Vector3f half = (lights_world_[i] + to_eye).normalized();
        highlight += static_cast<float>(options_.lights[i].intensity) *
                     std::pow(std::max(n.dot(half), 0.0f), shininess);
      }
      colour += Eigen::Vector3f::Constant(specular * highlight * exposure * front);
    }
    if (t.material < 0) return colour;
    // Grazing angles: a Fresnel reflection (Schlick, a dielectric's 4 %) replaces what passes
    // through a see-through surface; a backlit shot's light wraps round the outline.
    const float facing = std::min(1.0f, std::abs(n.dot(to_eye)));
    const float grazing = 1.0f - facing;
    const float grazing2 = grazing * grazing;
    const float fresnel = 0.04f + 0.96f * grazing2 * grazing2 * grazing;
    const float transmission = scene_.materials[t.material].transmission * (1.0f - fresnel);
    if (transmission > 0.0f) {
      // What lies behind: the backdrop (or the lit panel) at this pixel, tinted.
      const Eigen::Vector3f behind = BackdropAt(ix, iy);
      colour = (1.0f - transmission) * colour +
               transmission * scene_.materials[t.material].base_color.cwiseProduct(behind);
    }
    if (options_.backlit) {
      const float wrap = grazing2 * grazing2 * grazing2 * (specular > 0.0f ? 0.5f : 0.3f);
      colour += Eigen::Vector3f::Constant(static_cast<float>(options_.backlight) * wrap *
                                          BackdropFalloff(ix, iy));
    }
    return colour;
  }

  // The backdrop light's falloff towards the frame's corners (1 at the centre).
  float BackdropFalloff(int x, int y) const {
    if (options_.backdrop_falloff <= 0.0) return 1.0f;
    const float nx = (2.0f * x + 1.0f) / camera_.width - 1.0f;
    const float ny = (2.0f * y + 1.0f) / camera_.height - 1.0f;
    return 1.0f - static_cast<float>(options_.backdrop_falloff) * 0.5f * (nx * nx + ny * ny);
  }

  // The backdrop (linear RGB) at pixel (x, y): its gradient, the light's falloff and, on the
  // sweep, the key light's cast shadow.
  Eigen::Vector3f BackdropAt(int x, int y) const {
    float gain = BackdropFalloff(x, y);
    if (cast_ != nullptr && !options_.backlit) {
      // Where the pixel's ray meets the sweep (wall or floor, studio frame; a pinhole ray is
      // close enough for a soft shadow).
      const Eigen::Vector3f ray_cam(static_cast<float>((x - camera_.cx) / camera_.fx),
                                    static_cast<float>((y - camera_.cy) / camera_.fy), 1.0f);
      const Eigen::Vector3f ray = studio_from_world_ * (world_from_cam_ * ray_cam);
      const Eigen::Vector3f& o = camera_centre_studio_;
      float hit = std::numeric_limits<float>::infinity();
      if (ray.y() > 1e-6f)
        hit = std::min(hit, (static_cast<float>(options_.sweep_distance_m) - o.y()) / ray.y());
      if (ray.z() < -1e-6f)
        hit = std::min(hit, (static_cast<float>(options_.sweep_floor_m) - o.z()) / ray.z());
      if (hit > 0.0f && std::isfinite(hit)) {
        const Eigen::Vector3f studio = o + hit * ray;
        const Eigen::Vector3f world = studio_from_world_.transpose() * studio;
        gain *= 1.0f - static_cast<float>(options_.cast_shadow) * sweep_key_share_ *
                           cast_->Occlusion(world);
      }
    }
    return backdrop_rows_[y] * gain;
  }

  // Writes a pixel's final colour (linear RGB) with sensor noise, as 8-bit BGR.
  void WritePixel(int x, int y, const Eigen::Vector3f& colour_in, cv::Vec3b& out) const {
    const ColourTables& tables = Tables();
    Eigen::Vector3f colour = colour_in;
    if (vignette_a_ > 0.0f) {
      const float dx = static_cast<float>(x - camera_.cx), dy = static_cast<float>(y - camera_.cy);
      const float q = 1.0f + vignette_a_ * (dx * dx + dy * dy) * inv_corner_sq_;
      colour /= q * q;
    }
    for (int c = 0; c < 3; ++c) {
      float value = tables.Encode(colour[c]);
      if (options_.noise_sigma > 0) {
        const std::uint64_t index = (static_cast<std::uint64_t>(y) * camera_.width + x) * 3 + c;
        value += static_cast<float>(options_.noise_sigma) * HashNormal(mixed_seed_, index);
      }
      out[2 - c] = static_cast<std::uint8_t>(std::clamp(value, 0.0f, 255.0f) + 0.5f);
    }
  }

  void FillBackdrop(int x0, int y0, int x1, int y1) const {
    for (int y = y0; y < y1; ++y) {
      auto* image_row = result_.image.ptr<cv::Vec3b>(y);
      for (int x = x0; x < x1; ++x) WritePixel(x, y, BackdropAt(x, y), image_row[x]);
      std::fill(result_.mask.ptr<std::uint8_t>(y) + x0, result_.mask.ptr<std::uint8_t>(y) + x1, 0);
      std::fill(result_.depth.ptr<float>(y) + x0, result_.depth.ptr<float>(y) + x1, 0.0f);
    }
  }

  void Resolve(int x0, int y0, int x1, int y1, int w, const std::vector<Sample>& buffer) const {
    for (int y = y0; y < y1; ++y) {
      auto* image_row = result_.image.ptr<cv::Vec3b>(y);
      auto* mask_row = result_.mask.ptr<std::uint8_t>(y);
      auto* depth_row = result_.depth.ptr<float>(y);
      for (int x = x0; x < x1; ++x) {
        const Sample* pixel = &buffer[(static_cast<std::size_t>(y - y0) * w + (x - x0)) * samples_];
        // Fast path: one triangle (or the backdrop) covers every sample.
        bool uniform = true;
        for (int s = 1; s < samples_ && uniform; ++s)
          uniform = pixel[s].triangle == pixel[0].triangle;
        if (uniform) {
          const int id = pixel[0].triangle;
          if (id < 0) {
            WritePixel(x, y, BackdropAt(x, y), image_row[x]);
            mask_row[x] = 0;
            depth_row[x] = 0.0f;
          } else {
            float depth = 0.0f;
            WritePixel(x, y, Shade(triangles_[id], x, y, &depth), image_row[x]);
            mask_row[x] = triangles_[id].object ? 255 : 0;
            depth_row[x] = triangles_[id].object ? depth : 0.0f;
          }
          continue;
        }
        Eigen::Vector3f colour = Eigen::Vector3f::Zero();
        int object_samples = 0;
        float nearest_object = 0.0f;
        std::array<bool, 16> done{};
        for (int s = 0; s < samples_; ++s) {
          if (done[s]) continue;
          const int id = pixel[s].triangle;
          int count = 0;
          double cx = 0, cy = 0;
          for (int r = s; r < samples_; ++r) {
            if (pixel[r].triangle == id) {
              done[r] = true;
              ++count;
              cx += offsets_[r].x();
              cy += offsets_[r].y();
            }
          }
          const float weight = static_cast<float>(count) / samples_;
          if (id < 0) {
            colour += weight * BackdropAt(x, y);
            continue;
          }
          const ScreenTriangle& t = triangles_[id];
          float depth = 0.0f;
          colour += weight * Shade(t, x + cx / count, y + cy / count, &depth);
          if (t.object) {
            object_samples += count;
            if (nearest_object == 0.0f || depth < nearest_object) nearest_object = depth;
          }
        }
        WritePixel(x, y, colour, image_row[x]);
        const bool object = 2 * object_samples >= samples_;
        mask_row[x] = object ? 255 : 0;
        depth_row[x] = object ? nearest_object : 0.0f;
      }
    }
  }

  const Scene& scene_;
  const CameraModel& camera_;
  const RenderOptions& options_;
  const std::vector<ScreenTriangle>& triangles_;
  const std::vector<std::vector<std::uint32_t>>& bins_;
  int tiles_x_;
  const std::vector<Eigen::Vector3f>& lights_world_;
  RenderResult& result_;
  int n_;
  int samples_;
  Eigen::Matrix3f world_from_cam_;
  Eigen::Vector3f cam_translation_;
  const ContactShadowMap* shadow_ = nullptr;
  const CastShadowMap* cast_ = nullptr;
  // The key light's share of the sweep's light (what a full cast shadow takes away from it,
  // times cast_shadow).
  float sweep_key_share_ = 0.5f;
  float inv_corner_sq_ = 0.0f;
  float vignette_a_ = 0.0f;
  Eigen::Matrix3f studio_from_world_ = Eigen::Matrix3f::Identity();
  Eigen::Vector3f camera_centre_studio_ = Eigen::Vector3f::Zero();
  std::vector<Eigen::Vector2d> offsets_;
  std::vector<Eigen::Vector3f> backdrop_rows_;  // linear RGB per image row
  Eigen::Vector3f plate_;
  std::uint64_t mixed_seed_ = 0;
};

}  // namespace

void RenderOptions::Validate() const {
  CAROUSEL_THROW_IF(samples_per_axis < 1 || samples_per_axis > 4, InvalidArgument,
                    "RenderOptions.samples_per_axis must be in 1..4, got " << samples_per_axis);
  CAROUSEL_THROW_IF(!(ambient >= 0 && ambient < 1e3), InvalidArgument,
                    "RenderOptions.ambient must be in [0, 1000)");
  for (const Eigen::Vector3d* colour : {&backdrop_top, &backdrop_bottom, &plate_color}) {
    CAROUSEL_THROW_IF(!colour->allFinite(), InvalidArgument,
                      "RenderOptions: backdrop and plate colours must be finite");
  }
  CAROUSEL_THROW_IF(!(exposure > 0 && exposure < 1e3), InvalidArgument,
                    "RenderOptions.exposure must be in (0, 1000), got " << exposure);
  for (const DirectionalLight& light : lights) {
    CAROUSEL_THROW_IF(
        !(light.intensity >= 0 && light.intensity < 1e3) || !(light.wrap >= 0 && light.wrap <= 1) ||
            !light.direction_studio.allFinite() || !(light.direction_studio.norm() > 0),
        InvalidArgument,
        "RenderOptions.lights: intensity in [0, 1000), wrap in 0..1 and a finite, "
        "non-zero direction are required");
  }
  CAROUSEL_THROW_IF(!(plate_radius_m >= 0), InvalidArgument,
                    "RenderOptions.plate_radius_m must be >= 0");
  CAROUSEL_THROW_IF(!(contact_shadow >= 0 && contact_shadow <= 1) ||
                        !(contact_shadow_radius_m > 0 && contact_shadow_radius_m < 1),
                    InvalidArgument,
                    "RenderOptions: contact_shadow must be in 0..1 and contact_shadow_radius_m in "
                    "(0, 1) m");
  CAROUSEL_THROW_IF(!(cast_shadow >= 0 && cast_shadow <= 1) ||
                        !(key_light_size_deg > 0 && key_light_size_deg < 90) ||
                        !(sweep_distance_m > 0 && sweep_distance_m < 100) ||
                        !(sweep_floor_m <= 0 && sweep_floor_m > -100),
                    InvalidArgument,
                    "RenderOptions: cast_shadow must be in 0..1, key_light_size_deg in (0, 90), "
                    "sweep_distance_m > 0 and sweep_floor_m <= 0");
  CAROUSEL_THROW_IF(!(backdrop_falloff >= 0 && backdrop_falloff <= 0.9) ||
                        !(vignetting >= 0 && vignetting <= 0.9),
                    InvalidArgument,
                    "RenderOptions: backdrop_falloff and vignetting must be in 0..0.9");
  CAROUSEL_THROW_IF(
      !(backlight > 0 && backlight <= 1) || !(backlit_front >= 0 && backlit_front <= 1),
      InvalidArgument, "RenderOptions: backlight must be in (0, 1] and backlit_front in 0..1");
  CAROUSEL_THROW_IF(!(noise_sigma >= 0 && noise_sigma <= 64), InvalidArgument,
                    "RenderOptions.noise_sigma must be in 0..64, got " << noise_sigma);
  CAROUSEL_THROW_IF(!(max_edge_error_px > 0), InvalidArgument,
                    "RenderOptions.max_edge_error_px must be > 0");
  CAROUSEL_THROW_IF(threads < 0, InvalidArgument, "RenderOptions.threads must be >= 0");
  CAROUSEL_THROW_IF(!(near_m > 0), InvalidArgument, "RenderOptions.near_m must be > 0");
}

RenderResult Render(const Scene& scene, const CameraModel& camera, double table_angle_rad,
                    const RenderOptions& options) {
  options.Validate();
  camera.Validate();
  scene.Validate();

  // Camera-space setup of every triangle (object, then plate).
  std::vector<ScreenTriangle> triangles;
  triangles.reserve(scene.triangles.size() + 256);
  TriangleSetup setup(camera, options, triangles);
  const Eigen::Vector3d eye = camera.Centre();
  for (std::size_t i = 0; i < scene.triangles.size(); ++i) {
    const Eigen::Vector3i& tri = scene.triangles[i];
    std::array<ClipVertex, 3> v;
    for (int k = 0; k < 3; ++k) {
      v[k] = {camera.cam_from_world * scene.positions[tri[k]], scene.uvs[tri[k]],
              scene.normals[tri[k]]};
    }
    const Eigen::Vector3d& p0 = scene.positions[tri[0]];
    const Eigen::Vector3d face_normal =
        (scene.positions[tri[1]] - p0).cross(scene.positions[tri[2]] - p0);
    const bool back_facing = face_normal.dot(eye - p0) < 0;
    const int material = scene.triangle_material[i];
    const int texture = scene.materials[material].texture;
    setup.Add(v, material, true, back_facing,
              texture >= 0 ? scene.textures[texture].get() : nullptr);
  }
  if (options.plate_radius_m > 0) {
    // Rings of compact triangles (a fan of slivers would give every triangle a huge bounding
    // box), just below the object's base so that the two never fight over depth.
    const Mesh plate = MakeDisc(options.plate_radius_m, 128, 16);
    const double z = -0.001;
    const Eigen::Vector3f up = Eigen::Vector3f::UnitZ();
    for (Mesh::FaceHandle face : plate.faces()) {
      std::array<ClipVertex, 3> v;
      int k = 0;
      for (Mesh::VertexHandle vertex : plate.fv_range(face)) {
        const OpenMesh::Vec3d& p = plate.point(vertex);
        v[k++] = {camera.cam_from_world * Eigen::Vector3d(p[0], p[1], z), {0, 0}, up};
      }
      setup.Add(v, -1, false, eye.z() < z, nullptr);
    }
  }

  // Bin triangles to tiles, in order (determinism).
  const int tiles_x = (camera.width + kTileSize - 1) / kTileSize;
  const int tiles_y = (camera.height + kTileSize - 1) / kTileSize;
  std::vector<std::vector<std::uint32_t>> bins(static_cast<std::size_t>(tiles_x) * tiles_y);
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    const ScreenTriangle& t = triangles[i];
    auto tile_of = [](double coordinate, int tiles) {
      return static_cast<int>(
          std::clamp(std::floor(coordinate / kTileSize), 0.0, static_cast<double>(tiles - 1)));
    };
    const int tx0 = tile_of(std::min({t.x[0], t.x[1], t.x[2]}) - 1, tiles_x);
    const int tx1 = tile_of(std::max({t.x[0], t.x[1], t.x[2]}) + 1, tiles_x);
    const int ty0 = tile_of(std::min({t.y[0], t.y[1], t.y[2]}) - 1, tiles_y);
    const int ty1 = tile_of(std::max({t.y[0], t.y[1], t.y[2]}) + 1, tiles_y);
    for (int ty = ty0; ty <= ty1; ++ty) {
      for (int tx = tx0; tx <= tx1; ++tx)
        bins[ty * tiles_x + tx].push_back(static_cast<std::uint32_t>(i));
    }
  }

  // Lights: fixed in the studio; the scene turned by +angle, so in its frame they turned back.
  const Eigen::Matrix3d world_from_studio = Rigid3d::RotationZ(-table_angle_rad).rotation;
  std::vector<Eigen::Vector3f> lights_world;
  for (const DirectionalLight& light : options.lights) {
    lights_world.push_back((world_from_studio * light.direction_studio.normalized()).cast<float>());
  }

  RenderResult result;
  result.image.create(camera.height, camera.width, CV_8UC3);
  result.mask.create(camera.height, camera.width, CV_8UC1);
  result.depth.create(camera.height, camera.width, CV_32FC1);
  result.triangles_rasterized = triangles.size();
  Rasteriser rasteriser(scene, camera, table_angle_rad, options, triangles, bins, tiles_x,
                        lights_world, result);
  CastShadowMap cast;
  if (options.cast_shadow > 0 && !options.backlit && !lights_world.empty() &&
      !scene.triangles.empty() && options.lit) {
    cast = MakeCastShadowMap(scene, lights_world.front(), options.key_light_size_deg);
    rasteriser.SetCastShadow(&cast);
  }
  ContactShadowMap shadow;
  if (options.contact_shadow > 0 && options.plate_radius_m > 0 && !options.backlit) {
    shadow = MakeContactShadowMap(scene, options.plate_radius_m + options.contact_shadow_radius_m,
                                  options.contact_shadow_radius_m);
    rasteriser.SetContactShadow(&shadow);
  }
  const int tile_count = tiles_x * tiles_y;
  std::atomic<int> next{0};
  std::mutex error_mutex;
  std::exception_ptr error;
  // A worker that fails (out of memory) stops everyone; the error is rethrown after joining.
  auto worker = [&] {
    try {
      std::vector<Sample> buffer;
      for (int tile = next++; tile < tile_count; tile = next++) rasteriser.RenderTile(tile, buffer);
    } catch (...) {
      next = tile_count;
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  };
  const int threads = std::min(ResolveThreadCount(options.threads), tile_count);
  {
    std::vector<std::jthread> pool;
    try {
      for (int i = 1; i < threads; ++i) pool.emplace_back(worker);
    } catch (...) {
      next = tile_count;  // the started workers stop; jthread joins them
      throw;
    }
    worker();
  }
  if (error) std::rethrow_exception(error);
  return result;
}

}  // namespace carousel::sim
