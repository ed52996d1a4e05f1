// The texel transfer of TransferTexture (texture_map.h): every texel's surface point projected
// into its face's front photo and sampled there, or, where the front photo shows background,
// in another view that sees the face.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <numbers>
#include <utility>

#include <Eigen/Geometry>

#include <opencv2/imgproc.hpp>

#include "carousel/core/parallel.h"
#include "carousel/core/raster.h"
#include "texture_map_steps.h"

namespace carousel::texture::internal {
namespace {

// Bilinear sample of an 8-bit BGR image at a pixel position (integer = pixel centre).
bool SampleBilinear(const cv::Mat& image, const Eigen::Vector2d& px, cv::Vec3d* out) {
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

// Lanczos-3 (Duchon 1979; the windowed sinc image resizers default to): sinc(d) sinc(d / 3)
// over the 6 x 6 pixels around a position, normalised, per axis. Sharper than bilinear
// interpolation, which blurs the photo before the texture is sampled again by a viewer: on
// texture_bench --blob, +0.9 dB against the true albedo (bicubic Catmull-Rom: +0.7 dB).
// Weights are tabulated for kLanczosPhases sub-pixel offsets (1/256 pixel apart).
constexpr int kLanczosPhases = 256;

const std::array<std::array<float, 6>, kLanczosPhases + 1>& LanczosWeights() {
  static const auto table = [] {
    std::array<std::array<float, 6>, kLanczosPhases + 1> t{};
    for (int phase = 0; phase <= kLanczosPhases; ++phase) {
      const double offset = static_cast<double>(phase) / kLanczosPhases;
      double w[6];
      double sum = 0.0;
      for (int i = 0; i < 6; ++i) {
        const double d = (i - 2) - offset;  // taps at -2..3 pixels from the lower neighbour
        const double pd = std::numbers::pi * d;
        w[i] = std::abs(d) < 1e-12 ? 1.0 : 3.0 * std::sin(pd) * std::sin(pd / 3.0) / (pd * pd);
        sum += w[i];
      }
      for (int i = 0; i < 6; ++i) t[phase][i] = static_cast<float>(w[i] / sum);
    }
    return t;
  }();
  return table;
}

// Lanczos-3 sample of an 8-bit BGR image at a pixel position (integer = pixel centre); within
// three pixels of the border, bilinear.
bool SampleLanczos(const cv::Mat& image, const Eigen::Vector2d& px, cv::Vec3d* out) {
  const double x = px.x(), y = px.y();
  if (!(x >= 2.0 && y >= 2.0 && x < image.cols - 3 && y < image.rows - 3))
    return SampleBilinear(image, px, out);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const auto& table = LanczosWeights();
  const auto& wx = table[static_cast<int>(std::lround((x - x0) * kLanczosPhases))];
  const auto& wy = table[static_cast<int>(std::lround((y - y0) * kLanczosPhases))];
  // Down the 6 rows first (18 contiguous bytes each: vectorises), then across the 6 pixels.
  float column[18] = {};
  for (int j = 0; j < 6; ++j) {
    const auto* row = image.ptr<std::uint8_t>(y0 - 2 + j) + 3 * (x0 - 2);
    for (int n = 0; n < 18; ++n) column[n] += wy[j] * static_cast<float>(row[n]);
  }
  float acc[3] = {0.0f, 0.0f, 0.0f};
  for (int i = 0; i < 6; ++i)
    for (int k = 0; k < 3; ++k) acc[k] += wx[i] * column[3 * i + k];
  for (int k = 0; k < 3; ++k) (*out)[k] = acc[k];
  return true;
}

// What TransferFace reads.
struct TransferInputs {
  const std::vector<FaceData>& faces;
  const std::vector<View>& views;
  const GroupingResult& grouping;
  const ViewSampler& sampler;
  const TransferOptions& options;
  int size;
};

struct FaceCounts {
  int blended = 0;
  int corrected = 0;  // on the front photo's background
  int occluded = 0;   // hidden in the front photo
};

// The texels of face f (front view v) from the photos, into `map`; texels on the background
// in every view that sees the face go to `holes` (covered, not coloured).
FaceCounts TransferFace(const TransferInputs& in, int f, std::vector<cv::Point>* holes,
                        TransferredTexels* texels, TextureMap* map) {
  FaceCounts counts;
  const FaceData& face = in.faces[f];
  const int v = in.grouping.front_view[f];
  const int nv = in.grouping.views;
  const int size = in.size;
  std::array<Eigen::Vector2d, 3> t;
  for (int i = 0; i < 3; ++i)
    t[i] = Eigen::Vector2d(face.uv[i].x() * size - 0.5, (1.0 - face.uv[i].y()) * size - 0.5);
  std::array<int, 3> seam{-1, -1, -1};
  if (in.options.blend) seam = SeamViews(in.faces, f, v, in.grouping);
  // Other views for texels the front photo shows hidden or on the background, most frontal
  // first: those that see the face whole (the grouping's `seen`) and, for texels hidden but on
  // the object, those facing it whose photo is loaded (a face half under a lace in every view).
  // A texel on the background only takes a view that sees the face whole, else it is a hole.
  const Eigen::Vector3d middle = At(face, kSamples[0]);
  auto cosine = [&](int w) {
    return face.normal.dot((in.views[w].camera().Centre() - middle).normalized());
  };
  const double front_cosine = cosine(v);
  struct Other {
    double cosine;
    int view;
    bool seen;
  };
  std::vector<Other> others;
  const bool occlusion = in.options.zbuffer_max_side > 0;
  if (in.options.correction || occlusion)
    for (int w = 0; w < nv; ++w) {
      if (w == v) continue;
      const bool seen = in.grouping.seen[static_cast<std::size_t>(f) * nv + w] != 0;
      const double c = cosine(w);
      if ((seen && in.options.correction) || (occlusion && c > 0.0 && in.sampler.HasPhoto(w)))
        others.push_back({c, w, seen});
    }
  std::sort(others.begin(), others.end(),
            [](const Other& a, const Other& b) { return a.cosine > b.cosine; });
  int covered = 0;
  ForEachPixelCentreWithBarycentrics(
      t, size, size, [&](int x, int y, const std::array<double, 3>& b) {
        const Eigen::Vector3d p = At(face, b);
        const std::optional<ViewSampler::Located> front = in.sampler.Locate(v, p);
        if (!front) return;
        ViewSampler::Located at = *front;
        int source = v;
        const bool on_object = !in.options.correction || in.sampler.OnObject(v, at);
        if (!on_object || !in.sampler.Visible(v, at, front_cosine)) {
          source = -1;
          for (const Other& w : others) {
            if (!on_object && !w.seen) continue;
            const std::optional<ViewSampler::Located> there = in.sampler.Locate(w.view, p);
            if (there && (!in.options.correction || in.sampler.OnObject(w.view, *there)) &&
                in.sampler.Visible(w.view, *there, w.cosine)) {
              source = w.view;
              at = *there;
              break;
            }
          }
          // Hidden in every view: the front view's colour, as without the test; on the
          // background in every view that sees the face whole: a hole, filled around.
          if (source < 0 && on_object) source = v;
          if (source < 0)
            for (const Other& w : others) {
              if (!w.seen) continue;
              const std::optional<ViewSampler::Located> there = in.sampler.Locate(w.view, p);
              if (there && in.sampler.OnObject(w.view, *there)) {
                source = w.view;
                at = *there;
                break;
              }
            }
          if (source < 0) {
            holes->emplace_back(x, y);
            map->coverage.at<std::uint8_t>(y, x) = 255;
            ++covered;
            return;
          }
          if (source != v) ++(on_object ? counts.occluded : counts.corrected);
        }
        cv::Vec3d colour;
        if (!in.sampler.Sample(source, at, &colour)) return;
        if (source == v && BlendAcrossSeam(in.sampler, seam, b, p, in.options.correction, &colour))
          ++counts.blended;
        map->texture.at<cv::Vec3b>(y, x) = cv::Vec3b(cv::saturate_cast<std::uint8_t>(colour[0]),
                                                     cv::saturate_cast<std::uint8_t>(colour[1]),
                                                     cv::saturate_cast<std::uint8_t>(colour[2]));
        map->coverage.at<std::uint8_t>(y, x) = 255;
        texels->face_sum[f] += colour;
        ++texels->face_count[f];
        ++covered;
      });
  map->texels_per_face[f] = covered;
  const double pixels = ProjectedArea(face, in.views[v].camera());
  map->density_ratio[f] = pixels > 0.0 ? covered / pixels : 0.0;
  return counts;
}

// The part of the photo the mesh projects into, with a margin for bilinear sampling and the
// masks' erosion; the whole photo when a corner is behind the camera.
cv::Rect ProjectedBox(const std::vector<FaceData>& faces, const CameraModel& camera) {
  constexpr int kMargin = 8;  // pixels
  const cv::Rect photo(0, 0, camera.width, camera.height);
  Eigen::AlignedBox2d box;
  for (const FaceData& face : faces)
    for (const Eigen::Vector3d& p : face.p) {
      const auto px = camera.Project(p);
      if (!px) return photo;
      box.extend(*px);
    }
  if (box.isEmpty()) return photo;
  const cv::Point lower(static_cast<int>(std::floor(box.min().x())) - kMargin,
                        static_cast<int>(std::floor(box.min().y())) - kMargin);
  const cv::Point upper(static_cast<int>(std::ceil(box.max().x())) + kMargin + 1,
                        static_cast<int>(std::ceil(box.max().y())) + kMargin + 1);
  const cv::Rect inside = cv::Rect(lower, upper) & photo;
  return inside.area() > 0 ? inside : photo;
}

}  // namespace

ViewSampler::ViewSampler(const std::vector<FaceData>& faces, const std::vector<View>& views,
                         const GroupingResult& grouping, const TransferOptions& options)
    : views_(views),
      photos_(views.size()),
      masks_(views.size()),
      depth_(views.size()),
      origins_(views.size(), Eigen::Vector2d::Zero()),
      gains_(views.size(), cv::Vec3d(1, 1, 1)) {
  const int nv = static_cast<int>(views.size());
  // The photos of the views in use: front views; with correction, the views that see some
  // face; with gains, the views usable for some face. The masks of the views that may serve a
  // texel (with correction).
  std::vector<unsigned char> photo(nv, 0), mask(nv, 0);
  for (const int v : grouping.front_view)
    if (v >= 0) photo[v] = 1;
  for (std::size_t i = 0; i < grouping.seen.size(); ++i)
    if (options.correction && grouping.seen[i]) photo[i % nv] = mask[i % nv] = 1;
  for (std::size_t i = 0; i < grouping.usable.size() && options.gain; ++i)
    if (grouping.usable[i]) photo[i % nv] = 1;
  ParallelFor(views.size(), 1, 0, [&](std::size_t begin, std::size_t end) {
    for (std::size_t v = begin; v < end; ++v) {
      if (!photo[v] && !mask[v]) continue;
      const cv::Rect box = ProjectedBox(faces, views[v].camera());
      origins_[v] = Eigen::Vector2d(box.x, box.y);
      if (photo[v]) photos_[v] = views[v].Image()(box).clone();
      // Shrunk by 2 pixels: the silhouette's edge pixels mix object and background.
      if (mask[v])
        cv::erode(views[v].Mask()(box) >= 128, masks_[v],
                  cv::getStructuringElement(cv::MORPH_ELLIPSE, {5, 5}));
      views[v].ReleasePixels();
      if (photo[v] && options.zbuffer_max_side > 0)
        depth_[v].emplace(faces, views[v].camera(), options.zbuffer_max_side);
    }
  });
}

std::optional<ViewSampler::Located> ViewSampler::Locate(int v, const Eigen::Vector3d& p) const {
  const Eigen::Vector3d c = views_[v].camera().cam_from_world * p;
  if (c.z() <= 1e-6) return std::nullopt;
  return Located{views_[v].camera().ProjectFromCam(c), c.z()};
}

bool ViewSampler::OnObject(int v, const Eigen::Vector3d& p) const {
  if (masks_[v].empty()) return true;
  const std::optional<Located> at = Locate(v, p);
  return at && OnObject(v, *at);
}

bool ViewSampler::OnObject(int v, const Located& at) const {
  if (masks_[v].empty()) return true;
  const Eigen::Vector2d px = at.px - origins_[v];
  const int x = static_cast<int>(std::lround(px.x())), y = static_cast<int>(std::lround(px.y()));
  return x >= 0 && y >= 0 && x < masks_[v].cols && y < masks_[v].rows &&
         masks_[v].at<std::uint8_t>(y, x) >= 128;
}

bool ViewSampler::Sample(int v, const Eigen::Vector3d& p, cv::Vec3d* colour) const {
  if (photos_[v].empty()) return false;
  const std::optional<Located> at = Locate(v, p);
  return at && Sample(v, *at, colour);
}

bool ViewSampler::Sample(int v, const Located& at, cv::Vec3d* colour) const {
  if (photos_[v].empty()) return false;
  if (!SampleLanczos(photos_[v], at.px - origins_[v], colour)) return false;
  for (int k = 0; k < 3; ++k) (*colour)[k] *= gains_[v][k];
  return true;
}

TransferredTexels TransferCharts(const std::vector<FaceData>& faces, const std::vector<View>& views,
                                 const GroupingResult& grouping, const ViewSampler& sampler,
                                 const TransferOptions& options, int size, Progress& progress,
                                 TextureMap* map) {
  const std::size_t nf = faces.size();
  // Faces by chart: charts never share texels, so charts can be filled in parallel.
  int charts = 0;
  for (const FaceData& f : faces) charts = std::max(charts, f.chart + 1);
  std::vector<std::vector<int>> chart_faces(std::max(charts, 1));
  for (std::size_t f = 0; f < nf; ++f)
    chart_faces[std::max(faces[f].chart, 0)].push_back(static_cast<int>(f));
  TransferredTexels texels;
  texels.face_sum.assign(nf, cv::Vec3d(0, 0, 0));
  texels.face_count.assign(nf, 0);
  texels.holes.resize(chart_faces.size());
  const TransferInputs in{faces, views, grouping, sampler, options, size};
  std::atomic<int> blended{0}, corrected{0}, occluded{0};
  std::atomic<std::size_t> charts_done{0};
  ParallelFor(chart_faces.size(), 1, 0, [&](std::size_t begin, std::size_t end) {
    for (std::size_t c = begin; c < end; ++c) {
      for (const int f : chart_faces[c]) {
        if (grouping.front_view[f] < 0) continue;
        const FaceCounts counts = TransferFace(in, f, &texels.holes[c], &texels, map);
        blended += counts.blended;
        corrected += counts.corrected;
        occluded += counts.occluded;
      }
      progress.Report(++charts_done, chart_faces.size());
    }
  });
  map->blended_texels = blended.load();
  map->corrected_texels = corrected.load();
  map->occluded_texels = occluded.load();
  return texels;
}

}  // namespace carousel::texture::internal
