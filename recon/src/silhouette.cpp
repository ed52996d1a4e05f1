#include "carousel/recon/silhouette.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <numbers>
#include <optional>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/core/parallel.h"

namespace carousel::recon {
namespace {

// Longest side of the thumbnail the backdrop and plate models are fitted on, pixels.
constexpr int kFitSize = 320;

// A smooth colour model c(x, y) = sum_k coeff_k * basis_k(x, y), per channel, with x and y
// normalised to [-1, 1] over the image.
struct ColourModel {
  int terms = 6;  // 1: constant, 3: linear, 6: quadratic
  Eigen::Matrix<double, 6, 3> coeff = Eigen::Matrix<double, 6, 3>::Zero();
  double rms = 0.0;

  static std::array<double, 6> Basis(double x, double y) {
    return {1.0, x, y, x * x, x * y, y * y};
  }
  cv::Vec3f At(double x, double y) const {
    const auto b = Basis(x, y);
    cv::Vec3f c;
    for (int ch = 0; ch < 3; ++ch) {
      double v = 0.0;
      for (int k = 0; k < terms; ++k) v += coeff(k, ch) * b[k];
      c[ch] = static_cast<float>(v);
    }
    return c;
  }
};

// The model along image row `ny` (normalised), at the centres of `width` pixels.
void EvaluateRow(const ColourModel& model, double ny, int width, std::vector<cv::Vec3f>* row) {
  // c(x) = r0 + r1 x + r2 x^2 per channel for this row.
  std::array<float, 3> r0{}, r1{}, r2{};
  for (int ch = 0; ch < 3; ++ch) {
    const auto& c = model.coeff;
    r0[ch] = static_cast<float>(c(0, ch) + (model.terms > 1 ? c(2, ch) * ny : 0.0) +
                                (model.terms > 3 ? c(5, ch) * ny * ny : 0.0));
    r1[ch] = static_cast<float>(model.terms > 1 ? c(1, ch) + (model.terms > 3 ? c(4, ch) * ny : 0.0)
                                                : 0.0);
    r2[ch] = static_cast<float>(model.terms > 3 ? c(3, ch) : 0.0);
  }
  const float scale = 2.0f / static_cast<float>(width);
  for (int x = 0; x < width; ++x) {
    const float nx = (static_cast<float>(x) + 0.5f) * scale - 1.0f;
    for (int ch = 0; ch < 3; ++ch) (*row)[x][ch] = r0[ch] + nx * (r1[ch] + nx * r2[ch]);
  }
}

struct Sample {
  double x, y;
  cv::Vec3f colour;
};

// Robust fit: least squares, then re-fit on the samples within max(3 rms, floor) of the model,
// a few times. `seed` marks the samples trusted for the first fit. Returns false when fewer
// than `min_inliers` samples agree with the model.
bool FitColourModel(const std::vector<Sample>& samples, const std::vector<bool>& seed, int terms,
                    double floor_levels, std::size_t min_inliers, ColourModel* model) {
  model->terms = terms;
  // Start from the seeds near their median colour: a least-squares fit to seeds of which a
  // third are the object (framed tight, it covers a side of the border) would be dragged
  // towards it and never recover.
  std::vector<bool> inlier = seed;
  {
    std::array<std::vector<float>, 3> channel;
    for (std::size_t i = 0; i < samples.size(); ++i)
      if (seed[i])
        for (int ch = 0; ch < 3; ++ch) channel[ch].push_back(samples[i].colour[ch]);
    if (channel[0].empty()) return false;
    cv::Vec3f median;
    for (int ch = 0; ch < 3; ++ch) {
      auto& v = channel[ch];
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
      median[ch] = v[v.size() / 2];
    }
    for (std::size_t i = 0; i < samples.size(); ++i)
      inlier[i] = seed[i] && cv::norm(samples[i].colour - median) <= 2.5 * floor_levels;
  }
  for (int iteration = 0; iteration < 6; ++iteration) {
    std::size_t n = 0;
    for (const bool b : inlier) n += b ? 1 : 0;
    if (n < std::max<std::size_t>(min_inliers, static_cast<std::size_t>(terms) * 4)) return false;
    Eigen::MatrixXd a(n, terms);
    Eigen::MatrixXd rhs(n, 3);
    std::size_t row = 0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      if (!inlier[i]) continue;
      const auto basis = ColourModel::Basis(samples[i].x, samples[i].y);
      for (int k = 0; k < terms; ++k) a(row, k) = basis[k];
      for (int ch = 0; ch < 3; ++ch) rhs(row, ch) = samples[i].colour[ch];
      ++row;
    }
    const Eigen::MatrixXd solution = a.colPivHouseholderQr().solve(rhs);
    model->coeff.setZero();
    model->coeff.topRows(terms) = solution;
    double sum_sq = 0.0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      if (!inlier[i]) continue;
      sum_sq += cv::norm(samples[i].colour - model->At(samples[i].x, samples[i].y), cv::NORM_L2SQR);
    }
    model->rms = std::sqrt(sum_sq / static_cast<double>(n));
    // Noise widens the band, but never beyond a few times the floor: clutter is no backdrop.
    const double limit = std::clamp(3.0 * model->rms, floor_levels, 2.5 * floor_levels);
    for (std::size_t i = 0; i < samples.size(); ++i)
      inlier[i] = cv::norm(samples[i].colour - model->At(samples[i].x, samples[i].y)) <= limit;
  }
  std::size_t n = 0;
  for (const bool b : inlier) n += b ? 1 : 0;
  return n >= min_inliers;
}

// The turntable plate's outline in the image, filled (plate), and the rim band where plate and
// backdrop meet: the outline swept over radius +-rim_m and height +-rim_m (the plate's
// thickness, chamfer, and the uncertainty of its height), grown by rim_px (anti-aliasing).
void PlateRegions(const CameraModel& camera, double radius_m, double rim_m, double rim_px,
                  cv::Mat* plate, cv::Mat* rim) {
  *plate = cv::Mat::zeros(camera.height, camera.width, CV_8UC1);
  *rim = cv::Mat::zeros(camera.height, camera.width, CV_8UC1);
  if (radius_m <= 0.0) return;
  constexpr int kPoints = 720;
  constexpr int kShift = 4;  // sub-pixel vertex precision for OpenCV's drawing
  const double limit = 4.0 * std::max(camera.width, camera.height);
  auto project = [&](double r, double t, double z) -> std::optional<cv::Point> {
    const auto pixel = camera.Project({r * std::cos(t), r * std::sin(t), z});
    if (!pixel || std::abs(pixel->x()) > limit || std::abs(pixel->y()) > limit) return {};
    return cv::Point(cvRound(pixel->x() * (1 << kShift)), cvRound(pixel->y() * (1 << kShift)));
  };
  std::vector<cv::Point> outline;
  for (int i = 0; i < kPoints; ++i)
    if (const auto p = project(radius_m, 2.0 * std::numbers::pi * i / kPoints, 0.0))
      outline.push_back(*p);
  if (outline.size() < 3) return;
  cv::fillPoly(*plate, std::vector<std::vector<cv::Point>>{outline}, cv::Scalar(255), cv::LINE_8,
               kShift);
  // Band: per outline segment, the convex hull of the swept corners.
  const double r_in = std::max(0.0, radius_m - rim_m);
  const double r_out = radius_m + rim_m;
  for (int i = 0; i < kPoints; ++i) {
    std::vector<cv::Point> corners;
    for (const int step : {i, i + 1}) {
      const double t = 2.0 * std::numbers::pi * step / kPoints;
      for (const double r : {r_in, r_out})
        for (const double z : {-rim_m, rim_m})
          if (const auto p = project(r, t, z)) corners.push_back(*p);
    }
    if (corners.size() < 3) continue;
    std::vector<cv::Point> hull;
    cv::convexHull(corners, hull);
    cv::fillConvexPoly(*rim, hull, cv::Scalar(255), cv::LINE_8, kShift);
  }
  const int grow = static_cast<int>(std::ceil(rim_px));
  if (grow > 0)
    cv::dilate(*rim, *rim,
               cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * grow + 1, 2 * grow + 1)));
}

double Norm3(const cv::Vec3f& v) { return std::sqrt(v.dot(v)); }

// Distance of colour i from the segment [a, b].
double DistanceToSegment(const cv::Vec3f& i, const cv::Vec3f& a, const cv::Vec3f& b) {
  const cv::Vec3f ab = b - a;
  const double len_sq = ab.dot(ab);
  double t = len_sq > 0.0 ? (i - a).dot(ab) / len_sq : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return Norm3(i - (a + ab * static_cast<float>(t)));
}

class Classifier {
 public:
  explicit Classifier(const SilhouetteOptions& options) : options_(options) {}
  bool IsBackground(const cv::Vec3f& i, const cv::Vec3f& b) const {
    const cv::Vec3f d = i - b;
    if (d.dot(d) <= options_.noise_threshold * options_.noise_threshold) return true;
    const double bb = b.dot(b);
    if (bb <= 1.0) return false;  // black background: only the noise test applies
    const double alpha = i.dot(b) / bb;
    if (alpha < options_.min_shadow_brightness || alpha > options_.max_highlight_brightness)
      return false;
    return Norm3(i - b * static_cast<float>(alpha)) <= options_.chroma_threshold;
  }

 private:
  const SilhouetteOptions& options_;
};

void RemoveSmallComponents(cv::Mat* fg, double min_fraction, int* kept) {
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(*fg, labels, stats, centroids, 8, CV_32S);
  int largest = 0;
  for (int i = 1; i < n; ++i) largest = std::max(largest, stats.at<int>(i, cv::CC_STAT_AREA));
  const double min_area = std::max(4.0, min_fraction * largest);
  std::vector<std::uint8_t> keep(n, 0);
  *kept = 0;
  for (int i = 1; i < n; ++i) {
    if (stats.at<int>(i, cv::CC_STAT_AREA) >= min_area) {
      keep[i] = 255;
      ++*kept;
    }
  }
  for (int y = 0; y < fg->rows; ++y) {
    const int* l = labels.ptr<int>(y);
    std::uint8_t* m = fg->ptr<std::uint8_t>(y);
    for (int x = 0; x < fg->cols; ++x) m[x] = keep[l[x]];
  }
}

void FillSmallHoles(cv::Mat* fg, double max_area) {
  if (max_area < 1.0) return;
  cv::Mat background = 255 - *fg;
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(background, labels, stats, centroids, 4, CV_32S);
  std::vector<std::uint8_t> fill(n, 0);
  for (int i = 1; i < n; ++i) {
    const int x = stats.at<int>(i, cv::CC_STAT_LEFT);
    const int y = stats.at<int>(i, cv::CC_STAT_TOP);
    const int w = stats.at<int>(i, cv::CC_STAT_WIDTH);
    const int h = stats.at<int>(i, cv::CC_STAT_HEIGHT);
    const bool touches_border = x == 0 || y == 0 || x + w == fg->cols || y + h == fg->rows;
    if (!touches_border && stats.at<int>(i, cv::CC_STAT_AREA) <= max_area) fill[i] = 255;
  }
  for (int y = 0; y < fg->rows; ++y) {
    const int* l = labels.ptr<int>(y);
    std::uint8_t* m = fg->ptr<std::uint8_t>(y);
    for (int x = 0; x < fg->cols; ++x) m[x] = static_cast<std::uint8_t>(m[x] | fill[l[x]]);
  }
}

}  // namespace

SilhouetteMethod ParseSilhouetteMethod(const std::string& name) {
  if (name == "key") return SilhouetteMethod::kKey;
  if (name == "difference") return SilhouetteMethod::kDifference;
  throw InvalidArgument("unknown silhouette method '" + name + "' (expected key or difference)");
}

const char* SilhouetteMethodName(SilhouetteMethod method) {
  return method == SilhouetteMethod::kKey ? "key" : "difference";
}

const OptionTable<SilhouetteOptions>& SilhouetteOptions::Fields() {
  using O = SilhouetteOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.AddChoice(&O::method,
                {.name = "method",
                 .help = "silhouettes by keying against the backdrop, or by differencing against "
                         "background plates (backgrounds/cam<C>.jpg)"},
                {{"key", SilhouetteMethod::kKey}, {"difference", SilhouetteMethod::kDifference}});
    t.Add(&O::noise_threshold, {.name = "noise-threshold",
                                .help = "colour distance that is always background (noise, JPEG)",
                                .unit = "8-bit levels",
                                .min = 0,
                                .advanced = true});
    t.Add(&O::chroma_threshold, {.name = "chroma-threshold",
                                 .help = "largest chromaticity distortion of a background pixel",
                                 .unit = "8-bit levels",
                                 .min = 0,
                                 .min_exclusive = true,
                                 .advanced = true});
    t.Add(&O::min_shadow_brightness,
          {.name = "min-shadow-brightness",
           .help = "a background pixel may be darkened to this fraction of the backdrop (shadows)",
           .min = 0,
           .max = 1,
           .advanced = true});
    t.Add(&O::max_highlight_brightness,
          {.name = "max-highlight-brightness",
           .help = "... or brightened to this multiple of it (highlights, exposure drift)",
           .min = 1,
           .advanced = true});
    t.Add(&O::plate_radius_m, {.name = "plate-radius-m",
                               .help = "turntable plate radius to remove from the silhouettes",
                               .unit = "m",
                               .min = 0,
                               .special = 0,
                               .special_meaning = "none"});
    t.Add(&O::plate_rim_m, {.name = "plate-rim-m",
                            .help = "the plate's rim band (thickness, edge) counted as background",
                            .unit = "m",
                            .min = 0,
                            .max = 0.05,
                            .advanced = true});
    t.Add(&O::plate_rim_px, {.name = "plate-rim-px",
                             .help = "the rim band grown by this many pixels (anti-aliasing)",
                             .unit = "px",
                             .min = 0,
                             .max = 50,
                             .advanced = true});
    t.Add(&O::refine_boundary,
          {.name = "refine-boundary", .help = "boundary refinement by local alpha estimation"});
    t.Add(&O::min_component_fraction,
          {.name = "min-component-fraction",
           .help = "object pieces smaller than this fraction of the largest are dropped",
           .min = 0,
           .max = 1,
           .advanced = true});
    t.Add(&O::max_hole_fraction,
          {.name = "max-hole-fraction",
           .help = "background holes smaller than this fraction of the object are filled",
           .min = 0,
           .max = 1,
           .advanced = true});
    return t;
  }();
  return table;
}

void SilhouetteOptions::Validate() const {
  Fields().Check(*this);
  CAROUSEL_THROW_IF(threads < 0, InvalidArgument, "SilhouetteOptions.threads must be >= 0");
}

cv::Mat ComputeSilhouette(const cv::Mat& image, const CameraModel& camera,
                          const SilhouetteOptions& options, const cv::Mat& background,
                          const std::string& name, SilhouetteStats* stats) {
  options.Validate();
  CAROUSEL_THROW_IF(image.empty() || image.type() != CV_8UC3, InvalidArgument,
                    name << ": silhouettes need an 8-bit BGR photo");
  CAROUSEL_THROW_IF(image.cols != camera.width || image.rows != camera.height, InvalidArgument,
                    name << ": photo is " << image.cols << "x" << image.rows
                         << " but its camera is " << camera.width << "x" << camera.height);
  const bool difference = options.method == SilhouetteMethod::kDifference;
  if (difference) {
    CAROUSEL_THROW_IF(background.empty(), InvalidArgument,
                      name << ": the difference method needs a background plate (a photo of "
                              "the empty turntable by the same camera)");
    CAROUSEL_THROW_IF(background.type() != CV_8UC3 || background.size() != image.size(),
                      InvalidArgument,
                      name << ": background plate is " << background.cols << "x" << background.rows
                           << " and not an 8-bit BGR image like the photo (" << image.cols << "x"
                           << image.rows << ")");
  }
  const int width = image.cols;
  const int height = image.rows;
  cv::Mat plate, rim;
  PlateRegions(camera, difference ? 0.0 : options.plate_radius_m, options.plate_rim_m,
               options.plate_rim_px, &plate, &rim);

  // --- the expected background colour per pixel ---------------------------------------------
  ColourModel backdrop;
  ColourModel plate_colour;
  bool have_plate = false;
  cv::Mat smoothed_background;
  if (difference) {
    cv::GaussianBlur(background, smoothed_background, cv::Size(5, 5), 1.0);
  } else {
    const double scale = std::min(1.0, static_cast<double>(kFitSize) / std::max(width, height));
    cv::Mat small, small_plate;
    cv::resize(image, small, cv::Size(), scale, scale, cv::INTER_AREA);
    // Fit samples stay clear of the rim band by a thumbnail pixel.
    const cv::Mat pad = cv::getStructuringElement(
        cv::MORPH_RECT, cv::Size(2 * static_cast<int>(std::ceil(1.0 / scale)) + 1,
                                 2 * static_cast<int>(std::ceil(1.0 / scale)) + 1));
    cv::Mat plate_grown, plate_inner, small_plate_inner;
    cv::dilate(plate | rim, plate_grown, pad);
    cv::resize(plate_grown, small_plate, small.size(), 0, 0, cv::INTER_NEAREST);
    cv::erode(plate & ~rim, plate_inner, pad);
    cv::resize(plate_inner, small_plate_inner, small.size(), 0, 0, cv::INTER_NEAREST);
    std::vector<Sample> backdrop_samples, plate_samples;
    std::vector<bool> backdrop_seed, plate_seed;
    const int border = std::max(2, small.cols / 12);
    for (int y = 0; y < small.rows; ++y) {
      for (int x = 0; x < small.cols; ++x) {
        const auto& c = small.at<cv::Vec3b>(y, x);
        // The thumbnail pixel's centre in normalised full-image coordinates.
        const double fx = ((x + 0.5) / scale) / width * 2.0 - 1.0;
        const double fy = ((y + 0.5) / scale) / height * 2.0 - 1.0;
        Sample s{fx, fy, cv::Vec3f(c[0], c[1], c[2])};
        if (small_plate_inner.at<std::uint8_t>(y, x)) {
          plate_samples.push_back(s);
          plate_seed.push_back(true);
        } else if (!small_plate.at<std::uint8_t>(y, x)) {
          backdrop_samples.push_back(s);
          const bool at_border =
              x < border || y < border || x >= small.cols - border || y >= small.rows - border;
          backdrop_seed.push_back(at_border);
        }
      }
    }
    const auto min_backdrop = std::max<std::size_t>(50, backdrop_samples.size() / 10);
    const double floor = std::max(12.0, 2.0 * options.noise_threshold);
    // A side of the border may be covered by the object: seed with the border, then let the
    // robust fit reject what does not agree.
    if (!FitColourModel(backdrop_samples, backdrop_seed, 6, floor, min_backdrop, &backdrop)) {
      throw FormatError(name,
                        "no backdrop to key against: fewer than 10% of the pixels around "
                        "the object agree with a smooth backdrop colour (object filling "
                        "the frame, or a cluttered background; use the difference method)");
    }
    if (!plate_samples.empty()) {
      // All plate pixels seed the fit, which starts from those near their median colour:
      // the object may cover part of the plate.
      const auto min_plate = std::max<std::size_t>(10, plate_samples.size() / 5);
      have_plate = FitColourModel(plate_samples, plate_seed, 3, floor, min_plate, &plate_colour) ||
                   FitColourModel(plate_samples, plate_seed, 1, floor, min_plate, &plate_colour);
      if (!have_plate)
        CAROUSEL_LOG_WARN(name << ": the turntable plate is hidden; it is treated as backdrop");
    }
  }

  // --- classification --------------------------------------------------------------------------
  const Classifier classifier(options);
  const double rim_tolerance = options.noise_threshold + options.chroma_threshold;
  auto expected = [&](int x, int y) -> cv::Vec3f {
    if (difference) {
      const auto& b = smoothed_background.at<cv::Vec3b>(y, x);
      return {static_cast<float>(b[0]), static_cast<float>(b[1]), static_cast<float>(b[2])};
    }
    const double nx = (x + 0.5) / width * 2.0 - 1.0;
    const double ny = (y + 0.5) / height * 2.0 - 1.0;
    if (have_plate && plate.at<std::uint8_t>(y, x)) return plate_colour.At(nx, ny);
    return backdrop.At(nx, ny);
  };
  // Per row, the models are quadratics in x: evaluated once per row into buffers.
  cv::Mat fg(height, width, CV_8UC1);
  std::vector<cv::Vec3f> backdrop_row(width), plate_row(width);
  for (int y = 0; y < height; ++y) {
    const auto* in = image.ptr<cv::Vec3b>(y);
    auto* out = fg.ptr<std::uint8_t>(y);
    const auto* rim_row = rim.ptr<std::uint8_t>(y);
    const auto* plate_mask_row = plate.ptr<std::uint8_t>(y);
    const auto* smoothed_row = difference ? smoothed_background.ptr<cv::Vec3b>(y) : nullptr;
    const double ny = (y + 0.5) / height * 2.0 - 1.0;
    if (!difference) {
      EvaluateRow(backdrop, ny, width, &backdrop_row);
      if (have_plate) EvaluateRow(plate_colour, ny, width, &plate_row);
    }
    for (int x = 0; x < width; ++x) {
      const cv::Vec3f i(in[x][0], in[x][1], in[x][2]);
      cv::Vec3f b;
      if (difference)
        b = cv::Vec3f(smoothed_row[x][0], smoothed_row[x][1], smoothed_row[x][2]);
      else
        b = have_plate && plate_mask_row[x] ? plate_row[x] : backdrop_row[x];
      bool is_background = classifier.IsBackground(i, b);
      if (!is_background && have_plate && rim_row[x]) {
        // Rim: the pixel may blend plate and backdrop, or be either.
        const cv::Vec3f& bb = backdrop_row[x];
        const cv::Vec3f& p = plate_row[x];
        is_background = classifier.IsBackground(i, bb) || classifier.IsBackground(i, p) ||
                        DistanceToSegment(i, bb, p) <= rim_tolerance;
      }
      out[x] = is_background ? 0 : 255;
    }
  }

  int components = 0;
  RemoveSmallComponents(&fg, options.min_component_fraction, &components);
  const double object_area = cv::countNonZero(fg);
  FillSmallHoles(&fg, options.max_hole_fraction * object_area);

  // --- boundary refinement: local alpha from the colour line between B and F ------------------
  if (options.refine_boundary && object_area > 0) {
    constexpr int kBand = 2;    // pixels either side of the boundary
    constexpr int kWindow = 9;  // neighbourhood for the object colour F
    cv::Rect roi = cv::boundingRect(fg);
    roi.x -= kWindow + kBand;
    roi.y -= kWindow + kBand;
    roi.width += 2 * (kWindow + kBand);
    roi.height += 2 * (kWindow + kBand);
    roi &= cv::Rect(0, 0, width, height);
    const cv::Mat fg_roi = fg(roi);
    cv::Mat grown, shrunk, confident;
    const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5));
    cv::dilate(fg_roi, grown, kernel);
    cv::erode(fg_roi, shrunk, kernel);
    cv::erode(fg_roi, confident, kernel, cv::Point(-1, -1), 1);
    cv::Mat weight;
    confident.convertTo(weight, CV_32F, 1.0 / 255.0);
    cv::Mat colour;
    image(roi).convertTo(colour, CV_32FC3);
    cv::Mat weighted;
    cv::Mat weight3;
    cv::merge(std::vector<cv::Mat>{weight, weight, weight}, weight3);
    cv::multiply(colour, weight3, weighted);
    cv::Mat sum_colour, sum_weight;
    cv::boxFilter(weighted, sum_colour, CV_32F, cv::Size(kWindow, kWindow), cv::Point(-1, -1),
                  false);
    cv::boxFilter(weight, sum_weight, CV_32F, cv::Size(kWindow, kWindow), cv::Point(-1, -1), false);
    cv::Mat refined = fg_roi.clone();
    const double min_contrast = 2.0 * std::max(options.noise_threshold, 4.0);
    for (int y = 0; y < roi.height; ++y) {
      for (int x = 0; x < roi.width; ++x) {
        if (!grown.at<std::uint8_t>(y, x) || shrunk.at<std::uint8_t>(y, x)) continue;
        const float w = sum_weight.at<float>(y, x);
        if (w < 1.0f) continue;
        const cv::Vec3f f = sum_colour.at<cv::Vec3f>(y, x) / w;
        const cv::Vec3f b = expected(x + roi.x, y + roi.y);
        const cv::Vec3f fb = f - b;
        const double contrast_sq = fb.dot(fb);
        if (contrast_sq < min_contrast * min_contrast) continue;
        const double alpha = (colour.at<cv::Vec3f>(y, x) - b).dot(fb) / contrast_sq;
        refined.at<std::uint8_t>(y, x) = alpha >= 0.5 ? 255 : 0;
      }
    }
    refined.copyTo(fg(roi));
    RemoveSmallComponents(&fg, options.min_component_fraction, &components);
  }

  if (stats != nullptr) {
    stats->object_fraction = cv::countNonZero(fg) / static_cast<double>(fg.total());
    stats->backdrop_residual = backdrop.rms;
    stats->components = components;
  }
  return fg;
}

SilhouettesResult ComputeSilhouettes(const std::vector<View>& views,
                                     const std::vector<cv::Mat>& backgrounds,
                                     const SilhouetteOptions& options, Progress& progress) {
  options.Validate();
  if (options.method == SilhouetteMethod::kDifference) {
    CAROUSEL_THROW_IF(backgrounds.size() != views.size(), InvalidArgument,
                      "the difference method needs a background plate for each of the "
                          << views.size() << " views (got " << backgrounds.size() << ")");
  }
  SilhouettesResult result;
  result.masks.resize(views.size());
  result.stats.resize(views.size());
  progress.BeginStage("silhouettes");
  std::atomic<std::size_t> done{0};
  ParallelFor(views.size(), 1, options.threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      progress.CheckCancelled();
      const View& view = views[i];
      const cv::Mat background =
          options.method == SilhouetteMethod::kDifference ? backgrounds[i] : cv::Mat();
      result.masks[i] = ComputeSilhouette(view.Image(), view.camera(), options, background,
                                          view.name(), &result.stats[i]);
      view.ReleasePixels();
      progress.Report(++done, views.size());
    }
  });
  progress.EndStage();
  return result;
}

double MaskIoU(const cv::Mat& a, const cv::Mat& b) {
  CAROUSEL_THROW_IF(a.size() != b.size() || a.type() != CV_8UC1 || b.type() != CV_8UC1,
                    InvalidArgument, "MaskIoU: masks must be 8-bit and of the same size");
  const cv::Mat ma = a >= 128;
  const cv::Mat mb = b >= 128;
  const double intersection = cv::countNonZero(ma & mb);
  const double united = cv::countNonZero(ma | mb);
  return united > 0 ? intersection / united : 1.0;
}

}  // namespace carousel::recon
