// GroupFaces (texture_map.h): each face's front image among the photos.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <map>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/parallel.h"
#include "carousel/core/raster.h"
#include "carousel/core/timer.h"
#include "carousel/texture/texture_map.h"
#include "texture_map_steps.h"

namespace carousel::texture {
namespace internal {

DepthBuffer::DepthBuffer(const std::vector<FaceData>& faces, const CameraModel& camera,
                         int max_side)
    : camera_(camera.Scaled(
          std::min(1.0, static_cast<double>(max_side) / std::max(camera.width, camera.height)))),
      scale_(static_cast<double>(camera_.width) / camera.width,
             static_cast<double>(camera_.height) / camera.height) {
  struct Projected {
    std::array<Eigen::Vector2d, 3> px;
    std::array<double, 3> z;
  };
  std::vector<Projected> projected;
  projected.reserve(faces.size());
  Eigen::AlignedBox2d box;
  for (const FaceData& f : faces) {
    Projected p;
    bool ok = true;
    for (int i = 0; i < 3 && ok; ++i) {
      const Eigen::Vector3d c = camera_.cam_from_world * f.p[i];
      ok = c.z() > 1e-6;
      if (!ok) break;
      p.px[i] = camera_.ProjectFromCam(c);
      p.z[i] = c.z();
      box.extend(p.px[i]);
    }
    if (ok) projected.push_back(p);
  }
  // Only the part of the image the mesh covers (and a pixel around, for the 3 x 3 search): a
  // product fills a fraction of the frame.
  const cv::Rect image(0, 0, camera_.width, camera_.height);
  const cv::Rect covered =
      box.isEmpty() ? cv::Rect()
                    : cv::Rect(cv::Point(static_cast<int>(std::floor(box.min().x())) - 1,
                                         static_cast<int>(std::floor(box.min().y())) - 1),
                               cv::Point(static_cast<int>(std::ceil(box.max().x())) + 2,
                                         static_cast<int>(std::ceil(box.max().y())) + 2)) &
                          image;
  origin_ = Eigen::Vector2d(covered.x, covered.y);
  depth_ = cv::Mat(std::max(covered.height, 1), std::max(covered.width, 1), CV_32F,
                   cv::Scalar(std::numeric_limits<float>::max()));
  for (Projected& p : projected) {
    for (Eigen::Vector2d& q : p.px) q -= origin_;
    const auto& px = p.px;
    const auto& z = p.z;
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
  // Each pixel keeps the nearest depth of the 3 x 3 around it (outside counts as empty): a
  // point on a face edge may round onto a pixel its own face does not cover.
  cv::erode(depth_, depth_, cv::Mat(), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
            cv::Scalar(std::numeric_limits<float>::max()));
}

bool DepthBuffer::Visible(const Eigen::Vector3d& point_world, double cosine) const {
  const Eigen::Vector3d c = camera_.cam_from_world * point_world;
  if (c.z() <= 1e-6) return false;
  return VisibleInBuffer(camera_.ProjectFromCam(c), c.z(), cosine);
}

bool DepthBuffer::VisibleAt(const Eigen::Vector2d& photo_px, double z, double cosine) const {
  if (z <= 1e-6) return false;
  // CameraModel::Scaled: pixel edges scale, centres sit half a pixel inside them.
  return VisibleInBuffer((photo_px.array() + 0.5) * scale_.array() - 0.5, z, cosine);
}

bool DepthBuffer::VisibleInBuffer(const Eigen::Vector2d& px, double z, double cosine) const {
  const int x = static_cast<int>(std::lround(px.x()));
  const int y = static_cast<int>(std::lround(px.y()));
  if (x < 0 || y < 0 || x >= camera_.width || y >= camera_.height) return false;
  const int bx = x - static_cast<int>(origin_.x()), by = y - static_cast<int>(origin_.y());
  if (bx < 0 || by < 0 || bx >= depth_.cols || by >= depth_.rows) return true;  // nothing there
  const float nearest = depth_.at<float>(by, bx);  // of the 3 x 3 around (the constructor)
  const double footprint = z / camera_.fx;         // metres per buffer pixel
  const double tolerance = 0.001 + 2.0 * footprint / std::max(cosine, 0.25);
  return z <= nearest + tolerance || nearest == std::numeric_limits<float>::max();
}

}  // namespace internal

namespace {

using internal::At;
using internal::DepthBuffer;
using internal::FaceData;
using internal::kSamples;

// Per face and view (face * views + view): the cosine of the viewing angle (<= 0: not a
// candidate), all samples visible, at least half of them visible, all samples on the mask.
struct ViewMeasures {
  std::vector<float> cosine;
  std::vector<unsigned char> visible, partly, on_mask;
};

ViewMeasures MeasureViews(const std::vector<FaceData>& faces, const std::vector<View>& views,
                          const std::vector<unsigned char>& excluded,
                          const GroupingOptions& options, Progress& progress) {
  const std::size_t nf = faces.size();
  const int nv = static_cast<int>(views.size());
  ViewMeasures m;
  m.cosine.assign(nf * nv, 0.0f);
  m.visible.assign(nf * nv, 0);
  m.partly.assign(nf * nv, 0);
  m.on_mask.assign(nf * nv, 1);
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
          if (depth.Visible(p, c)) ++seen;
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
        m.cosine[i] = static_cast<float>(c);
        m.visible[i] = seen == static_cast<int>(kSamples.size()) ? 1 : 0;
        m.partly[i] = 2 * seen >= static_cast<int>(kSamples.size()) ? 1 : 0;
        m.on_mask[i] = !options.correction || inside == static_cast<int>(kSamples.size()) ? 1 : 0;
      }
      progress.Report(static_cast<std::size_t>(++done), views.size());
    }
  });
  return m;
}

// Per face, the latest capture pass it may take its front view from: the earliest pass with a
// view that reaches `ratio` of the face's best cosine (among the views that see it whole and
// on the mask; else whole; else every pass).
std::vector<int> LatestPasses(const ViewMeasures& m, std::size_t nf, int nv,
                              const std::vector<int>& view_pass, double ratio) {
  std::vector<int> max_pass(nf, std::numeric_limits<int>::max());
  if (ratio <= 0.0 || std::all_of(view_pass.begin(), view_pass.end(), [](int p) { return p == 0; }))
    return max_pass;
  const int passes = *std::max_element(view_pass.begin(), view_pass.end()) + 1;
  std::vector<float> best(static_cast<std::size_t>(passes));
  for (std::size_t f = 0; f < nf; ++f) {
    for (const bool need_mask : {true, false}) {
      std::fill(best.begin(), best.end(), 0.0f);
      for (int v = 0; v < nv; ++v) {
        const std::size_t i = f * nv + v;
        if (m.visible[i] && (m.on_mask[i] || !need_mask))
          best[view_pass[v]] = std::max(best[view_pass[v]], m.cosine[i]);
      }
      const float overall = *std::max_element(best.begin(), best.end());
      if (overall <= 0.0f) continue;
      for (int p = 0; p < passes; ++p)
        if (best[p] >= ratio * overall) {
          max_pass[f] = p;
          break;
        }
      break;
    }
  }
  return max_pass;
}

// Each face's front view: the most frontal view that sees it whole and on the mask; else the
// most frontal that sees it whole; else the most frontal that sees half of it.
void ChooseFrontViews(const ViewMeasures& m, std::size_t nf, int nv, bool correction,
                      const std::vector<int>& view_pass, const std::vector<int>& max_pass,
                      GroupingResult* result) {
  result->views = nv;
  result->front_view.assign(nf, Mesh::kNoView);
  result->usable.assign(nf * nv, 0);
  result->seen.assign(nf * nv, 0);
  for (std::size_t f = 0; f < nf; ++f) {
    int best_visible = -1, best_ok = -1, best_partly = -1;
    for (int v = 0; v < nv; ++v) {
      const std::size_t i = f * nv + v;
      if (m.cosine[i] <= 0.0f) continue;
      result->usable[i] = m.visible[i] && m.on_mask[i] ? 1 : 0;
      result->seen[i] = m.visible[i];
      if (view_pass[v] > max_pass[f]) continue;  // usable (gains, blending), not a front view
      if (m.visible[i] && (best_visible < 0 || m.cosine[i] > m.cosine[f * nv + best_visible]))
        best_visible = v;
      if (m.visible[i] && m.on_mask[i] && (best_ok < 0 || m.cosine[i] > m.cosine[f * nv + best_ok]))
        best_ok = v;
      if (m.partly[i] && (best_partly < 0 || m.cosine[i] > m.cosine[f * nv + best_partly]))
        best_partly = v;
    }
    int front = best_ok;
    if (front >= 0 && best_ok != best_visible) ++result->corrected_faces;
    if (front < 0 && best_visible >= 0) {
      front = best_visible;
      if (correction) ++result->uncorrectable_faces;
    }
    if (front < 0) front = best_partly;
    if (front < 0) ++result->unseen_faces;
    result->front_view[f] = front;
  }
}

// Island cleanup: a group of at most `max_island_faces` faces of one front view switches to
// the neighbouring view its border meets most often for which every face of it is usable.
void CleanIslands(const std::vector<FaceData>& faces, int max_island_faces,
                  const std::vector<int>& view_pass, const std::vector<int>& max_pass,
                  GroupingResult* result) {
  const std::size_t nf = faces.size();
  const int nv = result->views;
  std::vector<int> component(nf, -1);
  for (std::size_t seed = 0; seed < nf; ++seed) {
    if (component[seed] >= 0 || result->front_view[seed] < 0) continue;
    const int view = result->front_view[seed];
    std::vector<int> members{static_cast<int>(seed)};
    component[seed] = static_cast<int>(seed);
    std::map<int, int> around;  // neighbouring views, by count
    for (std::size_t k = 0; k < members.size(); ++k) {
      for (const int g : faces[members[k]].across) {
        if (g < 0) continue;
        if (result->front_view[g] == view) {
          if (component[g] < 0) {
            component[g] = static_cast<int>(seed);
            members.push_back(g);
          }
        } else if (result->front_view[g] >= 0) {
          ++around[result->front_view[g]];
        }
      }
    }
    if (static_cast<int>(members.size()) > max_island_faces || around.empty()) continue;
    std::vector<std::pair<int, int>> ranked(around.begin(), around.end());
    std::sort(ranked.begin(), ranked.end(), [](auto a, auto b) { return a.second > b.second; });
    for (const auto& candidate : ranked) {
      const int other = candidate.first;
      const bool fits = std::all_of(members.begin(), members.end(), [&](int m) {
        return result->usable[static_cast<std::size_t>(m) * nv + other] != 0 &&
               view_pass[other] <= max_pass[m];
      });
      if (!fits) continue;
      for (const int m : members) result->front_view[m] = other;
      result->island_faces_switched += static_cast<int>(members.size());
      break;
    }
  }
}

// Iterated conditional modes on the front views: each face in turn takes, among its current
// view and its neighbours' (usable, and at least min_ratio of its best cosine), the one with
// the least data cost (1 - cosine / best cosine) plus seam_cost per neighbour left on
// another view; sweeps until nothing changes (at most 20).
void MakeFrontViewsCoherent(const ViewMeasures& m, const std::vector<FaceData>& faces,
                            double seam_cost, double min_ratio, const std::vector<int>& view_pass,
                            const std::vector<int>& max_pass, GroupingResult* result) {
  const std::size_t nf = faces.size();
  const int nv = result->views;
  std::vector<float> best(nf, 0.0f);
  std::vector<int> initial = result->front_view;
  for (std::size_t f = 0; f < nf; ++f) {
    const int v = result->front_view[f];
    if (v >= 0 && result->usable[f * nv + v]) best[f] = m.cosine[f * nv + v];
  }
  for (int sweep = 0; sweep < 20; ++sweep) {
    int changed = 0;
    for (std::size_t f = 0; f < nf; ++f) {
      if (best[f] <= 0.0f) continue;  // no usable view: the fallback choice stays
      const int current = result->front_view[f];
      std::array<int, 4> candidates{current, -1, -1, -1};
      for (int k = 0; k < 3; ++k) {
        const int g = faces[f].across[static_cast<std::size_t>(k)];
        if (g >= 0) candidates[static_cast<std::size_t>(k) + 1] = result->front_view[g];
      }
      int chosen = current;
      double chosen_cost = std::numeric_limits<double>::max();
      for (const int v : candidates) {
        if (v < 0) continue;
        const std::size_t i = f * nv + v;
        if (!result->usable[i] || m.cosine[i] < min_ratio * best[f] || view_pass[v] > max_pass[f])
          continue;
        double cost = 1.0 - m.cosine[i] / best[f];
        for (const int g : faces[f].across) {
          if (g >= 0 && result->front_view[g] >= 0 && result->front_view[g] != v) cost += seam_cost;
        }
        if (cost < chosen_cost - 1e-12) {
          chosen_cost = cost;
          chosen = v;
        }
      }
      if (chosen != current) {
        result->front_view[f] = chosen;
        ++changed;
      }
    }
    if (changed == 0) break;
  }
  for (std::size_t f = 0; f < nf; ++f) {
    if (result->front_view[f] != initial[f]) ++result->coherence_faces_switched;
  }
}

// Connected groups of faces with one front view, and their mean size.
void CountPatches(const std::vector<FaceData>& faces, GroupingResult* result) {
  const std::size_t nf = faces.size();
  std::vector<unsigned char> visited(nf, 0);
  std::vector<int> stack;
  int patches = 0;
  std::size_t faces_in_patches = 0;
  for (std::size_t seed = 0; seed < nf; ++seed) {
    if (visited[seed] || result->front_view[seed] < 0) continue;
    const int view = result->front_view[seed];
    ++patches;
    visited[seed] = 1;
    stack.assign(1, static_cast<int>(seed));
    while (!stack.empty()) {
      const int f = stack.back();
      stack.pop_back();
      ++faces_in_patches;
      for (const int g : faces[static_cast<std::size_t>(f)].across) {
        if (g >= 0 && !visited[g] && result->front_view[g] == view) {
          visited[g] = 1;
          stack.push_back(g);
        }
      }
    }
  }
  result->patches = patches;
  result->mean_patch_faces =
      patches > 0 ? static_cast<double>(faces_in_patches) / static_cast<double>(patches) : 0.0;
}

}  // namespace

const OptionTable<GroupingOptions>& GroupingOptions::Fields() {
  using O = GroupingOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::exclude_views, {.name = "exclude-views",
                              .help = "views not to texture from (held out), e.g. 3,11",
                              .min = 0});
    t.Add(&O::correction,
          {.name = "correction",
           .help = "refuse photos whose mask shows background under a face or texel"});
    t.Add(&O::max_island_faces,
          {.name = "max-island-faces",
           .help = "groups of at most this many faces may switch to a neighbour's photo",
           .unit = "faces",
           .min = 1,
           .special = 0,
           .special_meaning = "no island cleanup",
           .advanced = true});
    t.Add(&O::seam_cost,
          {.name = "seam-cost",
           .help = "coherent front views: the cost of a seam between neighbouring faces against "
                   "a view's obliqueness (1 - cosine / best cosine)",
           .min = 0.0,
           .advanced = true});
    t.Add(&O::min_cosine_ratio,
          {.name = "min-cosine-ratio",
           .help = "coherent front views: a face takes no view whose cosine is below this "
                   "fraction of its best",
           .min = 0.0,
           .max = 1.0,
           .advanced = true});
    t.Add(&O::pass_cosine_ratio,
          {.name = "pass-cosine-ratio",
           .help = "a face takes a photo of a later capture pass only where no photo of an "
                   "earlier one sees it at this fraction of its best cosine (0: any pass)",
           .min = 0.0,
           .max = 1.0,
           .advanced = true});
    t.Add(&O::zbuffer_max_side, {.name = "zbuffer-max-side",
                                 .help = "longest side of the per-view visibility z-buffers",
                                 .unit = "px",
                                 .min = 64,
                                 .max = 8192,
                                 .advanced = true});
    return t;
  }();
  return table;
}

void GroupingOptions::Validate() const { Fields().Check(*this); }

GroupingResult GroupFaces(const Mesh& mesh, const std::vector<View>& views,
                          const GroupingOptions& options, Progress& progress) {
  options.Validate();
  internal::CheckViews(views);
  const int nv = static_cast<int>(views.size());
  std::vector<unsigned char> excluded(nv, 0);
  for (const int v : options.exclude_views) {
    CAROUSEL_THROW_IF(v < 0 || v >= nv, InvalidArgument,
                      "texture: excluded view " << v << " outside 0.." << nv - 1);
    excluded[v] = 1;
  }
  CAROUSEL_THROW_IF(
      !options.view_pass.empty() && options.view_pass.size() != views.size(), InvalidArgument,
      "texture: " << options.view_pass.size() << " view passes for " << nv << " views");
  for (const int p : options.view_pass)
    CAROUSEL_THROW_IF(p < 0, InvalidArgument, "texture: a view's pass is negative (" << p << ")");
  Stopwatch stopwatch;
  progress.BeginStage("texture: grouping");
  const std::vector<FaceData> faces = internal::ReadFaces(mesh);
  const ViewMeasures measures = MeasureViews(faces, views, excluded, options, progress);
  const std::vector<int> view_pass =
      options.view_pass.empty() ? std::vector<int>(nv, 0) : options.view_pass;
  const std::vector<int> max_pass =
      LatestPasses(measures, faces.size(), nv, view_pass, options.pass_cosine_ratio);
  GroupingResult result;
  ChooseFrontViews(measures, faces.size(), nv, options.correction, view_pass, max_pass, &result);
  if (options.seam_cost > 0.0)
    MakeFrontViewsCoherent(measures, faces, options.seam_cost, options.min_cosine_ratio, view_pass,
                           max_pass, &result);
  if (options.max_island_faces > 0)
    CleanIslands(faces, options.max_island_faces, view_pass, max_pass, &result);
  CountPatches(faces, &result);
  progress.EndStage();
  result.seconds = stopwatch.ElapsedSeconds();
  return result;
}

}  // namespace carousel::texture
