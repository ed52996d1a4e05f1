#include "carousel/texture/texture_map.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <queue>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/parallel.h"
#include "carousel/core/raster.h"
#include "carousel/core/timer.h"

namespace carousel::texture {
namespace {

// A face's corners, normal and UVs, read once.
struct FaceData {
  std::array<Eigen::Vector3d, 3> p;
  std::array<Eigen::Vector2d, 3> uv;
  std::array<int, 3> across{-1, -1, -1};  // the face across edge (k, k + 1)
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  int chart = -1;
};

std::vector<FaceData> ReadFaces(const Mesh& mesh) {
  std::vector<FaceData> faces(mesh.n_faces());
  for (const auto f : mesh.faces()) {
    FaceData& d = faces[f.idx()];
    std::array<Mesh::HalfedgeHandle, 3> h;
    int k = 0;
    for (const auto he : mesh.fh_range(f)) {
      if (k == 3) break;
      h[k++] = he;
    }
    CAROUSEL_THROW_IF(k != 3, InvalidArgument, "texture: face " << f.idx() << " is not a triangle");
    for (int i = 0; i < 3; ++i) {
      const auto& q = mesh.point(mesh.to_vertex_handle(h[i]));
      d.p[i] = Eigen::Vector3d(q[0], q[1], q[2]);
      const auto& t = mesh.uv(h[i]);
      d.uv[i] = Eigen::Vector2d(t[0], t[1]);
      // Edge (i, i + 1) is the halfedge from corner i to corner i + 1: h[i + 1].
      const auto across = mesh.opposite_face_handle(h[(i + 1) % 3]);
      d.across[i] = across.is_valid() ? across.idx() : -1;
    }
    const Eigen::Vector3d n = (d.p[1] - d.p[0]).cross(d.p[2] - d.p[0]);
    d.normal = n.norm() > 0.0 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d::Zero();
    d.chart = mesh.chart_id(f);
  }
  return faces;
}

// Sample points of a face (barycentric): centre, near each corner, near each edge's middle.
constexpr std::array<std::array<double, 3>, 7> kSamples = {{{1.0 / 3, 1.0 / 3, 1.0 / 3},
                                                            {0.8, 0.1, 0.1},
                                                            {0.1, 0.8, 0.1},
                                                            {0.1, 0.1, 0.8},
                                                            {0.45, 0.45, 0.1},
                                                            {0.1, 0.45, 0.45},
                                                            {0.45, 0.1, 0.45}}};

Eigen::Vector3d At(const FaceData& f, const std::array<double, 3>& b) {
  return b[0] * f.p[0] + b[1] * f.p[1] + b[2] * f.p[2];
}

// Per-view depth buffer of the mesh (camera-frame z, metres), at a reduced resolution.
class DepthBuffer {
 public:
  DepthBuffer(const std::vector<FaceData>& faces, const CameraModel& camera, int max_side)
      : camera_(camera.Scaled(
            std::min(1.0, static_cast<double>(max_side) / std::max(camera.width, camera.height)))),
        depth_(camera_.height, camera_.width, CV_32F,
               cv::Scalar(std::numeric_limits<float>::max())) {
    for (const FaceData& f : faces) {
      std::array<Eigen::Vector2d, 3> px;
      std::array<double, 3> z;
      bool ok = true;
      for (int i = 0; i < 3; ++i) {
        const Eigen::Vector3d c = camera_.cam_from_world * f.p[i];
        if (c.z() <= 1e-6) {
          ok = false;
          break;
        }
        px[i] = camera_.ProjectFromCam(c);
        z[i] = c.z();
      }
      if (!ok) continue;
      const double area =
          (px[1] - px[0]).x() * (px[2] - px[0]).y() - (px[1] - px[0]).y() * (px[2] - px[0]).x();
      if (std::abs(area) < 1e-12) continue;
      ForEachPixelCentreIn(px, depth_.cols, depth_.rows, [&](int x, int y) {
        const Eigen::Vector2d q(x, y);
        const double b1 =
            ((q - px[0]).x() * (px[2] - px[0]).y() - (q - px[0]).y() * (px[2] - px[0]).x()) / area;
        const double b2 =
            ((px[1] - px[0]).x() * (q - px[0]).y() - (px[1] - px[0]).y() * (q - px[0]).x()) / area;
        const double b0 = 1.0 - b1 - b2;
        // Perspective-correct: 1/z is linear in the image.
        const double inv = b0 / z[0] + b1 / z[1] + b2 / z[2];
        if (inv <= 0.0) return;
        float& d = depth_.at<float>(y, x);
        d = std::min(d, static_cast<float>(1.0 / inv));
      });
    }
  }

  // Whether the surface point is the nearest thing the camera sees along its ray.
  bool Visible(const Eigen::Vector3d& point_world) const {
    const Eigen::Vector3d c = camera_.cam_from_world * point_world;
    if (c.z() <= 1e-6) return false;
    const Eigen::Vector2d px = camera_.ProjectFromCam(c);
    const int x = static_cast<int>(std::lround(px.x()));
    const int y = static_cast<int>(std::lround(px.y()));
    if (x < 0 || y < 0 || x >= depth_.cols || y >= depth_.rows) return false;
    // The nearest depth around the pixel: a point on a face edge may round onto a pixel its
    // own face does not cover.
    float nearest = depth_.at<float>(y, x);
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int xx = x + dx, yy = y + dy;
        if (xx >= 0 && yy >= 0 && xx < depth_.cols && yy < depth_.rows)
          nearest = std::min(nearest, depth_.at<float>(yy, xx));
      }
    const double tolerance = 0.003 + 0.004 * c.z();
    return c.z() <= nearest + tolerance || nearest == std::numeric_limits<float>::max();
  }

 private:
  CameraModel camera_;
  cv::Mat depth_;
};

// Bilinear sample of an 8-bit BGR image at a pixel position (integer = pixel centre).
bool Sample(const cv::Mat& image, const Eigen::Vector2d& px, cv::Vec3d* out) {
  const double x = px.x(), y = px.y();
  if (!(x >= 0.0 && y >= 0.0 && x <= image.cols - 1 && y <= image.rows - 1)) return false;
  const int x0 = std::min(static_cast<int>(x), image.cols - 2 < 0 ? 0 : image.cols - 2);
  const int y0 = std::min(static_cast<int>(y), image.rows - 2 < 0 ? 0 : image.rows - 2);
  const int x1 = std::min(x0 + 1, image.cols - 1), y1 = std::min(y0 + 1, image.rows - 1);
  const double fx = x - x0, fy = y - y0;
  const auto& a = image.at<cv::Vec3b>(y0, x0);
  const auto& b = image.at<cv::Vec3b>(y0, x1);
  const auto& c = image.at<cv::Vec3b>(y1, x0);
  const auto& d = image.at<cv::Vec3b>(y1, x1);
  for (int k = 0; k < 3; ++k)
    (*out)[k] = (1 - fy) * ((1 - fx) * a[k] + fx * b[k]) + fy * ((1 - fx) * c[k] + fx * d[k]);
  return true;
}

// The mean colour of the 8-neighbours of `q` that `take(x, y)` accepts; false when none does.
template <typename Take>
bool NeighbourMean(const cv::Mat& texture, const cv::Point& q, Take&& take, cv::Vec3b* mean) {
  cv::Vec3d sum(0, 0, 0);
  int n = 0;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int x = q.x + dx, y = q.y + dy;
      if (x < 0 || y < 0 || x >= texture.cols || y >= texture.rows || !take(x, y)) continue;
      sum += cv::Vec3d(texture.at<cv::Vec3b>(y, x));
      ++n;
    }
  if (n == 0) return false;
  *mean = cv::Vec3b(cv::saturate_cast<std::uint8_t>(sum[0] / n),
                    cv::saturate_cast<std::uint8_t>(sum[1] / n),
                    cv::saturate_cast<std::uint8_t>(sum[2] / n));
  return true;
}

double ProjectedArea(const FaceData& f, const CameraModel& camera) {
  std::array<Eigen::Vector2d, 3> px;
  for (int i = 0; i < 3; ++i) {
    const auto p = camera.Project(f.p[i]);
    if (!p) return 0.0;
    px[i] = *p;
  }
  return 0.5 * std::abs((px[1] - px[0]).x() * (px[2] - px[0]).y() -
                        (px[1] - px[0]).y() * (px[2] - px[0]).x());
}

double UvArea(const FaceData& f) {
  return 0.5 * std::abs((f.uv[1] - f.uv[0]).x() * (f.uv[2] - f.uv[0]).y() -
                        (f.uv[1] - f.uv[0]).y() * (f.uv[2] - f.uv[0]).x());
}

void CheckViews(const std::vector<View>& views) {
  CAROUSEL_THROW_IF(views.empty(), InvalidArgument, "texture: no views");
  for (const View& v : views) v.camera().Validate();
}

}  // namespace

void GroupingOptions::Validate() const {
  CAROUSEL_THROW_IF(max_island_faces < 0, InvalidArgument,
                    "GroupingOptions.max_island_faces must be >= 0");
  CAROUSEL_THROW_IF(zbuffer_max_side < 64 || zbuffer_max_side > 8192, InvalidArgument,
                    "GroupingOptions.zbuffer_max_side must be in [64, 8192]");
}

void TransferOptions::Validate() const {
  CAROUSEL_THROW_IF(size < 64 || size > 16384, InvalidArgument,
                    "TransferOptions.size must be in [64, 16384]");
  CAROUSEL_THROW_IF(dilation_texels < 0 || dilation_texels > 64, InvalidArgument,
                    "TransferOptions.dilation_texels must be in [0, 64]");
}

GroupingResult GroupFaces(const Mesh& mesh, const std::vector<View>& views,
                          const GroupingOptions& options, Progress& progress) {
  options.Validate();
  CheckViews(views);
  const int nv = static_cast<int>(views.size());
  std::vector<unsigned char> excluded(nv, 0);
  for (const int v : options.exclude_views) {
    CAROUSEL_THROW_IF(v < 0 || v >= nv, InvalidArgument,
                      "texture: excluded view " << v << " outside 0.." << nv - 1);
    excluded[v] = 1;
  }
  Stopwatch stopwatch;
  progress.BeginStage("texture: grouping");
  const std::vector<FaceData> faces = ReadFaces(mesh);
  const std::size_t nf = faces.size();
  // Per face and view: cosine of the viewing angle (<= 0: not a candidate), visibility of
  // all samples, samples on the mask.
  std::vector<float> cosine(nf * nv, 0.0f);
  std::vector<unsigned char> visible(nf * nv, 0), partly(nf * nv, 0), on_mask(nf * nv, 1);
  std::atomic<int> done{0};
  ParallelFor(views.size(), 1, 0, [&](std::size_t begin, std::size_t end) {
    for (std::size_t v = begin; v < end; ++v) {
      if (excluded[v]) continue;
      const CameraModel& camera = views[v].camera();
      const DepthBuffer depth(faces, camera, options.zbuffer_max_side);
      const cv::Mat mask = options.correction ? views[v].Mask() : cv::Mat();
      const Eigen::Vector3d centre = camera.Centre();
      for (std::size_t f = 0; f < nf; ++f) {
        const FaceData& face = faces[f];
        const Eigen::Vector3d middle = At(face, kSamples[0]);
        const double c = face.normal.dot((centre - middle).normalized());
        if (c <= 0.0) continue;
        int seen = 0, inside = 0;
        for (const auto& b : kSamples) {
          const Eigen::Vector3d p = At(face, b);
          if (depth.Visible(p)) ++seen;
          if (options.correction) {
            const auto px = camera.Project(p);
            if (px) {
              const int x = static_cast<int>(std::lround(px->x()));
              const int y = static_cast<int>(std::lround(px->y()));
              if (x >= 0 && y >= 0 && x < mask.cols && y < mask.rows &&
                  mask.at<std::uint8_t>(y, x) >= 128)
                ++inside;
            }
          }
        }
        const std::size_t i = f * nv + v;
        cosine[i] = static_cast<float>(c);
        visible[i] = seen == static_cast<int>(kSamples.size()) ? 1 : 0;
        partly[i] = 2 * seen >= static_cast<int>(kSamples.size()) ? 1 : 0;
        on_mask[i] = !options.correction || inside == static_cast<int>(kSamples.size()) ? 1 : 0;
      }
      progress.Report(static_cast<std::size_t>(++done), views.size());
    }
  });
  GroupingResult result;
  result.views = nv;
  result.front_view.assign(nf, Mesh::kNoView);
  result.usable.assign(nf * nv, 0);
  result.seen.assign(nf * nv, 0);
  for (std::size_t f = 0; f < nf; ++f) {
    int best_visible = -1, best_ok = -1, best_partly = -1;
    for (int v = 0; v < nv; ++v) {
      const std::size_t i = f * nv + v;
      if (cosine[i] <= 0.0f) continue;
      if (visible[i] && (best_visible < 0 || cosine[i] > cosine[f * nv + best_visible]))
        best_visible = v;
      if (visible[i] && on_mask[i] && (best_ok < 0 || cosine[i] > cosine[f * nv + best_ok]))
        best_ok = v;
      if (partly[i] && (best_partly < 0 || cosine[i] > cosine[f * nv + best_partly]))
        best_partly = v;
      result.usable[i] = visible[i] && on_mask[i] ? 1 : 0;
      result.seen[i] = visible[i];
    }
    int front = best_ok;
    if (front >= 0 && best_ok != best_visible) ++result.corrected_faces;
    if (front < 0 && best_visible >= 0) {
      front = best_visible;
      if (options.correction) ++result.uncorrectable_faces;
    }
    if (front < 0) front = best_partly;
    if (front < 0) ++result.unseen_faces;
    result.front_view[f] = front;
  }
  // Island cleanup.
  if (options.max_island_faces > 0) {
    std::vector<int> component(nf, -1);
    for (std::size_t seed = 0; seed < nf; ++seed) {
      if (component[seed] >= 0 || result.front_view[seed] < 0) continue;
      const int view = result.front_view[seed];
      std::vector<int> members{static_cast<int>(seed)};
      component[seed] = static_cast<int>(seed);
      std::map<int, int> around;  // neighbouring views, by count
      for (std::size_t k = 0; k < members.size(); ++k) {
        for (const int g : faces[members[k]].across) {
          if (g < 0) continue;
          if (result.front_view[g] == view) {
            if (component[g] < 0) {
              component[g] = static_cast<int>(seed);
              members.push_back(g);
            }
          } else if (result.front_view[g] >= 0) {
            ++around[result.front_view[g]];
          }
        }
      }
      if (static_cast<int>(members.size()) > options.max_island_faces || around.empty()) continue;
      std::vector<std::pair<int, int>> ranked(around.begin(), around.end());
      std::sort(ranked.begin(), ranked.end(), [](auto a, auto b) { return a.second > b.second; });
      for (const auto& candidate : ranked) {
        const int other = candidate.first;
        const bool fits = std::all_of(members.begin(), members.end(), [&](int m) {
          return result.usable[static_cast<std::size_t>(m) * nv + other] != 0;
        });
        if (!fits) continue;
        for (const int m : members) result.front_view[m] = other;
        result.island_faces_switched += static_cast<int>(members.size());
        break;
      }
    }
  }
  progress.EndStage();
  result.seconds = stopwatch.ElapsedSeconds();
  return result;
}

int ChooseTextureSize(const Mesh& mesh, const std::vector<View>& views,
                      const std::vector<int>& front_view, double coverage, int max_size) {
  CAROUSEL_THROW_IF(!mesh.has_uvs(), InvalidArgument,
                    "texture: the mesh has no UVs (build its atlas first)");
  CAROUSEL_THROW_IF(!(coverage > 0.0 && coverage <= 1.0) || max_size < 512, InvalidArgument,
                    "ChooseTextureSize: coverage in (0, 1], max_size >= 512");
  CAROUSEL_THROW_IF(front_view.size() != mesh.n_faces(), InvalidArgument,
                    "ChooseTextureSize: one front view per face expected");
  const std::vector<FaceData> faces = ReadFaces(mesh);
  std::vector<double> needed;
  for (std::size_t f = 0; f < faces.size(); ++f) {
    const int v = front_view[f];
    if (v < 0 || v >= static_cast<int>(views.size())) continue;
    const double pixels = ProjectedArea(faces[f], views[v].camera());
    const double uv = UvArea(faces[f]);
    if (pixels > 0.0 && uv > 0.0) needed.push_back(std::sqrt(pixels / uv));
  }
  if (needed.empty()) return 512;
  const std::size_t at = std::min(
      needed.size() - 1, static_cast<std::size_t>(std::ceil(coverage * needed.size())) - 1);
  std::nth_element(needed.begin(), needed.begin() + static_cast<std::ptrdiff_t>(at), needed.end());
  const double side = needed[at];
  const int rounded = static_cast<int>(std::ceil(side / 512.0)) * 512;
  return std::clamp(rounded, 512, max_size);
}

TextureMap TransferTexture(const Mesh& mesh, const std::vector<View>& views,
                           const GroupingResult& grouping, const TransferOptions& options,
                           Progress& progress) {
  options.Validate();
  CheckViews(views);
  CAROUSEL_THROW_IF(!mesh.has_uvs(), InvalidArgument,
                    "texture: the mesh has no UVs (build its atlas first)");
  const int nv = static_cast<int>(views.size());
  CAROUSEL_THROW_IF(grouping.front_view.size() != mesh.n_faces() || grouping.views != nv ||
                        grouping.usable.size() != mesh.n_faces() * views.size() ||
                        grouping.seen.size() != grouping.usable.size(),
                    InvalidArgument, "texture: the grouping belongs to another mesh or view set");
  Stopwatch stopwatch;
  progress.BeginStage("texture: transfer");
  const std::vector<FaceData> faces = ReadFaces(mesh);
  const std::size_t nf = faces.size();
  const std::vector<int>& front = grouping.front_view;
  // Photos of the views in use.
  std::vector<cv::Mat> photos(nv);
  {
    std::vector<unsigned char> used(nv, 0);
    for (const int v : front)
      if (v >= 0) used[v] = 1;
    ParallelFor(views.size(), 1, 0, [&](std::size_t begin, std::size_t end) {
      for (std::size_t v = begin; v < end; ++v)
        if (used[v]) photos[v] = views[v].Image();
    });
  }
  // Masks of the views that may serve a texel.
  std::vector<cv::Mat> masks(nv);
  if (options.correction) {
    std::vector<unsigned char> needed(nv, 0);
    for (std::size_t i = 0; i < grouping.seen.size(); ++i)
      if (grouping.seen[i]) needed[i % nv] = 1;
    ParallelFor(views.size(), 1, 0, [&](std::size_t begin, std::size_t end) {
      for (std::size_t v = begin; v < end; ++v)
        if (needed[v]) {
          // Shrunk by 2 pixels: the silhouette's edge pixels mix object and background.
          cv::erode(views[v].Mask() >= 128, masks[v],
                    cv::getStructuringElement(cv::MORPH_ELLIPSE, {5, 5}));
          if (photos[v].empty()) photos[v] = views[v].Image();
        }
    });
  }
  auto on_object = [&](int v, const Eigen::Vector3d& p) {
    if (masks[v].empty()) return true;
    const Eigen::Vector3d c = views[v].camera().cam_from_world * p;
    if (c.z() <= 1e-6) return false;
    const Eigen::Vector2d px = views[v].camera().ProjectFromCam(c);
    const int x = static_cast<int>(std::lround(px.x())), y = static_cast<int>(std::lround(px.y()));
    return x >= 0 && y >= 0 && x < masks[v].cols && y < masks[v].rows &&
           masks[v].at<std::uint8_t>(y, x) >= 128;
  };
  TextureMap result;
  result.gains.assign(nv, cv::Vec3d(1, 1, 1));
  auto sample = [&](int v, const Eigen::Vector3d& p, cv::Vec3d* colour) {
    if (photos[v].empty()) return false;
    const Eigen::Vector3d c = views[v].camera().cam_from_world * p;
    if (c.z() <= 1e-6) return false;
    if (!Sample(photos[v], views[v].camera().ProjectFromCam(c), colour)) return false;
    for (int k = 0; k < 3; ++k) (*colour)[k] *= result.gains[v][k];
    return true;
  };
  // Per-view gains: alternating least squares on log colours of faces seen by several views.
  if (options.gain) {
    for (int v = 0; v < nv; ++v)
      if (photos[v].empty()) {
        bool any = false;
        for (std::size_t f = 0; f < nf && !any; ++f) any = grouping.usable[f * nv + v] != 0;
        if (any) photos[v] = views[v].Image();
      }
    struct Observation {
      int face, view;
      cv::Vec3d log_colour;
    };
    std::vector<Observation> observations;
    for (std::size_t f = 0; f < nf; ++f) {
      int count = 0;
      for (int v = 0; v < nv; ++v) count += grouping.usable[f * nv + v];
      if (count < 2) continue;
      for (int v = 0; v < nv; ++v) {
        if (!grouping.usable[f * nv + v]) continue;
        cv::Vec3d sum(0, 0, 0);
        int n = 0;
        for (const auto& b : kSamples) {
          cv::Vec3d c;
          if (sample(v, At(faces[f], b), &c)) {
            sum += c;
            ++n;
          }
        }
        if (n == 0) continue;
        sum /= n;
        if (std::min({sum[0], sum[1], sum[2]}) < 12.0 || std::max({sum[0], sum[1], sum[2]}) > 243.0)
          continue;
        observations.push_back({static_cast<int>(f), v,
                                cv::Vec3d(std::log(sum[0]), std::log(sum[1]), std::log(sum[2]))});
      }
    }
    std::vector<cv::Vec3d> log_gain(nv, cv::Vec3d(0, 0, 0));
    std::vector<cv::Vec3d> log_true(nf, cv::Vec3d(0, 0, 0));
    for (int iteration = 0; iteration < 20 && !observations.empty(); ++iteration) {
      std::vector<cv::Vec3d> sum_f(nf, cv::Vec3d(0, 0, 0));
      std::vector<int> n_f(nf, 0);
      for (const auto& o : observations) {
        sum_f[o.face] += o.log_colour - log_gain[o.view];
        ++n_f[o.face];
      }
      for (std::size_t f = 0; f < nf; ++f)
        if (n_f[f] > 0) log_true[f] = sum_f[f] / n_f[f];
      std::vector<cv::Vec3d> sum_v(nv, cv::Vec3d(0, 0, 0));
      std::vector<int> n_v(nv, 0);
      for (const auto& o : observations) {
        sum_v[o.view] += o.log_colour - log_true[o.face];
        ++n_v[o.view];
      }
      cv::Vec3d mean(0, 0, 0);
      int used = 0;
      for (int v = 0; v < nv; ++v)
        if (n_v[v] > 0) {
          log_gain[v] = sum_v[v] / n_v[v];
          mean += log_gain[v];
          ++used;
        }
      if (used > 0) mean /= used;
      for (int v = 0; v < nv; ++v)
        if (n_v[v] > 0) log_gain[v] -= mean;
    }
    // Colours are divided by the view's gain to bring every view to the common level.
    for (int v = 0; v < nv; ++v)
      for (int k = 0; k < 3; ++k) result.gains[v][k] = std::exp(-log_gain[v][k]);
  }
  const int size = options.size;
  result.texture = cv::Mat(size, size, CV_8UC3, cv::Scalar(0, 0, 0));
  result.coverage = cv::Mat(size, size, CV_8UC1, cv::Scalar(0));
  result.texels_per_face.assign(nf, 0);
  result.density_ratio.assign(nf, 0.0);
  // Faces by chart: charts never share texels, so charts can be filled in parallel.
  int charts = 0;
  for (const FaceData& f : faces) charts = std::max(charts, f.chart + 1);
  std::vector<std::vector<int>> chart_faces(std::max(charts, 1));
  for (std::size_t f = 0; f < nf; ++f)
    chart_faces[std::max(faces[f].chart, 0)].push_back(static_cast<int>(f));
  std::atomic<int> blended{0}, corrected{0};
  std::atomic<std::size_t> charts_done{0};
  // Mean colour of each face's texels (for the faces no view sees).
  std::vector<cv::Vec3d> face_sum(nf, cv::Vec3d(0, 0, 0));
  std::vector<int> face_count(nf, 0);
  // Texels on the background in every view, per chart (filled afterwards).
  std::vector<std::vector<cv::Point>> holes(chart_faces.size());
  ParallelFor(chart_faces.size(), 1, 0, [&](std::size_t begin, std::size_t end) {
    for (std::size_t c = begin; c < end; ++c) {
      for (const int f : chart_faces[c]) {
        const FaceData& face = faces[f];
        const int v = front[f];
        if (v < 0) continue;
        std::array<Eigen::Vector2d, 3> t;
        for (int i = 0; i < 3; ++i)
          t[i] = Eigen::Vector2d(face.uv[i].x() * size - 0.5, (1.0 - face.uv[i].y()) * size - 0.5);
        const double area =
            (t[1] - t[0]).x() * (t[2] - t[0]).y() - (t[1] - t[0]).y() * (t[2] - t[0]).x();
        if (std::abs(area) < 1e-12) continue;
        // Seam edges: the neighbour across has another front view usable for this face.
        std::array<int, 3> seam{-1, -1, -1};
        if (options.blend)
          for (int k = 0; k < 3; ++k) {
            const int g = face.across[k];
            if (g >= 0 && front[g] >= 0 && front[g] != v &&
                grouping.usable[static_cast<std::size_t>(f) * nv + front[g]])
              seam[k] = front[g];
          }
        // Other views for texels the front photo shows on the background, best angle first.
        std::vector<std::pair<double, int>> others;
        if (options.correction)
          for (int w = 0; w < nv; ++w)
            if (w != v && grouping.seen[static_cast<std::size_t>(f) * nv + w])
              others.emplace_back(
                  -face.normal.dot(
                      (views[w].camera().Centre() - At(face, kSamples[0])).normalized()),
                  w);
        std::sort(others.begin(), others.end());
        int texels = 0, local_blended = 0, local_corrected = 0;
        ForEachPixelCentreIn(t, size, size, [&](int x, int y) {
          const Eigen::Vector2d q(x, y);
          const double b1 =
              ((q - t[0]).x() * (t[2] - t[0]).y() - (q - t[0]).y() * (t[2] - t[0]).x()) / area;
          const double b2 =
              ((t[1] - t[0]).x() * (q - t[0]).y() - (t[1] - t[0]).y() * (q - t[0]).x()) / area;
          const std::array<double, 3> b{1.0 - b1 - b2, b1, b2};
          const Eigen::Vector3d p = At(face, b);
          cv::Vec3d colour;
          int source = v;
          if (options.correction && !on_object(v, p)) {
            source = -1;
            for (const auto& [score, w] : others)
              if (on_object(w, p)) {
                source = w;
                break;
              }
            if (source < 0) {
              holes[c].emplace_back(x, y);
              result.coverage.at<std::uint8_t>(y, x) = 255;
              ++texels;
              return;
            }
            ++local_corrected;
          }
          if (!sample(source, p, &colour)) return;
          // Eq. 8 towards the nearest seam edge: d = D_c / D_f is the barycentric coordinate
          // of the corner opposite the edge.
          int nearest = -1;
          double d = 1.0;
          for (int k = 0; k < 3; ++k)
            if (seam[k] >= 0 && b[(k + 2) % 3] < d) {
              d = std::max(0.0, b[(k + 2) % 3]);
              nearest = k;
            }
          if (nearest >= 0 && source == v) {
            cv::Vec3d other;
            if ((!options.correction || on_object(seam[nearest], p)) &&
                sample(seam[nearest], p, &other)) {
              colour = (colour + other * (1.0 - d)) / (2.0 - d);
              ++local_blended;
            }
          }
          result.texture.at<cv::Vec3b>(y, x) =
              cv::Vec3b(cv::saturate_cast<std::uint8_t>(colour[0]),
                        cv::saturate_cast<std::uint8_t>(colour[1]),
                        cv::saturate_cast<std::uint8_t>(colour[2]));
          result.coverage.at<std::uint8_t>(y, x) = 255;
          face_sum[f] += colour;
          ++face_count[f];
          ++texels;
        });
        result.texels_per_face[f] = texels;
        const double pixels = ProjectedArea(face, views[v].camera());
        result.density_ratio[f] = pixels > 0.0 ? texels / pixels : 0.0;
        blended += local_blended;
        corrected += local_corrected;
      }
      progress.Report(++charts_done, chart_faces.size());
    }
  });
  result.blended_texels = blended.load();
  result.corrected_texels = corrected.load();
  // Holes (background in every view): rings of the surrounding texels' mean, inwards.
  {
    cv::Mat hole(size, size, CV_8UC1, cv::Scalar(0));
    std::vector<cv::Point> pending;
    for (const auto& list : holes)
      for (const cv::Point& q : list) {
        hole.at<std::uint8_t>(q.y, q.x) = 1;
        pending.push_back(q);
      }
    result.inpainted_texels = static_cast<int>(pending.size());
    while (!pending.empty()) {
      std::vector<std::pair<cv::Point, cv::Vec3b>> values;
      std::vector<cv::Point> still;
      for (const cv::Point& q : pending) {
        cv::Vec3b mean;
        const bool found = NeighbourMean(
            result.texture, q,
            [&](int x, int y) {
              return !hole.at<std::uint8_t>(y, x) && result.coverage.at<std::uint8_t>(y, x);
            },
            &mean);
        if (found)
          values.emplace_back(q, mean);
        else
          still.push_back(q);
      }
      if (values.empty()) {
        // Islands without a good texel around: the texture's mean colour.
        const cv::Scalar mean = cv::mean(result.texture, result.coverage & (hole == 0));
        for (const cv::Point& q : still)
          result.texture.at<cv::Vec3b>(q.y, q.x) = cv::Vec3b(
              cv::saturate_cast<std::uint8_t>(mean[0]), cv::saturate_cast<std::uint8_t>(mean[1]),
              cv::saturate_cast<std::uint8_t>(mean[2]));
        break;
      }
      for (const auto& [q, colour] : values) {
        result.texture.at<cv::Vec3b>(q.y, q.x) = colour;
        hole.at<std::uint8_t>(q.y, q.x) = 0;
      }
      pending.swap(still);
    }
  }
  // Faces no view sees: the mean colour of their textured neighbours, spreading outwards.
  {
    std::vector<cv::Vec3d> mean(nf, cv::Vec3d(0, 0, 0));
    std::vector<unsigned char> known(nf, 0);
    std::vector<int> pending;
    for (std::size_t f = 0; f < nf; ++f) {
      if (front[f] < 0) {
        pending.push_back(static_cast<int>(f));
        continue;
      }
      if (face_count[f] > 0) {
        mean[f] = face_sum[f] / face_count[f];
        known[f] = 1;
      }
    }
    result.filled_faces = static_cast<int>(pending.size());
    for (int round = 0; !pending.empty() && round < 1000; ++round) {
      std::vector<int> still;
      std::vector<std::pair<int, cv::Vec3d>> learned;
      for (const int f : pending) {
        cv::Vec3d sum(0, 0, 0);
        int n = 0;
        for (const int g : faces[f].across)
          if (g >= 0 && known[g]) {
            sum += mean[g];
            ++n;
          }
        if (n > 0)
          learned.emplace_back(f, sum / n);
        else
          still.push_back(f);
      }
      if (learned.empty()) break;
      for (const auto& [f, c] : learned) {
        mean[f] = c;
        known[f] = 1;
      }
      pending.swap(still);
    }
    for (std::size_t f = 0; f < nf; ++f) {
      if (front[f] >= 0) continue;
      const FaceData& face = faces[f];
      std::array<Eigen::Vector2d, 3> t;
      for (int i = 0; i < 3; ++i)
        t[i] = Eigen::Vector2d(face.uv[i].x() * size - 0.5, (1.0 - face.uv[i].y()) * size - 0.5);
      const cv::Vec3b colour(cv::saturate_cast<std::uint8_t>(mean[f][0]),
                             cv::saturate_cast<std::uint8_t>(mean[f][1]),
                             cv::saturate_cast<std::uint8_t>(mean[f][2]));
      int texels = 0;
      ForEachPixelCentreIn(t, size, size, [&](int x, int y) {
        result.texture.at<cv::Vec3b>(y, x) = colour;
        result.coverage.at<std::uint8_t>(y, x) = 255;
        ++texels;
      });
      result.texels_per_face[f] = texels;
    }
  }
  // Gutter dilation: rings of texels take the mean of their covered neighbours.
  {
    cv::Mat filled = result.coverage.clone();
    std::vector<cv::Point> ring;
    {
      cv::Mat grown;
      cv::dilate(filled, grown, cv::Mat::ones(3, 3, CV_8U));
      cv::Mat border = grown & ~filled;
      if (cv::countNonZero(border) > 0) cv::findNonZero(border, ring);
    }
    for (int r = 0; r < options.dilation_texels && !ring.empty(); ++r) {
      std::vector<std::pair<cv::Point, cv::Vec3b>> values;
      values.reserve(ring.size());
      for (const cv::Point& q : ring) {
        cv::Vec3b mean;
        if (NeighbourMean(
                result.texture, q, [&](int x, int y) { return filled.at<std::uint8_t>(y, x) != 0; },
                &mean))
          values.emplace_back(q, mean);
      }
      std::vector<cv::Point> next;
      for (const auto& [q, colour] : values) {
        result.texture.at<cv::Vec3b>(q.y, q.x) = colour;
        filled.at<std::uint8_t>(q.y, q.x) = 255;
      }
      for (const auto& [q, colour] : values) {
        (void)colour;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = q.x + dx, yy = q.y + dy;
            if (xx < 0 || yy < 0 || xx >= size || yy >= size) continue;
            std::uint8_t& m = filled.at<std::uint8_t>(yy, xx);
            if (m == 0) {
              m = 1;  // queued for the next ring (1: not yet coloured)
              next.emplace_back(xx, yy);
            }
          }
      }
      // Texels queued but not coloured stay uncovered for the averaging.
      for (const cv::Point& q : next) filled.at<std::uint8_t>(q.y, q.x) = 0;
      ring.swap(next);
    }
    // What is left: the texture's mean colour (the coarsest mip levels blend towards it).
    const cv::Scalar average = cv::mean(result.texture, result.coverage);
    result.texture.setTo(average, filled == 0);
  }
  progress.EndStage();
  result.seconds = stopwatch.ElapsedSeconds();
  return result;
}

}  // namespace carousel::texture
