#include "carousel/core/raster.h"

#include <limits>

#include "carousel/core/error.h"
#include "carousel/core/mesh.h"
#include "carousel/core/parallel.h"

namespace carousel {
namespace {

constexpr int kBandRows = 16;  // rows rasterised together by one worker
constexpr int kMaxSubdivision = 12;
// Edges shorter than this on screen are never split, however much the lens bends them.
constexpr double kMinSplitLengthPx = 0.25;

// A corner of a (possibly split) triangle: camera-frame position and its barycentric
// coordinates in the original face (midpoints in 3D average them exactly).
struct Corner {
  Eigen::Vector3d cam;
  Eigen::Vector3d in_face;
};

// A triangle on screen, ordered so that area2 > 0.
struct ScreenTriangle {
  double x[3], y[3];  // distorted pixel coordinates
  double inv_z[3];    // 1 / camera z
  Eigen::Vector3d in_face[3];
  double area2;  // cross(p1 - p0, p2 - p0)
  int face;
};

class TriangleSetup {
 public:
  TriangleSetup(const CameraModel& camera, const MeshRasterOptions& options,
                std::vector<ScreenTriangle>& out)
      : camera_(camera), options_(options), out_(out), split_(!camera.distortion.IsZero()) {}

  void Add(const std::array<Corner, 3>& c, int face, int depth = 0) {
    std::array<Eigen::Vector2d, 3> p;
    for (int k = 0; k < 3; ++k) {
      if (!(c[k].cam.z() > options_.near_m)) return;
      p[k] = camera_.ProjectFromCam(c[k].cam);
      if (!p[k].allFinite()) return;
    }
    const double min_x = std::min({p[0].x(), p[1].x(), p[2].x()});
    const double max_x = std::max({p[0].x(), p[1].x(), p[2].x()});
    const double min_y = std::min({p[0].y(), p[1].y(), p[2].y()});
    const double max_y = std::max({p[0].y(), p[1].y(), p[2].y()});
    if (max_x < -0.5 || max_y < -0.5 || min_x > camera_.width - 0.5 || min_y > camera_.height - 0.5)
      return;  // wholly outside the image
    if (split_ && depth < kMaxSubdivision) {
      std::array<bool, 3> split{};
      int splits = 0;
      for (int k = 0; k < 3; ++k) splits += (split[k] = EdgeBends(c[k].cam, c[(k + 1) % 3].cam));
      auto mid = [&](int a, int b) {
        return Corner{0.5 * (c[a].cam + c[b].cam), 0.5 * (c[a].in_face + c[b].in_face)};
      };
      auto add = [&](const Corner& a, const Corner& b, const Corner& d) {
        Add({a, b, d}, face, depth + 1);
      };
      if (splits == 3) {
        const Corner m01 = mid(0, 1), m12 = mid(1, 2), m20 = mid(2, 0);
        add(c[0], m01, m20);
        add(m01, c[1], m12);
        add(m20, m12, c[2]);
        add(m01, m12, m20);
        return;
      }
      if (splits == 1) {
        const int k = split[0] ? 0 : split[1] ? 1 : 2;  // edge k -> k + 1
        const Corner m = mid(k, (k + 1) % 3);
        add(c[k], m, c[(k + 2) % 3]);
        add(m, c[(k + 1) % 3], c[(k + 2) % 3]);
        return;
      }
      if (splits == 2) {
        const int whole = !split[0] ? 0 : !split[1] ? 1 : 2;  // edge a -> b stays whole
        const int a = whole, b = (whole + 1) % 3, d = (whole + 2) % 3;
        const Corner bd = mid(b, d), da = mid(d, a);
        add(c[d], da, bd);
        add(c[a], c[b], bd);
        add(c[a], bd, da);
        return;
      }
    }
    double area2 = (p[1].x() - p[0].x()) * (p[2].y() - p[0].y()) -
                   (p[2].x() - p[0].x()) * (p[1].y() - p[0].y());
    if (!(std::abs(area2) > 1e-12)) return;
    std::array<int, 3> order = {0, 1, 2};
    if (area2 < 0) {
      std::swap(order[1], order[2]);
      area2 = -area2;
    }
    ScreenTriangle t;
    for (int k = 0; k < 3; ++k) {
      const int o = order[k];
      t.x[k] = p[o].x();
      t.y[k] = p[o].y();
      t.inv_z[k] = 1.0 / c[o].cam.z();
      t.in_face[k] = c[o].in_face;
    }
    t.area2 = area2;
    t.face = face;
    out_.push_back(t);
  }

 private:
  // True when the lens moves the edge's 3D midpoint further than allowed from where a
  // straight screen edge puts it (at the perspective-correct parameter): the bend across the
  // edge and the stretch along it. In a canonical endpoint order, so that both triangles
  // sharing the edge decide alike.
  bool EdgeBends(const Eigen::Vector3d& a_in, const Eigen::Vector3d& b_in) const {
    const bool swap =
        std::lexicographical_compare(b_in.data(), b_in.data() + 3, a_in.data(), a_in.data() + 3);
    const Eigen::Vector3d& a = swap ? b_in : a_in;
    const Eigen::Vector3d& b = swap ? a_in : b_in;
    const Eigen::Vector2d pa = camera_.ProjectFromCam(a), pb = camera_.ProjectFromCam(b);
    const Eigen::Vector2d pm = camera_.ProjectFromCam(0.5 * (a + b));
    const Eigen::Vector2d ab = pb - pa;
    if (!(ab.norm() > kMinSplitLengthPx) || !pm.allFinite()) return false;
    const double t = b.z() / (a.z() + b.z());  // where 1/z interpolation reaches the midpoint
    return (pm - (pa + t * ab)).norm() > options_.max_edge_error_px;
  }

  const CameraModel& camera_;
  const MeshRasterOptions& options_;
  std::vector<ScreenTriangle>& out_;
  bool split_;
};

// Top or left edge a -> b of a triangle with area2 > 0 (clockwise on screen, y down): the top
// edge runs to the right, left edges run upwards.
bool TopLeft(double ax, double ay, double bx, double by) {
  const double dx = bx - ax, dy = by - ay;
  return (dy == 0 && dx > 0) || dy < 0;
}

struct Sample {
  float inv_z = 0.0f;
  int triangle = -1;  // index into the screen triangles
};

// Rasterises the rows [y0, y1) into `samples` (width x rows x per-pixel samples).
void RasteriseBand(const std::vector<ScreenTriangle>& triangles,
                   const std::vector<std::uint32_t>& bin, int width, int y0, int y1,
                   const std::vector<Eigen::Vector2d>& offsets, std::vector<Sample>& samples) {
  const int n = static_cast<int>(offsets.size());
  samples.assign(static_cast<std::size_t>(width) * (y1 - y0) * n, Sample{});
  for (const std::uint32_t index : bin) {
    const ScreenTriangle& t = triangles[index];
    auto clamp_to = [](double value, int lo, int hi) {
      return static_cast<int>(std::clamp(value, static_cast<double>(lo), static_cast<double>(hi)));
    };
    const int bx0 = clamp_to(std::floor(std::min({t.x[0], t.x[1], t.x[2]})), 0, width);
    const int bx1 = clamp_to(std::ceil(std::max({t.x[0], t.x[1], t.x[2]})), -1, width - 1);
    const int by0 = clamp_to(std::floor(std::min({t.y[0], t.y[1], t.y[2]})), y0, y1);
    const int by1 = clamp_to(std::ceil(std::max({t.y[0], t.y[1], t.y[2]})), y0 - 1, y1 - 1);
    if (bx0 > bx1 || by0 > by1) continue;
    // Edge k (opposite vertex k) from a = k + 1 to b = k + 2: E_k(p) = cross(b - a, p - a),
    // E_k / area2 is the screen barycentric of vertex k. Evaluated from the endpoints in a
    // canonical order (negated when swapped), so two triangles sharing an edge get exactly
    // opposite values and the top-left rule gives a sample on it to exactly one of them.
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
    for (int y = by0; y <= by1; ++y)
      for (int x = bx0; x <= bx1; ++x) {
        Sample* pixel = &samples[(static_cast<std::size_t>(y - y0) * width + x) * n];
        for (int s = 0; s < n; ++s) {
          const double px = x + offsets[s].x(), py = y + offsets[s].y();
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

// The face's barycentrics and the depth at (px, py), through screen triangle t (extrapolated
// when the point lies slightly outside it: its plane is the face's).
RasterFragment FragmentAt(const ScreenTriangle& t, double px, double py) {
  double w[3], total = 0.0;
  for (int k = 0; k < 3; ++k) {
    const int a = (k + 1) % 3, b = (k + 2) % 3;
    const double e = (t.x[b] - t.x[a]) * (py - t.y[a]) - (t.y[b] - t.y[a]) * (px - t.x[a]);
    w[k] = e / t.area2 * t.inv_z[k];  // screen barycentric / z
    total += w[k];
  }
  RasterFragment f;
  f.face = t.face;
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3; ++k) b += (w[k] / total) * t.in_face[k];
  b = b.cwiseMax(0.0).cwiseMin(1.0);
  const double sum = b.sum();
  b = sum > 0.0 ? Eigen::Vector3d(b / sum) : Eigen::Vector3d::Constant(1.0 / 3.0);
  f.barycentric = b.cast<float>();
  f.depth = static_cast<float>(1.0 / total);
  return f;
}

}  // namespace

void MeshRasterOptions::Validate() const {
  CAROUSEL_THROW_IF(samples_per_axis < 1 || samples_per_axis > 4, InvalidArgument,
                    "MeshRasterOptions.samples_per_axis must be in 1..4, got " << samples_per_axis);
  CAROUSEL_THROW_IF(!(max_edge_error_px > 0), InvalidArgument,
                    "MeshRasterOptions.max_edge_error_px must be > 0");
  CAROUSEL_THROW_IF(!(near_m > 0), InvalidArgument, "MeshRasterOptions.near_m must be > 0");
  CAROUSEL_THROW_IF(threads < 0, InvalidArgument, "MeshRasterOptions.threads must be >= 0");
}

int MeshRaster::CoveredSamples(int x, int y) const {
  int covered = 0;
  for (const RasterFragment& f : Fragments(x, y)) covered += f.samples;
  return covered;
}

cv::Mat MeshRaster::Mask() const {
  cv::Mat mask(height_, width_, CV_8UC1);
  for (int y = 0; y < height_; ++y) {
    auto* row = mask.ptr<std::uint8_t>(y);
    for (int x = 0; x < width_; ++x)
      row[x] = 2 * CoveredSamples(x, y) >= samples_per_pixel() ? 255 : 0;
  }
  return mask;
}

cv::Mat MeshRaster::Coverage() const {
  cv::Mat coverage(height_, width_, CV_8UC1);
  const int n = samples_per_pixel();
  for (int y = 0; y < height_; ++y) {
    auto* row = coverage.ptr<std::uint8_t>(y);
    for (int x = 0; x < width_; ++x)
      row[x] = static_cast<std::uint8_t>((255 * CoveredSamples(x, y) + n / 2) / n);
  }
  return coverage;
}

cv::Mat MeshRaster::FaceIds() const {
  cv::Mat ids(height_, width_, CV_32SC1);
  for (int y = 0; y < height_; ++y) {
    auto* row = ids.ptr<std::int32_t>(y);
    for (int x = 0; x < width_; ++x) {
      int best = -1, most = 0;
      for (const RasterFragment& f : Fragments(x, y))
        if (f.samples > most) {
          most = f.samples;
          best = f.face;
        }
      row[x] = best;
    }
  }
  return ids;
}

MeshRaster RasterizeMesh(std::span<const Eigen::Vector3d> positions_world,
                         std::span<const Eigen::Vector3i> triangles, const CameraModel& camera,
                         const MeshRasterOptions& options) {
  camera.Validate();
  options.Validate();
  const auto vertex_count = static_cast<int>(positions_world.size());
  for (std::size_t i = 0; i < triangles.size(); ++i)
    for (int k = 0; k < 3; ++k)
      CAROUSEL_THROW_IF(triangles[i][k] < 0 || triangles[i][k] >= vertex_count, InvalidArgument,
                        "RasterizeMesh: triangle " << i << " has vertex index " << triangles[i][k]
                                                   << ", outside [0, " << vertex_count << ")");
  CAROUSEL_THROW_IF(triangles.size() > static_cast<std::size_t>(std::numeric_limits<int>::max()),
                    InvalidArgument, "RasterizeMesh: too many triangles");

  // Screen triangles, set up in chunks and concatenated in order (determinism).
  constexpr std::size_t kSetupChunk = 4096;
  const std::size_t chunks = (triangles.size() + kSetupChunk - 1) / kSetupChunk;
  std::vector<std::vector<ScreenTriangle>> chunk_triangles(chunks);
  ParallelFor(chunks, 1, options.threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t c = begin; c < end; ++c) {
      TriangleSetup setup(camera, options, chunk_triangles[c]);
      const std::size_t last = std::min(triangles.size(), (c + 1) * kSetupChunk);
      for (std::size_t i = c * kSetupChunk; i < last; ++i) {
        std::array<Corner, 3> corners;
        for (int k = 0; k < 3; ++k)
          corners[k] = {camera.cam_from_world * positions_world[triangles[i][k]],
                        Eigen::Vector3d::Unit(k)};
        setup.Add(corners, static_cast<int>(i));
      }
    }
  });
  std::vector<ScreenTriangle> screen;
  for (const auto& part : chunk_triangles) screen.insert(screen.end(), part.begin(), part.end());
  chunk_triangles.clear();
  CAROUSEL_THROW_IF(screen.size() > std::numeric_limits<std::uint32_t>::max(), InvalidArgument,
                    "RasterizeMesh: too many triangles after subdivision");

  // Bands of rows, each with the triangles that may touch it, in order.
  const int width = camera.width, height = camera.height;
  const int bands = (height + kBandRows - 1) / kBandRows;
  std::vector<std::vector<std::uint32_t>> bins(bands);
  for (std::size_t i = 0; i < screen.size(); ++i) {
    const ScreenTriangle& t = screen[i];
    auto band_of = [&](double y) {
      return static_cast<int>(std::clamp(std::floor(y / kBandRows), 0.0, bands - 1.0));
    };
    const int b0 = band_of(std::floor(std::min({t.y[0], t.y[1], t.y[2]})) - 1);
    const int b1 = band_of(std::ceil(std::max({t.y[0], t.y[1], t.y[2]})) + 1);
    for (int b = b0; b <= b1; ++b) bins[b].push_back(static_cast<std::uint32_t>(i));
  }

  const int n = options.samples_per_axis;
  std::vector<Eigen::Vector2d> offsets;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) offsets.emplace_back((i + 0.5) / n - 0.5, (j + 0.5) / n - 0.5);
  const int per_pixel = n * n;

  // Each band: its samples, then one fragment per face and pixel.
  MeshRaster raster;
  raster.width_ = width;
  raster.height_ = height;
  raster.samples_per_axis_ = n;
  raster.triangles_rasterized_ = screen.size();
  std::vector<std::vector<RasterFragment>> band_fragments(bands);
  std::vector<std::uint8_t> counts(static_cast<std::size_t>(width) * height, 0);
  ParallelFor(bands, 1, options.threads, [&](std::size_t begin, std::size_t end) {
    std::vector<Sample> samples;
    for (std::size_t band = begin; band < end; ++band) {
      const int y0 = static_cast<int>(band) * kBandRows;
      const int y1 = std::min(height, y0 + kBandRows);
      std::vector<RasterFragment>& out = band_fragments[band];
      if (bins[band].empty()) continue;
      RasteriseBand(screen, bins[band], width, y0, y1, offsets, samples);
      for (int y = y0; y < y1; ++y)
        for (int x = 0; x < width; ++x) {
          const Sample* pixel =
              &samples[(static_cast<std::size_t>(y - y0) * width + x) * per_pixel];
          std::array<bool, 16> done{};
          std::uint8_t fragments = 0;
          for (int s = 0; s < per_pixel; ++s) {
            if (done[s] || pixel[s].triangle < 0) continue;
            const int face = screen[pixel[s].triangle].face;
            int count = 0;
            double cx = 0.0, cy = 0.0;
            for (int r = s; r < per_pixel; ++r)
              if (pixel[r].triangle >= 0 && screen[pixel[r].triangle].face == face) {
                done[r] = true;
                ++count;
                cx += offsets[r].x();
                cy += offsets[r].y();
              }
            RasterFragment f =
                FragmentAt(screen[pixel[s].triangle], x + cx / count, y + cy / count);
            f.samples = count;
            out.push_back(f);
            ++fragments;
          }
          counts[static_cast<std::size_t>(y) * width + x] = fragments;
        }
    }
  });
  std::size_t total = 0;
  for (const auto& part : band_fragments) total += part.size();
  CAROUSEL_THROW_IF(total > std::numeric_limits<std::uint32_t>::max(), InvalidArgument,
                    "RasterizeMesh: too many fragments (image too large)");
  raster.offsets_.assign(counts.size() + 1, 0);
  for (std::size_t p = 0; p < counts.size(); ++p)
    raster.offsets_[p + 1] = raster.offsets_[p] + counts[p];
  raster.fragments_.reserve(total);
  for (auto& part : band_fragments) {
    raster.fragments_.insert(raster.fragments_.end(), part.begin(), part.end());
    std::vector<RasterFragment>().swap(part);
  }
  return raster;
}

MeshRaster RasterizeMesh(const Mesh& mesh, const CameraModel& camera,
                         const MeshRasterOptions& options) {
  std::vector<Eigen::Vector3d> positions(mesh.n_vertices());
  for (const auto v : mesh.vertices()) {
    const auto& p = mesh.point(v);
    positions[v.idx()] = Eigen::Vector3d(p[0], p[1], p[2]);
  }
  // Deleted faces keep their index with a degenerate triangle, which draws nothing.
  std::vector<Eigen::Vector3i> triangles(mesh.n_faces(), Eigen::Vector3i::Zero());
  for (const auto f : mesh.faces()) {
    int k = 0;
    for (const auto v : mesh.fv_range(f)) {
      CAROUSEL_THROW_IF(k == 3, InvalidArgument,
                        "RasterizeMesh: face " << f.idx() << " is not a triangle");
      triangles[f.idx()][k++] = v.idx();
    }
  }
  return RasterizeMesh(positions, triangles, camera, options);
}

}  // namespace carousel
