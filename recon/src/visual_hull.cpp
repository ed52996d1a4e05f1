#include "carousel/recon/visual_hull.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/core/marching_tetrahedra.h"
#include "carousel/core/mesh_query.h"
#include "carousel/core/parallel.h"
#include "carousel/core/timer.h"

namespace carousel::recon {
namespace {

constexpr double kNearM = 1e-3;          // points closer to a camera are not projected
constexpr double kFootprintSlack = 1.2;  // projected-radius safety factor (lens distortion)
constexpr int kRootCells = 32;           // root grid cells along the longest side, at most
constexpr int kConsistencyGrid = 48;     // points per axis for the consistency check
constexpr int kPriorGrid = 96;           // cells per axis for the others' hull priors
// The priors' cells are decided a block of kPriorBlock^3 at a time first, with the block's
// projected radius taken kPriorBlockSlack times larger (the projection curves).
constexpr int kPriorBlock = 4;
constexpr double kPriorBlockSlack = 1.25;
static_assert(kPriorGrid % kPriorBlock == 0);
constexpr double kPriorSize = 1024.0;  // longest mask side the priors are computed at

// Signed distance to the silhouette boundary in pixels, positive inside, over a crop of the
// image around the silhouette; outside the crop a lower bound of the true (negative) distance.
class DistanceMap {
 public:
  DistanceMap(const cv::Mat& mask, const std::string& name) {
    width_ = mask.cols;
    height_ = mask.rows;
    cv::Mat object = mask >= 128;
    const cv::Rect box = cv::boundingRect(object);
    if (box.area() == 0) throw InvalidArgument(name + ": silhouette is empty");
    box_ = box;
    const cv::Moments m = cv::moments(object, true);
    centroid_ = Eigen::Vector2d(m.m10 / m.m00, m.m01 / m.m00);
    margin_ = std::clamp(std::max(box.width, box.height) / 8, 32, 128);
    crop_ = cv::Rect(box.x - margin_, box.y - margin_, box.width + 2 * margin_,
                     box.height + 2 * margin_) &
            cv::Rect(0, 0, width_, height_);
    const cv::Mat inside = object(crop_);
    const cv::Mat outside = ~inside;
    cv::Mat d_in, d_out;
    cv::distanceTransform(inside, d_in, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
    cv::distanceTransform(outside, d_out, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
    sd_.create(crop_.size(), CV_32F);
    for (int y = 0; y < crop_.height; ++y) {
      const auto* in = inside.ptr<std::uint8_t>(y);
      const auto* di = d_in.ptr<float>(y);
      const auto* dout = d_out.ptr<float>(y);
      auto* s = sd_.ptr<float>(y);
      for (int x = 0; x < crop_.width; ++x) s[x] = in[x] ? di[x] - 0.5f : 0.5f - dout[x];
    }
  }

  int width() const { return width_; }
  int height() const { return height_; }
  // The silhouette's bounding box and centroid, pixels.
  const cv::Rect& box() const { return box_; }
  const Eigen::Vector2d& centroid() const { return centroid_; }

  // Whether a pixel position lies on the photo (pixel centres at integers).
  bool InImage(double x, double y, double margin = 0.0) const {
    return x >= -0.5 + margin && y >= -0.5 + margin && x <= width_ - 0.5 - margin &&
           y <= height_ - 0.5 - margin;
  }

  // Bilinear signed distance at a pixel position. \pre InImage(x, y).
  double At(double x, double y) const {
    const double cx = x - crop_.x;
    const double cy = y - crop_.y;
    const double max_x = crop_.width - 1;
    const double max_y = crop_.height - 1;
    if (cx < 0.0 || cy < 0.0 || cx > max_x || cy > max_y) {
      // Outside the crop, the silhouette is at least margin_ + (distance to the crop) away.
      const double dx = std::max({0.0, -cx, cx - max_x});
      const double dy = std::max({0.0, -cy, cy - max_y});
      const double outside = std::sqrt(dx * dx + dy * dy);
      if (outside > 0.75) return -(margin_ + outside - 0.5);
    }
    const double px = std::clamp(cx, 0.0, max_x);
    const double py = std::clamp(cy, 0.0, max_y);
    const int x0 = std::min(static_cast<int>(px), crop_.width - 2 < 0 ? 0 : crop_.width - 2);
    const int y0 = std::min(static_cast<int>(py), crop_.height - 2 < 0 ? 0 : crop_.height - 2);
    const int x1 = std::min(x0 + 1, crop_.width - 1);
    const int y1 = std::min(y0 + 1, crop_.height - 1);
    const double wx = std::clamp(px - x0, 0.0, 1.0);
    const double wy = std::clamp(py - y0, 0.0, 1.0);
    const float* r0 = sd_.ptr<float>(y0);
    const float* r1 = sd_.ptr<float>(y1);
    return (1 - wy) * ((1 - wx) * r0[x0] + wx * r0[x1]) + wy * ((1 - wx) * r1[x0] + wx * r1[x1]);
  }

 private:
  int width_ = 0;
  int height_ = 0;
  int margin_ = 0;
  cv::Rect box_;
  Eigen::Vector2d centroid_;
  cv::Rect crop_;
  cv::Mat sd_;
};

struct ViewData {
  const CameraModel* camera = nullptr;
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  double focal_max = 0.0;
  double focal_mean = 0.0;
  std::unique_ptr<DistanceMap> distance;

  void SetCamera(const CameraModel& c) {
    camera = &c;
    rotation = c.cam_from_world.rotation;
    translation = c.cam_from_world.translation;
    focal_max = std::max(c.fx, c.fy);
    focal_mean = 0.5 * (c.fx + c.fy);
  }
};

// Filled discs drawn as cv::circle draws them (8-connected, integer centre and radius), from
// each radius's row spans, found once by drawing one: the priors draw hundreds of thousands of
// discs a few pixels wide, for which cv::circle's per-call overhead is most of the time.
class DiscSpans {
 public:
  // Sets the pixels of a filled disc at `centre` of `radius` to 255 in `image` (CV_8UC1).
  void Fill(cv::Mat& image, cv::Point centre, int radius) {
    if (radius < 0 || radius > kMaxCached) {
      cv::circle(image, centre, radius, cv::Scalar(255), cv::FILLED);
      return;
    }
    const std::vector<cv::Vec2i>& spans = Spans(radius);
    const int top = centre.y - radius;
    const int first = std::max(0, -top);
    const int last = std::min(static_cast<int>(spans.size()), image.rows - top);
    for (int row = first; row < last; ++row) {
      const int x0 = std::max(0, centre.x + spans[static_cast<std::size_t>(row)][0]);
      const int x1 = std::min(image.cols - 1, centre.x + spans[static_cast<std::size_t>(row)][1]);
      if (x0 <= x1) SetRun(image.ptr<std::uint8_t>(top + row) + x0, x1 - x0 + 1);
    }
  }

 private:
  static constexpr int kMaxCached = 64;

  // Sets `width` (>= 1) bytes at `at` to 255: a disc's rows are a few bytes, for which two
  // overlapping word stores beat a call to memset.
  static void SetRun(std::uint8_t* at, int width) {
    if (width > 16) {
      std::memset(at, 255, static_cast<std::size_t>(width));
    } else if (width >= 8) {
      constexpr std::uint64_t kOnes = ~std::uint64_t{0};
      std::memcpy(at, &kOnes, sizeof(kOnes));
      std::memcpy(at + width - 8, &kOnes, sizeof(kOnes));
    } else if (width >= 4) {
      constexpr std::uint32_t kOnes = ~std::uint32_t{0};
      std::memcpy(at, &kOnes, sizeof(kOnes));
      std::memcpy(at + width - 4, &kOnes, sizeof(kOnes));
    } else {
      for (int i = 0; i < width; ++i) at[i] = 255;
    }
  }

  // Per row from the top, the first and last column offsets (first > last: none).
  const std::vector<cv::Vec2i>& Spans(int radius) {
    if (spans_.size() <= static_cast<std::size_t>(radius)) spans_.resize(radius + 1);
    std::vector<cv::Vec2i>& spans = spans_[static_cast<std::size_t>(radius)];
    if (!spans.empty()) return spans;
    const int side = 2 * radius + 3;
    cv::Mat disc(side, side, CV_8UC1, cv::Scalar(0));
    const cv::Point centre(radius + 1, radius + 1);
    cv::circle(disc, centre, radius, cv::Scalar(255), cv::FILLED);
    for (int y = centre.y - radius; y <= centre.y + radius; ++y) {
      cv::Vec2i span(1, 0);
      const auto* row = disc.ptr<std::uint8_t>(y);
      for (int x = 0; x < side; ++x) {
        if (!row[x]) continue;
        if (span[0] > span[1]) span[0] = x - centre.x;
        span[1] = x - centre.x;
      }
      spans.push_back(span);
    }
    return spans;
  }

  std::vector<std::vector<cv::Vec2i>> spans_;
};

enum class CellClass { kOut, kIn, kAmbiguous };

class Carver {
 public:
  explicit Carver(const std::vector<ViewData>& views) : views_(views) {}

  // Decides a cube (centre, half edge) against all views.
  CellClass Classify(const Eigen::Vector3d& centre, double half) const {
    const double rho = half * std::sqrt(3.0);
    bool seen = false;
    bool ambiguous = false;
    for (const ViewData& view : views_) {
      const Eigen::Vector3d p = view.rotation * centre + view.translation;
      if (p.z() - rho <= kNearM) {
        ambiguous = true;
        continue;
      }
      const Eigen::Vector2d pixel = view.camera->ProjectFromCam(p);
      const double r = view.focal_max * rho / (p.z() - rho) * kFootprintSlack + 1.0;
      const DistanceMap& dm = *view.distance;
      if (!dm.InImage(pixel.x(), pixel.y(), -r)) continue;  // footprint off the photo: unknown
      seen = true;
      if (!dm.InImage(pixel.x(), pixel.y())) {
        ambiguous = true;
        continue;
      }
      const double sd = dm.At(pixel.x(), pixel.y());
      if (sd < -r) {
        if (dm.InImage(pixel.x(), pixel.y(), r)) return CellClass::kOut;
        ambiguous = true;
      } else if (sd <= r) {
        ambiguous = true;
      }
    }
    if (ambiguous) return CellClass::kAmbiguous;
    return seen ? CellClass::kIn : CellClass::kOut;
  }

  // The hull's field at a point: metres, positive inside. `unseen` is returned when no view
  // sees the point.
  double Field(const Eigen::Vector3d& x, double unseen) const {
    double best = std::numeric_limits<double>::infinity();
    for (const ViewData& view : views_) {
      const Eigen::Vector3d p = view.rotation * x + view.translation;
      if (p.z() <= kNearM) continue;
      const Eigen::Vector2d pixel = view.camera->ProjectFromCam(p);
      const DistanceMap& dm = *view.distance;
      if (!dm.InImage(pixel.x(), pixel.y())) continue;
      best = std::min(best, dm.At(pixel.x(), pixel.y()) * p.z() / view.focal_mean);
    }
    return std::isfinite(best) ? best : unseen;
  }

  // Per view: +1 inside the silhouette, -1 outside, 0 off the photo. With a radius (metres),
  // -1 only when the whole ball's footprint is outside (a part thinner than the ball is not
  // missed between sample points).
  int PointState(std::size_t v, const Eigen::Vector3d& x, double radius = 0.0) const {
    const ViewData& view = views_[v];
    const Eigen::Vector3d p = view.rotation * x + view.translation;
    if (p.z() - radius <= kNearM) return 0;
    const Eigen::Vector2d pixel = view.camera->ProjectFromCam(p);
    if (!view.distance->InImage(pixel.x(), pixel.y())) return 0;
    const double reach = radius > 0.0 ? view.focal_max * radius / (p.z() - radius) + 1.0 : 0.0;
    return view.distance->At(pixel.x(), pixel.y()) > -reach ? 1 : -1;
  }

 private:
  const std::vector<ViewData>& views_;
};

// Least-squares point closest to a set of rays (origin, unit direction).
Eigen::Vector3d ClosestPointToRays(const std::vector<Ray>& rays) {
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const Ray& ray : rays) {
    const Eigen::Matrix3d m =
        Eigen::Matrix3d::Identity() - ray.direction * ray.direction.transpose();
    a += m;
    b += m * ray.origin;
  }
  return a.ldlt().solve(b);
}

// Where hull errors point: the folder of the silhouettes, or a description of in-memory masks.
std::filesystem::path MasksLocation(const std::vector<View>& views) {
  for (const View& view : views)
    if (!view.mask_path().empty()) return view.mask_path().parent_path();
  return "silhouettes (in memory)";
}

// The finest grid: corner (i, j, k) lies at origin + voxel * (i, j, k).
struct GridFrame {
  Eigen::Vector3d origin;
  double voxel = 0.0;
  Eigen::Vector3i grid{0, 0, 0};  // finest voxels per axis
  Eigen::AlignedBox3d box;        // origin .. origin + voxel * grid
  bool on_floor = false;
  double floor_z = 0.0;
};

struct Contour {
  Mesh mesh;
  std::size_t corners = 0;
  std::size_t components_dropped = 0;
  std::size_t faces_dropped = 0;
};

// Contours the hull's field over `cells` (octree cells of edge 2^level voxels, in that level's
// integer coordinates) by marching tetrahedra: the field at the cells' corners, a vertex per
// edge that changes sign, triangles oriented from inside to outside; keeps the largest
// component. The mesh is empty when no cell crosses the surface.
Contour ContourCells(const std::vector<Eigen::Vector3i>& cells, int level, const GridFrame& frame,
                     const Carver& carver, int threads, Progress& progress) {
  Contour result;
  const int step = 1 << level;
  const double size = frame.voxel * step;
  const std::uint64_t nx = static_cast<std::uint64_t>(frame.grid.x()) + 1;
  const std::uint64_t ny = static_cast<std::uint64_t>(frame.grid.y()) + 1;
  // Keys of corners in the finest grid, so that edge keys are unique within a level.
  auto corner_key = [&](const Eigen::Vector3i& cell, int d) {
    const std::uint64_t i = static_cast<std::uint64_t>(cell.x() + (d & 1)) * step;
    const std::uint64_t j = static_cast<std::uint64_t>(cell.y() + ((d >> 1) & 1)) * step;
    const std::uint64_t k = static_cast<std::uint64_t>(cell.z() + ((d >> 2) & 1)) * step;
    return i + nx * (j + ny * k);
  };
  auto corner_position = [&](std::uint64_t key) {
    const std::uint64_t i = key % nx;
    const std::uint64_t j = (key / nx) % ny;
    const std::uint64_t k = key / (nx * ny);
    return Eigen::Vector3d(frame.origin + frame.voxel * Eigen::Vector3d(static_cast<double>(i),
                                                                        static_cast<double>(j),
                                                                        static_cast<double>(k)));
  };
  std::vector<std::uint64_t> corners;
  corners.reserve(cells.size() * 8);
  for (const Eigen::Vector3i& c : cells)
    for (int d = 0; d < 8; ++d) corners.push_back(corner_key(c, d));
  std::sort(corners.begin(), corners.end());
  corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
  result.corners = corners.size();
  std::vector<double> field(corners.size());
  ParallelFor(corners.size(), 8192, threads, [&](std::size_t begin, std::size_t end) {
    progress.CheckCancelled();
    for (std::size_t i = begin; i < end; ++i) {
      const Eigen::Vector3d x = corner_position(corners[i]);
      double f = carver.Field(x, -size);
      // Closed at the grid's border (and at the floor, the grid's bottom when there is one).
      f = std::min({f, (x - frame.box.min()).minCoeff() - 0.5 * frame.voxel,
                    (frame.box.max() - x).minCoeff() - 0.5 * frame.voxel});
      if (frame.on_floor) f = std::min(f, x.z() - frame.floor_z);
      if (f == 0.0) f = -1e-9 * frame.voxel;  // the zero set stays off the corners
      field[i] = f;
    }
  });
  progress.Report(0.5);
  auto lookup = [&](std::uint64_t key) {
    const auto it = std::lower_bound(corners.begin(), corners.end(), key);
    return static_cast<std::size_t>(it - corners.begin());
  };
  // Per chunk of cells: vertex entries (edge key = corner key * 8 + direction code, position)
  // made once per cell edge, and triangles over the chunk's entries, oriented outwards.
  struct Chunk {
    std::vector<std::uint64_t> keys;
    std::vector<Eigen::Vector3d> positions;
    std::vector<std::array<std::uint32_t, 3>> triangles;
  };
  const std::size_t chunk_size = 16384;
  std::vector<Chunk> chunks((cells.size() + chunk_size - 1) / chunk_size);
  ParallelFor(cells.size(), chunk_size, threads, [&](std::size_t begin, std::size_t end) {
    progress.CheckCancelled();
    Chunk& chunk = chunks[begin / chunk_size];
    for (std::size_t s = begin; s < end; ++s) {
      std::array<std::uint64_t, 8> key{};
      std::array<double, 8> value{};
      std::array<Eigen::Vector3d, 8> position;
      for (int d = 0; d < 8; ++d) {
        key[d] = corner_key(cells[s], d);
        value[d] = field[lookup(key[d])];
        position[d] = corner_position(key[d]);
      }
      std::array<std::uint32_t, 64> made;  // entry per cell edge (a * 8 + b), or none
      made.fill(std::numeric_limits<std::uint32_t>::max());
      auto edge = [&](int a, int b) {
        if (a > b) std::swap(a, b);  // corner b has coordinates >= corner a
        std::uint32_t& entry = made[a * 8 + b];
        if (entry != std::numeric_limits<std::uint32_t>::max()) return entry;
        const std::uint64_t code = static_cast<std::uint64_t>(b - a);  // 1..7, unique per offset
        // Clamped away from the corners: no coincident vertices, no zero-area triangles.
        const double t = std::clamp(value[a] / (value[a] - value[b]), 1e-3, 1.0 - 1e-3);
        entry = static_cast<std::uint32_t>(chunk.keys.size());
        chunk.keys.push_back(key[a] * 8 + code);
        chunk.positions.push_back(position[a] + t * (position[b] - position[a]));
        return entry;
      };
      MarchCube(value, position,
                [&](const std::array<std::array<int, 2>, 3>& edges,
                    const Eigen::Vector3d& towards_outside) {
                  std::uint32_t e0 = edge(edges[0][0], edges[0][1]);
                  std::uint32_t e1 = edge(edges[1][0], edges[1][1]);
                  std::uint32_t e2 = edge(edges[2][0], edges[2][1]);
                  const Eigen::Vector3d n = (chunk.positions[e1] - chunk.positions[e0])
                                                .cross(chunk.positions[e2] - chunk.positions[e0]);
                  if (n.dot(towards_outside) < 0.0) std::swap(e1, e2);
                  chunk.triangles.push_back({e0, e1, e2});
                });
    }
  });
  // Merge: one vertex per edge key (entries sorted by key), triangles renumbered.
  std::vector<std::size_t> offset(chunks.size() + 1, 0);
  for (std::size_t c = 0; c < chunks.size(); ++c) offset[c + 1] = offset[c] + chunks[c].keys.size();
  std::vector<std::pair<std::uint64_t, std::uint32_t>> entries(offset.back());
  for (std::size_t c = 0; c < chunks.size(); ++c)
    for (std::size_t i = 0; i < chunks[c].keys.size(); ++i)
      entries[offset[c] + i] = {chunks[c].keys[i], static_cast<std::uint32_t>(offset[c] + i)};
  std::sort(entries.begin(), entries.end());
  std::vector<int> vertex_of(entries.size());
  std::vector<Eigen::Vector3d> vertices;
  vertices.reserve(entries.size() / 2);
  auto position_of = [&](std::uint32_t entry) -> const Eigen::Vector3d& {
    const std::size_t c =
        static_cast<std::size_t>(std::upper_bound(offset.begin(), offset.end(), entry) -
                                 offset.begin()) -
        1;
    return chunks[c].positions[entry - offset[c]];
  };
  for (std::size_t i = 0; i < entries.size(); ++i) {
    if (i == 0 || entries[i].first != entries[i - 1].first)
      vertices.push_back(position_of(entries[i].second));
    vertex_of[entries[i].second] = static_cast<int>(vertices.size()) - 1;
  }
  entries = {};
  std::vector<std::array<int, 3>> triangles;
  std::size_t n_triangles = 0;
  for (const Chunk& chunk : chunks) n_triangles += chunk.triangles.size();
  triangles.reserve(n_triangles);
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    for (const auto& t : chunks[c].triangles)
      triangles.push_back(
          {vertex_of[offset[c] + t[0]], vertex_of[offset[c] + t[1]], vertex_of[offset[c] + t[2]]});
    chunks[c] = Chunk();
  }
  progress.Report(0.8);

  // Largest component (union-find over vertices), then the OpenMesh mesh.
  std::vector<int> parent(vertices.size());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) {
      parent[x] = parent[parent[x]];
      x = parent[x];
    }
    return x;
  };
  for (const auto& t : triangles) {
    const int a = find(t[0]);
    parent[find(t[1])] = a;
    parent[find(t[2])] = a;
  }
  std::vector<std::size_t> faces_per_root(vertices.size(), 0);
  for (const auto& t : triangles) ++faces_per_root[find(t[0])];
  const auto largest =
      std::max_element(faces_per_root.begin(), faces_per_root.end()) - faces_per_root.begin();
  for (std::size_t r = 0; r < faces_per_root.size(); ++r)
    if (faces_per_root[r] > 0 && static_cast<std::ptrdiff_t>(r) != largest) {
      ++result.components_dropped;
      result.faces_dropped += faces_per_root[r];
    }
  if (triangles.empty()) return result;
  std::vector<int> remap(vertices.size(), -1);
  Mesh& mesh = result.mesh;
  mesh.reserve(vertices.size(), 3 * triangles.size() / 2, triangles.size());
  for (const auto& t : triangles) {
    if (find(t[0]) != largest) continue;
    std::array<Mesh::VertexHandle, 3> handles;
    for (int k = 0; k < 3; ++k) {
      if (remap[t[k]] < 0) {
        const auto& p = vertices[t[k]];
        remap[t[k]] = mesh.add_vertex(Mesh::Point(p.x(), p.y(), p.z())).idx();
      }
      handles[k] = Mesh::VertexHandle(remap[t[k]]);
    }
    const auto face = mesh.add_face(handles[0], handles[1], handles[2]);
    CAROUSEL_CHECK(face.is_valid(), "marching tetrahedra produced a non-manifold triangle");
  }
  mesh.RecomputeNormals();
  return result;
}

// The region to carve: a cube around the point nearest the rays through the silhouettes'
// centroids, large enough for every silhouette's box, cut at the floor.
// \throw FormatError for inconsistent calibrations.
Eigen::AlignedBox3d CarvingRegion(const std::vector<View>& views, const std::vector<ViewData>& data,
                                  const VisualHullOptions& options) {
  std::vector<Ray> rays;
  double half_extent = 0.0;
  for (std::size_t i = 0; i < views.size(); ++i) {
    const auto ray = data[i].camera->RayThrough(data[i].distance->centroid());
    CAROUSEL_CHECK(ray.has_value(), "no ray through the centroid of " << views[i].name());
    rays.push_back(*ray);
  }
  const Eigen::Vector3d centre = ClosestPointToRays(rays);
  for (std::size_t i = 0; i < views.size(); ++i) {
    const cv::Rect& box = data[i].distance->box();
    const CameraModel& camera = *data[i].camera;
    const Eigen::Vector3d p =
        camera.cam_from_world.rotation * centre + camera.cam_from_world.translation;
    if (p.z() <= kNearM)
      throw FormatError(MasksLocation(views),
                        views[i].name() +
                            ": the silhouettes' common centre lies behind this "
                            "camera; the views' calibration is inconsistent");
    const auto c = camera.ProjectFromCam(p);
    double extent_px = 0.0;
    for (const auto& corner : {cv::Point2d(box.x, box.y), cv::Point2d(box.br().x, box.y),
                               cv::Point2d(box.x, box.br().y), cv::Point2d(box.br())})
      extent_px = std::max(extent_px, std::hypot(corner.x - c.x(), corner.y - c.y()));
    half_extent = std::max(half_extent, 1.3 * extent_px * p.z() / data[i].focal_mean);
  }
  Eigen::AlignedBox3d region(centre - Eigen::Vector3d::Constant(half_extent),
                             centre + Eigen::Vector3d::Constant(half_extent));
  if (options.use_floor) {
    if (region.max().z() <= options.floor_z_m)
      throw FormatError(
          MasksLocation(views),
          "the silhouettes meet below the floor (z = " + std::to_string(options.floor_z_m) +
              " m); the views' calibration does not match the rig");
    region.min().z() = std::max(region.min().z(), options.floor_z_m);
  }
  return region;
}

}  // namespace

const OptionTable<VisualHullOptions>& VisualHullOptions::Fields() {
  using O = VisualHullOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::voxel_size_m, {.name = "voxel-size-m",
                             .help = "hull voxel edge length",
                             .unit = "m",
                             .min = 0,
                             .min_exclusive = true,
                             .special = 0,
                             .special_meaning = "from --resolution or --voxel-px"});
    t.Add(&O::resolution, {.name = "resolution",
                           .help = "hull voxels along the object's longest side",
                           .min = 16,
                           .max = 4096,
                           .special = 0,
                           .special_meaning = "from --voxel-px"});
    t.Add(&O::voxel_px,
          {.name = "voxel-px",
           .help = "hull voxel size in pixels of the sharpest view, when no --resolution ...",
           .unit = "px",
           .min = 0,
           .min_exclusive = true});
    t.Add(&O::max_resolution,
          {.name = "max-resolution",
           .help = "... but at most this many voxels along the object's longest side",
           .min = 16,
           .max = 4096});
    t.Add(&O::use_floor,
          {.name = "floor", .help = "the object stands on the plate: nothing below the floor"});
    t.Add(&O::floor_z_m,
          {.name = "floor-z-m", .help = "height of the floor", .unit = "m", .advanced = true});
    t.Add(&O::min_view_consistency,
          {.name = "min-view-consistency",
           .help = "a view keeping less of the other views' hull than this is inconsistent",
           .min = 0,
           .max = 1,
           .advanced = true});
    t.Add(&O::max_surface_cells, {.name = "max-surface-cells",
                                  .help = "largest surface a hull may need (memory guard)",
                                  .unit = "cells",
                                  .min = 1000,
                                  .advanced = true});
    t.Add(&O::proxy_max_faces,
          {.name = "proxy-max-faces",
           .help = "hulls with more faces get a coarser proxy as the mesh optimization's input",
           .unit = "faces",
           .min = 10000,
           .special = 0,
           .special_meaning = "never",
           .advanced = true});
    return t;
  }();
  return table;
}

void VisualHullOptions::Validate() const {
  Fields().Check(*this);
  CAROUSEL_THROW_IF(threads < 0, InvalidArgument, "VisualHullOptions.threads must be >= 0");
}

VisualHullResult ComputeVisualHull(const std::vector<View>& views, const VisualHullOptions& options,
                                   Progress& progress) {
  options.Validate();
  CAROUSEL_THROW_IF(views.size() < 2, InvalidArgument,
                    "a visual hull needs at least 2 views (got " << views.size() << ")");
  VisualHullResult result;
  const int threads = ResolveThreadCount(options.threads);

  // --- distance transforms of the silhouettes ------------------------------------------------
  progress.BeginStage("visual hull: distance maps");
  Stopwatch stopwatch;
  std::vector<ViewData> data(views.size());
  std::vector<std::string> empty_views;
  std::mutex empty_mutex;
  std::atomic<std::size_t> done{0};
  ParallelFor(views.size(), 1, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      progress.CheckCancelled();
      const View& view = views[i];
      CAROUSEL_THROW_IF(!view.HasMask(), InvalidArgument,
                        view.name() << ": no silhouette (run the silhouette step first)");
      view.camera().Validate();
      const cv::Mat mask = view.Mask();
      ViewData& d = data[i];
      d.SetCamera(view.camera());
      if (cv::countNonZero(mask >= 128) == 0) {  // collected, to name every empty view
        std::lock_guard<std::mutex> lock(empty_mutex);
        empty_views.push_back(view.name());
      } else {
        d.distance = std::make_unique<DistanceMap>(mask, view.name());
      }
      progress.Report(++done, views.size());
    }
  });
  if (!empty_views.empty()) {
    std::sort(empty_views.begin(), empty_views.end());
    std::ostringstream names;
    for (std::size_t i = 0; i < empty_views.size(); ++i) names << (i ? ", " : "") << empty_views[i];
    throw FormatError(
        MasksLocation(views),
        std::to_string(empty_views.size()) +
            " view(s) have an empty silhouette (the object is not seen): " + names.str());
  }
  progress.EndStage();
  result.seconds_distance = stopwatch.ElapsedSeconds();
  const Carver carver(data);

  // --- the region to carve ---------------------------------------------------------------------
  const Eigen::AlignedBox3d region = CarvingRegion(views, data, options);

  // --- view consistency (coarse) and the object's bounding box ---------------------------------
  progress.BeginStage("visual hull: carving");
  stopwatch.Restart();
  const std::size_t n_views = views.size();
  const Eigen::Vector3d coarse_step = region.sizes() / kConsistencyGrid;
  std::vector<std::size_t> others_hull(n_views, 0), kept(n_views, 0);
  Eigen::AlignedBox3d object_box;
  std::size_t hull_points = 0;
  {
    std::mutex merge;
    ParallelFor(static_cast<std::size_t>(kConsistencyGrid), 1, threads,
                [&](std::size_t begin, std::size_t end) {
                  std::vector<std::size_t> local_others(n_views, 0), local_kept(n_views, 0);
                  std::vector<int> state(n_views);
                  Eigen::AlignedBox3d local_box;
                  std::size_t local_points = 0;
                  for (std::size_t k = begin; k < end; ++k) {
                    for (int j = 0; j < kConsistencyGrid; ++j) {
                      for (int i = 0; i < kConsistencyGrid; ++i) {
                        const Eigen::Vector3d x =
                            region.min() + coarse_step.cwiseProduct(Eigen::Vector3d(
                                               i + 0.5, j + 0.5, static_cast<double>(k) + 0.5));
                        int outside = 0;
                        int seen = 0;
                        std::size_t last_outside = 0;
                        for (std::size_t v = 0; v < n_views; ++v) {
                          state[v] = carver.PointState(v, x);
                          if (state[v] < 0) {
                            ++outside;
                            last_outside = v;
                          }
                          if (state[v] != 0) ++seen;
                        }
                        if (seen == 0) continue;
                        if (outside == 0) {
                          ++local_points;
                          local_box.extend(x);
                          for (std::size_t v = 0; v < n_views; ++v) {
                            ++local_others[v];
                            ++local_kept[v];
                          }
                        } else if (outside == 1) {
                          ++local_others[last_outside];
                        }
                      }
                    }
                  }
                  std::lock_guard<std::mutex> lock(merge);
                  for (std::size_t v = 0; v < n_views; ++v) {
                    others_hull[v] += local_others[v];
                    kept[v] += local_kept[v];
                  }
                  object_box.extend(local_box);
                  hull_points += local_points;
                });
  }
  result.view_consistency.resize(n_views, 1.0);
  std::vector<std::size_t> inconsistent;
  for (std::size_t v = 0; v < n_views; ++v) {
    if (others_hull[v] > 0)
      result.view_consistency[v] = static_cast<double>(kept[v]) / others_hull[v];
    if (n_views >= 4 && result.view_consistency[v] < options.min_view_consistency)
      inconsistent.push_back(v);
  }
  if (hull_points == 0 || !inconsistent.empty()) {
    std::vector<std::size_t> order(n_views);
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return result.view_consistency[a] < result.view_consistency[b];
    });
    if (inconsistent.empty())
      inconsistent.assign(order.begin(), order.begin() + std::min<std::size_t>(3, n_views));
    std::ostringstream message;
    message << (hull_points == 0 ? "the visual hull vanishes: the silhouettes have no common volume"
                                 : "the silhouettes do not agree")
            << "; views inconsistent with the others (wrong camera pose or mask):";
    for (std::size_t i = 0; i < inconsistent.size(); ++i) {
      const std::size_t v = inconsistent[i];
      message << (i ? ", " : " ") << views[v].name() << " (keeps "
              << static_cast<int>(std::round(100.0 * result.view_consistency[v]))
              << "% of the others' hull)";
    }
    throw InconsistentViews(MasksLocation(views), message.str(), inconsistent);
  }
  // Grow by a coarse cell (points are cell centres) and clamp to the region.
  object_box.min() -= coarse_step;
  object_box.max() += coarse_step;
  object_box = object_box.intersection(region);

  // --- voxel size and grid ---------------------------------------------------------------------
  double voxel = options.voxel_size_m;
  const double longest = object_box.sizes().maxCoeff();
  if (voxel <= 0.0 && options.resolution > 0) voxel = longest / options.resolution;
  if (voxel <= 0.0) {
    double finest = std::numeric_limits<double>::infinity();  // metres per pixel
    const Eigen::Vector3d middle = object_box.center();
    for (const ViewData& d : data) {
      const double z = (d.rotation * middle + d.translation).z();
      if (z > kNearM) finest = std::min(finest, z / d.focal_max);
    }
    voxel = std::max(options.voxel_px * finest, longest / options.max_resolution);
  }
  int levels = 0;
  while (longest / (voxel * (1 << levels)) > kRootCells) ++levels;
  const double root_size = voxel * (1 << levels);
  Eigen::Vector3i roots;  // root cells per axis
  for (int a = 0; a < 3; ++a)
    roots[a] = std::max(1, static_cast<int>(std::ceil(object_box.sizes()[a] / root_size)));
  const Eigen::Vector3d origin = object_box.center() - 0.5 * root_size * roots.cast<double>();
  Eigen::Vector3d grid_origin = origin;
  // Standing on the floor: the floor lies midway between two corner layers, so the bottom is
  // contoured exactly at the floor, never through a corner.
  const bool on_floor = options.use_floor && object_box.min().z() <= options.floor_z_m + voxel;
  if (on_floor) {
    grid_origin.z() = options.floor_z_m - 0.5 * voxel;
    roots.z() = std::max(
        1, static_cast<int>(std::ceil((object_box.max().z() - grid_origin.z()) / root_size)));
  }
  result.voxel_size_m = voxel;
  result.grid = roots * (1 << levels);
  result.box = Eigen::AlignedBox3d(grid_origin, grid_origin + voxel * result.grid.cast<double>());
  CAROUSEL_LOG_INFO("visual hull: voxel " << voxel * 1e3 << " mm, grid " << result.grid.x() << "x"
                                          << result.grid.y() << "x" << result.grid.z() << ", "
                                          << levels + 1 << " octree levels");

  // --- octree carving, level by level ----------------------------------------------------------
  using Cell = Eigen::Vector3i;
  std::vector<Cell> cells;
  for (int k = 0; k < roots.z(); ++k)
    for (int j = 0; j < roots.y(); ++j)
      for (int i = 0; i < roots.x(); ++i) cells.emplace_back(i, j, k);
  std::vector<std::vector<Cell>> ambiguous(levels + 1);  // per level, the cells split further
  for (int level = levels; level >= 0; --level) {
    const double size = voxel * (1 << level);
    std::vector<std::uint8_t> decision(cells.size());
    ParallelFor(cells.size(), 4096, threads, [&](std::size_t begin, std::size_t end) {
      progress.CheckCancelled();
      for (std::size_t c = begin; c < end; ++c) {
        const Eigen::Vector3d centre_c =
            grid_origin + size * (cells[c].cast<double>() + Eigen::Vector3d::Constant(0.5));
        CellClass decided = carver.Classify(centre_c, 0.5 * size);
        // Cells on the grid's border are never full: the surface must close there.
        const Eigen::Vector3i low = cells[c] * (1 << level);
        const Eigen::Vector3i high = low + Eigen::Vector3i::Constant(1 << level);
        if (decided == CellClass::kIn &&
            ((low.array() == 0).any() || (high.array() >= result.grid.array()).any()))
          decided = CellClass::kAmbiguous;
        decision[c] = static_cast<std::uint8_t>(decided);
      }
    });
    std::vector<Cell> next;
    for (std::size_t c = 0; c < cells.size(); ++c) {
      if (decision[c] != static_cast<std::uint8_t>(CellClass::kAmbiguous)) continue;
      ambiguous[level].push_back(cells[c]);
      if (level == 0) continue;
      for (int d = 0; d < 8; ++d)
        next.emplace_back(2 * cells[c].x() + (d & 1), 2 * cells[c].y() + ((d >> 1) & 1),
                          2 * cells[c].z() + ((d >> 2) & 1));
    }
    CAROUSEL_THROW_IF(next.size() > 8 * options.max_surface_cells ||
                          ambiguous[0].size() > options.max_surface_cells,
                      InvalidArgument,
                      "the visual hull at " << voxel * 1e3 << " mm voxels needs more than "
                                            << options.max_surface_cells
                                            << " surface cells; choose a coarser resolution");
    cells.swap(next);
    progress.Report(static_cast<double>(levels - level + 1) / (levels + 1));
  }
  const std::vector<Cell>& surface = ambiguous[0];
  result.surface_cells = surface.size();
  progress.EndStage();
  result.seconds_carve = stopwatch.ElapsedSeconds();

  // --- the surface: field at the corners, marching tetrahedra ----------------------------------
  progress.BeginStage("visual hull: surface");
  stopwatch.Restart();
  GridFrame frame;
  frame.origin = grid_origin;
  frame.voxel = voxel;
  frame.grid = result.grid;
  frame.box = result.box;
  frame.on_floor = on_floor;
  frame.floor_z = options.floor_z_m;
  Contour contour = ContourCells(surface, 0, frame, carver, threads, progress);
  if (contour.mesh.n_faces() == 0)
    throw FormatError(MasksLocation(views), "the visual hull has no surface at " +
                                                std::to_string(voxel * 1e3) +
                                                " mm voxels (the object is thinner than a voxel)");
  result.mesh = std::move(contour.mesh);
  result.corners_evaluated = contour.corners;
  result.components_dropped = contour.components_dropped;
  result.faces_dropped = contour.faces_dropped;
  result.volume_m3 = SignedVolume(result.mesh);
  // A coarser contour of the same field, for the mesh optimization of a large hull.
  if (options.proxy_max_faces > 0 && result.mesh.n_faces() > options.proxy_max_faces) {
    const double faces_per_cell =
        static_cast<double>(result.mesh.n_faces()) / static_cast<double>(surface.size());
    int level = 1;
    while (level<levels&& static_cast<double>(ambiguous[level].size()) *
                 faces_per_cell> static_cast<double>(options.proxy_max_faces))
      ++level;
    if (level <= levels && !ambiguous[level].empty()) {
      Contour coarse = ContourCells(ambiguous[level], level, frame, carver, threads, progress);
      if (coarse.mesh.n_faces() > 0) {
        result.proxy = std::move(coarse.mesh);
        result.proxy_level = level;
      }
    }
  }
  progress.EndStage();
  result.seconds_surface = stopwatch.ElapsedSeconds();
  if (result.components_dropped > 0)
    CAROUSEL_LOG_INFO("visual hull: dropped " << result.components_dropped << " small pieces ("
                                              << result.faces_dropped << " faces)");
  return result;
}

std::vector<cv::Mat> OthersHullPriors(const std::vector<View>& views,
                                      const std::vector<cv::Mat>& masks,
                                      const VisualHullOptions& options) {
  CAROUSEL_THROW_IF(
      masks.size() != views.size(), InvalidArgument,
      "OthersHullPriors: " << masks.size() << " masks for " << views.size() << " views");
  const std::size_t n = views.size();
  const int threads = ResolveThreadCount(options.threads);
  // Masks and cameras at a working resolution: the grid is coarse.
  std::vector<CameraModel> cameras(n);
  std::vector<ViewData> data(n);
  std::vector<double> scales(n, 1.0);
  ParallelFor(n, 1, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t v = begin; v < end; ++v) {
      const cv::Mat& mask = masks[v];
      CAROUSEL_THROW_IF(mask.type() != CV_8UC1 || mask.cols != views[v].camera().width ||
                            mask.rows != views[v].camera().height,
                        InvalidArgument,
                        views[v].name() << ": the mask does not match the camera's image size");
      scales[v] = std::min(1.0, kPriorSize / std::max(mask.cols, mask.rows));
      cameras[v] = scales[v] < 1.0 ? views[v].camera().Scaled(scales[v]) : views[v].camera();
      // Sampled at the pixel centres (an area average reads all of an 18-Mpx mask, and the
      // grid is coarser than either).
      cv::Mat small = mask;
      if (scales[v] < 1.0)
        cv::resize(mask, small, cv::Size(cameras[v].width, cameras[v].height), 0, 0,
                   cv::INTER_NEAREST_EXACT);
      data[v].SetCamera(cameras[v]);
      if (cv::countNonZero(small >= 128) > 0)
        data[v].distance = std::make_unique<DistanceMap>(small, views[v].name());
    }
  });
  for (std::size_t v = 0; v < n; ++v)
    if (!data[v].distance) return {};  // an empty silhouette: the hull names it
  const Eigen::AlignedBox3d carved = CarvingRegion(views, data, options);
  // The grid spans the others' hull's box (coarse cells that may be inside every silhouette
  // but one, grown by a coarse step), not the whole carved region: finer cells for the same
  // count.
  Eigen::AlignedBox3d region;
  {
    const Carver carver(data);
    const Eigen::Vector3d coarse = carved.sizes() / kConsistencyGrid;
    const double reach = 0.5 * coarse.norm();  // a coarse cell's circumscribed radius
    std::mutex merge;
    ParallelFor(static_cast<std::size_t>(kConsistencyGrid), 1, threads,
                [&](std::size_t begin, std::size_t end) {
                  Eigen::AlignedBox3d local;
                  for (std::size_t k = begin; k < end; ++k)
                    for (int j = 0; j < kConsistencyGrid; ++j)
                      for (int i = 0; i < kConsistencyGrid; ++i) {
                        const Eigen::Vector3d x =
                            carved.min() + coarse.cwiseProduct(Eigen::Vector3d(
                                               i + 0.5, j + 0.5, static_cast<double>(k) + 0.5));
                        int outside = 0;
                        for (std::size_t v = 0; v < n && outside < 2; ++v)
                          outside += carver.PointState(v, x, reach) < 0 ? 1 : 0;
                        if (outside < 2) local.extend(x);  // in the hull of all but one view
                      }
                  std::lock_guard<std::mutex> lock(merge);
                  region.extend(local);
                });
    if (region.isEmpty()) return {};  // no common volume: the hull names the views
    region.min() -= 2.0 * coarse;
    region.max() += 2.0 * coarse;
    region = region.intersection(carved);
  }
  const Eigen::Vector3d step = region.sizes() / kPriorGrid;
  const double rho = 0.5 * step.norm();  // a cell's circumscribed radius
  const double inner = 0.5 * step.minCoeff();
  // Per cell and view: wholly outside (the silhouette carves it), or wholly inside.
  const int cells_per_axis = kPriorGrid;
  const std::size_t cells =
      static_cast<std::size_t>(cells_per_axis) * cells_per_axis * cells_per_axis;
  std::vector<std::uint16_t> outside(cells, 0), not_inside(cells, 0);
  auto cell_centre = [&](std::size_t c) {
    const std::size_t i = c % cells_per_axis;
    const std::size_t j = (c / cells_per_axis) % cells_per_axis;
    const std::size_t k = c / (static_cast<std::size_t>(cells_per_axis) * cells_per_axis);
    return Eigen::Vector3d(region.min() + step.cwiseProduct(Eigen::Vector3d(
                                              i + 0.5, j + 0.5, static_cast<double>(k) + 0.5)));
  };
  // Per cell, the view it fails when it fails one: a cell failing two is outside every other
  // view's hull anyway.
  std::vector<std::int16_t> only_outside(cells, -1), only_not_inside(cells, -1);
  // First per block of cells and view: wholly outside (each of its cells is), wholly inside
  // (none of its cells is outside or on the outline), or to be looked at cell by cell (it
  // straddles the outline, lies off the photo or too near the camera). Most of the grid is
  // decided here.
  enum BlockState : std::uint8_t { kStraddles, kBlockOutside, kBlockInside };
  const int blocks_per_axis = cells_per_axis / kPriorBlock;
  const std::size_t blocks =
      static_cast<std::size_t>(blocks_per_axis) * blocks_per_axis * blocks_per_axis;
  const double block_rho = kPriorBlockSlack * kPriorBlock * rho;
  std::vector<std::uint8_t> block_state(blocks * n, kStraddles);
  ParallelFor(blocks, 64, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t b = begin; b < end; ++b) {
      const std::size_t bi = b % blocks_per_axis;
      const std::size_t bj = (b / blocks_per_axis) % blocks_per_axis;
      const std::size_t bk = b / (static_cast<std::size_t>(blocks_per_axis) * blocks_per_axis);
      const Eigen::Vector3d x =
          region.min() + kPriorBlock * step.cwiseProduct(Eigen::Vector3d(
                                           bi + 0.5, bj + 0.5, static_cast<double>(bk) + 0.5));
      for (std::size_t v = 0; v < n; ++v) {
        const ViewData& d = data[v];
        const Eigen::Vector3d p = d.rotation * x + d.translation;
        if (p.z() - block_rho <= kNearM) continue;
        const Eigen::Vector2d pixel = d.camera->ProjectFromCam(p);
        const double r = d.focal_max * block_rho / (p.z() - block_rho) + 1.0;
        const DistanceMap& dm = *d.distance;
        if (!dm.InImage(pixel.x(), pixel.y(), r)) continue;
        const double sd = dm.At(pixel.x(), pixel.y());
        if (sd < -r) block_state[b * n + v] = kBlockOutside;
        if (sd > r) block_state[b * n + v] = kBlockInside;
      }
    }
  });
  ParallelFor(cells, 4096, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t c = begin; c < end; ++c) {
      const Eigen::Vector3d x = cell_centre(c);
      const std::size_t i = c % cells_per_axis;
      const std::size_t j = (c / cells_per_axis) % cells_per_axis;
      const std::size_t k = c / (static_cast<std::size_t>(cells_per_axis) * cells_per_axis);
      const std::size_t b =
          (i / kPriorBlock) +
          blocks_per_axis * ((j / kPriorBlock) + blocks_per_axis * (k / kPriorBlock));
      const std::uint8_t* decided = &block_state[b * n];
      // Once two views carve the cell it is outside every view's others' hull.
      for (std::size_t v = 0; v < n && outside[c] < 2; ++v) {
        if (decided[v] == kBlockInside) continue;
        if (decided[v] == kBlockOutside) {
          ++outside[c];
          only_outside[c] = static_cast<std::int16_t>(v);
          ++not_inside[c];
          only_not_inside[c] = static_cast<std::int16_t>(v);
          continue;
        }
        const ViewData& d = data[v];
        const Eigen::Vector3d p = d.rotation * x + d.translation;
        if (p.z() - rho <= kNearM) continue;  // unknown
        const Eigen::Vector2d pixel = d.camera->ProjectFromCam(p);
        const DistanceMap& dm = *d.distance;
        if (!dm.InImage(pixel.x(), pixel.y())) continue;  // off the photo: unknown
        const double r = d.focal_max * rho / (p.z() - rho) + 1.0;
        const double sd = dm.At(pixel.x(), pixel.y());
        if (sd < -r) {
          ++outside[c];
          only_outside[c] = static_cast<std::int16_t>(v);
        }
        if (sd <= r) {
          ++not_inside[c];
          only_not_inside[c] = static_cast<std::int16_t>(v);
        }
      }
    }
  });
  // Per view, the cells of the others' hull splatted into its image: grown (the cell's
  // circumscribed footprint) for "may be object", shrunk (its inscribed one) for "is object".
  // Only cells outside at most one view can be in a view's others' hull (a fraction of the
  // grid): listed once, in grid order, with their centres and whether they lie on the surface
  // of a view's others' hull, where a neighbour is not in it: one is carved by two views or off
  // the grid (a surface cell for every view), or the neighbours not in every view's others' hull
  // are carved by one view alone (a surface cell but for that view when it is always the same).
  constexpr std::int16_t kAlwaysSurface = -1;
  constexpr std::int16_t kNeverSurface = -2;
  struct Held {
    Eigen::Vector3d centre;
    std::uint32_t cell;
    std::int16_t surface_but_for;  // a view, or kAlwaysSurface, kNeverSurface
  };
  std::vector<Held> held;
  const std::size_t slice = static_cast<std::size_t>(cells_per_axis) * cells_per_axis;
  for (std::size_t c = 0; c < cells; ++c) {
    if (outside[c] > 1) continue;
    const std::size_t i = c % cells_per_axis;
    const std::size_t j = (c / cells_per_axis) % cells_per_axis;
    const std::size_t k = c / slice;
    const auto last = static_cast<std::size_t>(cells_per_axis - 1);
    std::int16_t surface = kNeverSurface;
    if (i == 0 || j == 0 || k == 0 || i == last || j == last || k == last) {
      surface = kAlwaysSurface;
    } else {
      for (const std::size_t neighbour :
           {c - 1, c + 1, c - cells_per_axis, c + cells_per_axis, c - slice, c + slice}) {
        if (outside[neighbour] == 0) continue;
        if (outside[neighbour] > 1 ||
            (surface != kNeverSurface && surface != only_outside[neighbour])) {
          surface = kAlwaysSurface;
          break;
        }
        surface = only_outside[neighbour];
      }
    }
    held.push_back({cell_centre(c), static_cast<std::uint32_t>(c), surface});
  }
  std::vector<cv::Mat> priors(n);
  ParallelFor(n, 1, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t v = begin; v < end; ++v) {
      const ViewData& d = data[v];
      const auto view = static_cast<std::int16_t>(v);
      cv::Mat may(cameras[v].height, cameras[v].width, CV_8UC1, cv::Scalar(0));
      cv::Mat is(may.size(), CV_8UC1, cv::Scalar(0));
      double footprint_sum = 0.0;
      int footprints = 0;
      DiscSpans discs;
      // The footprints of the region's surface cells cover its projection (a ray through it
      // enters through one of them): the inner cells need not be drawn into `may`.
      for (const Held& h : held) {
        const std::size_t c = h.cell;
        if (outside[c] == 1 && only_outside[c] != view) continue;  // not in this view's
        const Eigen::Vector3d p = d.rotation * h.centre + d.translation;
        if (p.z() - rho <= kNearM) continue;
        const double r_out = d.focal_max * rho / (p.z() - rho) + 1.0;
        footprint_sum += r_out;
        ++footprints;
        const bool in_is = not_inside[c] == 0 || (not_inside[c] == 1 && only_not_inside[c] == view);
        const bool surface = h.surface_but_for == kAlwaysSurface ||
                             (h.surface_but_for >= 0 && h.surface_but_for != view);
        if (!surface && !in_is) continue;
        const Eigen::Vector2d pixel = d.camera->ProjectFromCam(p);
        const cv::Point centre(cvRound(pixel.x()), cvRound(pixel.y()));
        if (surface) discs.Fill(may, centre, static_cast<int>(std::ceil(r_out)));
        if (in_is) {
          const double r_in = d.focal_mean * inner / (p.z() + rho);
          discs.Fill(is, centre, std::max(1, static_cast<int>(r_in)));
        }
      }
      // Deep inside: a cell's footprint within the others' hull's inner region. Nearer the
      // outline, the hull of the others may be fatter than the object (a see-through loop
      // seen through by few views).
      cv::Mat deep;
      const int reach = static_cast<int>(std::ceil(footprint_sum / std::max(1, footprints)));
      cv::erode(
          is, deep,
          cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * reach + 1, 2 * reach + 1)));
      cv::Mat prior(may.size(), CV_8UC1, cv::Scalar(128));
      prior.setTo(0, may == 0);
      prior.setTo(192, is);
      prior.setTo(255, deep);
      priors[v] = prior;
    }
  });
  return priors;
}

}  // namespace carousel::recon
