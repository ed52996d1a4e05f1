#include "carousel/texture/held_out.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/parallel.h"
#include "carousel/core/raster.h"

namespace carousel::texture {
namespace {

// ---- colour: 8-bit sRGB <-> linear --------------------------------------------------------

float SrgbToLinear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

const std::array<float, 256>& LinearOfByte() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[i] = SrgbToLinear(static_cast<float>(i) / 255.0f);
    return t;
  }();
  return table;
}

std::uint8_t ByteOfLinear(float linear) {
  if (!(linear > 0.0f)) return 0;  // also NaN
  const float c = std::min(linear, 1.0f);
  const float srgb =
      c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;  // 0..1
  return static_cast<std::uint8_t>(std::lround(std::clamp(255.0f * srgb, 0.0f, 255.0f)));
}

// ---- texture sampling ---------------------------------------------------------------------

// The texture and its mip pyramid (level 0 = full size), each level half the one before
// (area averaging of the 8-bit sRGB values), down to 1 x 1.
std::vector<cv::Mat> MipPyramid(const cv::Mat& texture, bool mipmaps) {
  std::vector<cv::Mat> levels = {texture};
  while (mipmaps && (levels.back().cols > 1 || levels.back().rows > 1)) {
    const cv::Mat& last = levels.back();
    cv::Mat next;
    cv::resize(last, next, cv::Size(std::max(1, last.cols / 2), std::max(1, last.rows / 2)), 0, 0,
               cv::INTER_AREA);
    levels.push_back(next);
  }
  return levels;
}

// Bilinear sample (linear RGB) at (u, v), image convention; texel centres at (i + 0.5) / size.
Eigen::Vector3f Bilinear(const cv::Mat& level, float u, float v, TexturedModel::Wrap wrap) {
  const bool repeat = wrap == TexturedModel::Wrap::kRepeat;
  if (repeat) {
    u -= std::floor(u);
    v -= std::floor(v);
  }
  const float x = u * level.cols - 0.5f, y = v * level.rows - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const float ax = x - fx, ay = y - fy;
  auto index = [repeat](int i, int n) {
    return repeat ? ((i % n) + n) % n : std::clamp(i, 0, n - 1);
  };
  // Clamp in float first: far outside coordinates must not overflow int.
  const int ix = static_cast<int>(std::clamp(fx, -2.0f, static_cast<float>(level.cols) + 1.0f));
  const int iy = static_cast<int>(std::clamp(fy, -2.0f, static_cast<float>(level.rows) + 1.0f));
  const int x0 = index(ix, level.cols), x1 = index(ix + 1, level.cols);
  const int y0 = index(iy, level.rows), y1 = index(iy + 1, level.rows);
  const auto& linear = LinearOfByte();
  auto texel = [&](int tx, int ty) {
    const cv::Vec3b& p = level.at<cv::Vec3b>(ty, tx);
    return Eigen::Vector3f(linear[p[0]], linear[p[1]], linear[p[2]]);  // BGR
  };
  return (1 - ay) * ((1 - ax) * texel(x0, y0) + ax * texel(x1, y0)) +
         ay * ((1 - ax) * texel(x0, y1) + ax * texel(x1, y1));
}

Eigen::Vector3f Trilinear(const std::vector<cv::Mat>& levels, float u, float v, float lod,
                          TexturedModel::Wrap wrap) {
  const int last = static_cast<int>(levels.size()) - 1;
  lod = std::clamp(lod, 0.0f, static_cast<float>(last));
  const int l0 = static_cast<int>(lod);
  const float f = lod - static_cast<float>(l0);
  Eigen::Vector3f a = Bilinear(levels[l0], u, v, wrap);
  if (f < 1e-3f || l0 == last) return a;
  return (1 - f) * a + f * Bilinear(levels[l0 + 1], u, v, wrap);
}

// Mip level of each triangle: half the log2 of its texels per pixel of screen area (from its
// projected corners); 0 where it does not project.
std::vector<float> TriangleLods(const TexturedModel& model, const CameraModel& camera) {
  std::vector<float> lods(model.triangles.size(), 0.0f);
  const double texels = static_cast<double>(model.texture.cols) * model.texture.rows;
  for (std::size_t i = 0; i < model.triangles.size(); ++i) {
    const Eigen::Vector3i& t = model.triangles[i];
    std::array<Eigen::Vector2d, 3> p;
    bool projected = true;
    for (int k = 0; k < 3 && projected; ++k) {
      const auto pixel = camera.Project(model.positions[t[k]]);
      projected = pixel.has_value() && pixel->allFinite();
      if (projected) p[k] = *pixel;
    }
    if (!projected) continue;
    const Eigen::Vector2d s1 = p[1] - p[0], s2 = p[2] - p[0];
    const double screen_area2 = std::abs(s1.x() * s2.y() - s2.x() * s1.y());
    const Eigen::Vector2f e1 = model.uvs[t[1]] - model.uvs[t[0]];
    const Eigen::Vector2f e2 = model.uvs[t[2]] - model.uvs[t[0]];
    const double uv_area2 =
        std::abs(static_cast<double>(e1.x()) * e2.y() - static_cast<double>(e2.x()) * e1.y());
    if (screen_area2 > 0.0 && uv_area2 > 0.0)
      lods[i] = static_cast<float>(0.5 * std::log2(uv_area2 * texels / screen_area2));
  }
  return lods;
}

// ---- scores --------------------------------------------------------------------------------

// Mean SSIM (Gaussian 11x11, sigma 1.5, the usual constants) of two BGR images over `mask`.
double MaskedSsim(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  const cv::Scalar c1 = cv::Scalar::all(6.5025),
                   c2 = cv::Scalar::all(58.5225);  // (0.01, 0.03 x 255)^2
  cv::Mat fa, fb;
  a.convertTo(fa, CV_32F);
  b.convertTo(fb, CV_32F);
  auto blur = [](const cv::Mat& m) {
    cv::Mat out;
    cv::GaussianBlur(m, out, cv::Size(11, 11), 1.5);
    return out;
  };
  const cv::Mat mu_a = blur(fa), mu_b = blur(fb);
  const cv::Mat mu_aa = mu_a.mul(mu_a), mu_bb = mu_b.mul(mu_b), mu_ab = mu_a.mul(mu_b);
  const cv::Mat s_aa = blur(fa.mul(fa)) - mu_aa, s_bb = blur(fb.mul(fb)) - mu_bb,
                s_ab = blur(fa.mul(fb)) - mu_ab;
  cv::Mat t1, t2, t3, t4;
  cv::add(2 * mu_ab, c1, t1);
  cv::add(2 * s_ab, c2, t2);
  cv::add(mu_aa + mu_bb, c1, t3);
  cv::add(s_aa + s_bb, c2, t4);
  cv::Mat map;
  cv::divide(t1.mul(t2), t3.mul(t4), map);
  const cv::Scalar mean = cv::mean(map, mask);
  return (mean[0] + mean[1] + mean[2]) / 3.0;
}

}  // namespace

void ModelRenderOptions::Validate() const {
  CAROUSEL_THROW_IF(
      samples_per_axis < 1 || samples_per_axis > 4, InvalidArgument,
      "ModelRenderOptions.samples_per_axis must be in 1..4, got " << samples_per_axis);
  CAROUSEL_THROW_IF(!(max_edge_error_px > 0), InvalidArgument,
                    "ModelRenderOptions.max_edge_error_px must be > 0");
  CAROUSEL_THROW_IF(threads < 0, InvalidArgument, "ModelRenderOptions.threads must be >= 0");
}

ModelRendering RenderTexturedModel(const TexturedModel& model, const CameraModel& camera,
                                   const ModelRenderOptions& options) {
  options.Validate();
  model.Validate();
  camera.Validate();
  MeshRasterOptions raster_options;
  raster_options.samples_per_axis = options.samples_per_axis;
  raster_options.max_edge_error_px = options.max_edge_error_px;
  raster_options.threads = options.threads;
  const MeshRaster raster = RasterizeMesh(model.positions, model.triangles, camera, raster_options);
  const std::vector<cv::Mat> levels = MipPyramid(model.texture, options.mipmaps);
  const std::vector<float> lods = TriangleLods(model, camera);

  const auto& linear = LinearOfByte();
  auto to_linear = [&](const cv::Vec3b& bgr) {
    return Eigen::Vector3f(linear[bgr[0]], linear[bgr[1]], linear[bgr[2]]);
  };
  const Eigen::Vector3f top = to_linear(options.backdrop_top_bgr);
  const Eigen::Vector3f bottom = to_linear(options.backdrop_bottom_bgr);
  const float per_pixel = static_cast<float>(raster.samples_per_pixel());

  ModelRendering out;
  out.image.create(camera.height, camera.width, CV_8UC3);
  out.mask = raster.Mask();
  ParallelFor(camera.height, 16, options.threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t yy = begin; yy < end; ++yy) {
      const int y = static_cast<int>(yy);
      const float fy = camera.height > 1 ? static_cast<float>(y) / (camera.height - 1) : 0.0f;
      const Eigen::Vector3f backdrop = (1 - fy) * top + fy * bottom;
      auto* row = out.image.ptr<cv::Vec3b>(y);
      for (int x = 0; x < camera.width; ++x) {
        Eigen::Vector3f colour = Eigen::Vector3f::Zero();
        int covered = 0;
        for (const RasterFragment& f : raster.Fragments(x, y)) {
          const Eigen::Vector3i& t = model.triangles[f.face];
          const Eigen::Vector2f uv = f.barycentric[0] * model.uvs[t[0]] +
                                     f.barycentric[1] * model.uvs[t[1]] +
                                     f.barycentric[2] * model.uvs[t[2]];
          colour += (static_cast<float>(f.samples) / per_pixel) *
                    Trilinear(levels, uv.x(), uv.y(), lods[f.face], model.wrap);
          covered += f.samples;
        }
        colour += (static_cast<float>(raster.samples_per_pixel() - covered) / per_pixel) * backdrop;
        for (int c = 0; c < 3; ++c) row[x][c] = ByteOfLinear(colour[c]);
      }
    }
  });
  return out;
}

HeldOutScore CompareWithPhoto(const ModelRendering& rendering, const cv::Mat& photo,
                              const cv::Mat& reference_mask, int view) {
  CAROUSEL_THROW_IF(rendering.image.type() != CV_8UC3 || rendering.mask.type() != CV_8UC1 ||
                        rendering.image.size() != rendering.mask.size(),
                    InvalidArgument, "CompareWithPhoto: the rendering must be 8-bit BGR + mask");
  CAROUSEL_THROW_IF(
      photo.type() != CV_8UC3 || photo.size() != rendering.image.size(), InvalidArgument,
      "CompareWithPhoto: the photo is " << photo.cols << "x" << photo.rows
                                        << " (8-bit BGR expected) but the rendering "
                                        << rendering.image.cols << "x" << rendering.image.rows);
  CAROUSEL_THROW_IF(!reference_mask.empty() && (reference_mask.type() != CV_8UC1 ||
                                                reference_mask.size() != rendering.image.size()),
                    InvalidArgument,
                    "CompareWithPhoto: the reference mask is "
                        << reference_mask.cols << "x" << reference_mask.rows
                        << " (8-bit expected) but the rendering " << rendering.image.cols << "x"
                        << rendering.image.rows);
  HeldOutScore score;
  score.view = view;
  score.has_reference = !reference_mask.empty();
  const cv::Mat mask = (score.has_reference ? reference_mask : rendering.mask) >= 128;
  cv::Mat diff;
  cv::absdiff(rendering.image, photo, diff);
  diff.convertTo(diff, CV_64F);
  const cv::Scalar mse = cv::mean(diff.mul(diff), mask);
  const double m = (mse[0] + mse[1] + mse[2]) / 3.0;
  score.psnr_db = m > 0.0 ? 10.0 * std::log10(255.0 * 255.0 / m) : 99.0;
  score.ssim = MaskedSsim(rendering.image, photo, mask);
  const cv::Mat rendered = rendering.mask >= 128;
  const double both = cv::countNonZero(rendered & mask), either = cv::countNonZero(rendered | mask);
  score.mask_agreement = either > 0 ? both / either : 0.0;
  return score;
}

HeldOutScore ScoreHeldOutView(const TexturedModel& model, const View& view, int index,
                              const cv::Mat& reference_mask, const ModelRenderOptions& options) {
  const ModelRendering rendering = RenderTexturedModel(model, view.camera(), options);
  return CompareWithPhoto(rendering, view.Image(), reference_mask, index);
}

double MeanPsnrDb(const std::vector<HeldOutScore>& scores) {
  double sum = 0.0;
  for (const HeldOutScore& s : scores) sum += s.psnr_db / static_cast<double>(scores.size());
  return sum;
}

double MeanSsim(const std::vector<HeldOutScore>& scores) {
  double sum = 0.0;
  for (const HeldOutScore& s : scores) sum += s.ssim / static_cast<double>(scores.size());
  return sum;
}

}  // namespace carousel::texture
