#include "carousel/recon/silhouette.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <functional>
#include <numbers>
#include <optional>
#include <sstream>

#include <Eigen/Dense>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/imgproc/detail/gcgraph.hpp>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/core/parallel.h"
#include "carousel/recon/visual_hull.h"

namespace carousel::recon {
namespace {

// Longest side of the thumbnail the backdrop and plate models are fitted on, pixels.
constexpr int kFitSize = 240;
// Longest side of the copy the candidates' pieces are found on, pixels.
constexpr double kPieceSize = 1024.0;
// Pixels of the working copy everything but the boundary refinement runs on (about, where the
// photo is reduced by an integer factor).
constexpr double kWorkPixels = 1.0e6;
// Longest side of the region the graph cut segments, working pixels, and its iterations.
constexpr int kGraphCutSize = 480;
constexpr int kGraphCutIterations = 2;
// Multi-view consistency: with this many views or more; a view is re-decided when it has
// more than this many hole pixels (at the priors' size, at most 1024 along the longest side)
// well inside the others' hull, or as many (and this fraction of its silhouette) outside it.
constexpr std::size_t kMinConsistencyViews = 4;
constexpr double kMinDisagreementPx = 25.0;
constexpr double kMinDisagreementFraction = 0.002;
// A view disagreeing over more than this fraction of its silhouette is not repaired.
constexpr double kMaxRepairFraction = 0.25;
// A segmentation that keeps less than this fraction of the largest candidate piece means the
// border band showed the object's colours.
constexpr double kMinKeptOfCandidates = 0.1;
// The plate counts when this fraction of its inner edge is seen against the backdrop.
constexpr double kMinVisiblePlateEdge = 0.1;
// The views of a camera agree on the plate's colour (AgreedPlates) when it has at least this
// many keyed views, and a colour is the plate's when at least this many views saw it.
constexpr std::size_t kMinPlateAgreementViews = 3;
constexpr int kMinPlateAgreement = 2;
// A silhouette covers at least this fraction of the photo.
constexpr double kMinObjectFraction = 1e-4;
// 8-bit level from which a pixel counts as clipped white.
constexpr int kClippedLevel = 250;
// Boundary refinement: a pixel whose colour lies farther than this fraction of the object's
// contrast from the line between its background and object colours is no mix of the two.
constexpr double kThirdColour = 0.3;
// ... and it is the background's colour scaled (in linear light) when the scale is within these
// bounds (a shadow, a sheen) and its chromaticity within this fraction of its brightness.
constexpr double kMinBackgroundScale = 0.2;
constexpr double kMaxBackgroundScale = 1.4;
constexpr double kMaxBackgroundChroma = 0.15;
// The second matting pass takes the colours either side from at most this far, pixels.
constexpr float kLocalReach = 2.0f;
// Keyed silhouettes whose outline runs along the plate's rim for this fraction of its length
// in most views (the median) stop where the plate does: measured 16-17 % in every view of a
// white bottle before a white sweep, at most 7.5 % in half of the views of the shared models
// (a low shoe's top near the far rim: 16 % in a few).
constexpr double kMaxRimOutline = 0.13;
// A mask shot's lit panel is at least this bright (8-bit levels at the centre).
constexpr double kMinBacklitLevel = 96.0;
// A hole the object encloses in a mask shot whose mean alpha reaches this lets the panel
// through dimmed: a see-through part, filled.
constexpr float kSeeThroughAlpha = 0.06f;
// A mask shot whose darkest part lets more than this fraction of the panel's light through
// shows no object.
constexpr float kMaxSeeThroughRatio = 0.9f;

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
    // The normal equations (the basis is of order 1 over the image: well conditioned); a
    // QR of tens of thousands of rows per iteration cost more than the rest of the keying.
    Eigen::MatrixXd ata = Eigen::MatrixXd::Zero(terms, terms);
    Eigen::MatrixXd atb = Eigen::MatrixXd::Zero(terms, 3);
    for (std::size_t i = 0; i < samples.size(); ++i) {
      if (!inlier[i]) continue;
      const auto basis = ColourModel::Basis(samples[i].x, samples[i].y);
      for (int k = 0; k < terms; ++k) {
        for (int l = 0; l <= k; ++l) ata(k, l) += basis[k] * basis[l];
        for (int ch = 0; ch < 3; ++ch) atb(k, ch) += basis[k] * samples[i].colour[ch];
      }
    }
    ata = ata.selfadjointView<Eigen::Lower>();
    const Eigen::MatrixXd solution = ata.ldlt().solve(atb);
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
    bool changed = false;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const bool in = cv::norm(samples[i].colour - model->At(samples[i].x, samples[i].y)) <= limit;
      changed = changed || in != inlier[i];
      inlier[i] = in;
    }
    if (!changed) break;  // converged: the same samples would give the same model
  }
  std::size_t n = 0;
  for (const bool b : inlier) n += b ? 1 : 0;
  return n >= min_inliers;
}

// A plate colour model as PlateKeying keeps it, and back; the model's mean over `samples`.
PlateKeying FittedPlate(const ColourModel& model, const std::vector<Sample>& samples) {
  PlateKeying plate;
  plate.state = PlateKeying::State::kFitted;
  plate.terms = model.terms;
  for (int k = 0; k < 6; ++k)
    for (int ch = 0; ch < 3; ++ch) plate.coeff[3 * k + ch] = model.coeff(k, ch);
  cv::Vec3d sum(0.0, 0.0, 0.0);
  for (const Sample& sample : samples) sum += cv::Vec3d(model.At(sample.x, sample.y));
  plate.mean_bgr = samples.empty() ? sum : sum / static_cast<double>(samples.size());
  return plate;
}

ColourModel PlateModel(const PlateKeying& plate) {
  ColourModel model;
  model.terms = plate.terms;
  for (int k = 0; k < 6; ++k)
    for (int ch = 0; ch < 3; ++ch) model.coeff(k, ch) = plate.coeff[3 * k + ch];
  return model;
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

// `rect` grown by `margin` on every side, within `frame`.
cv::Rect Grown(const cv::Rect& rect, int margin, const cv::Rect& frame) {
  return cv::Rect(rect.x - margin, rect.y - margin, rect.width + 2 * margin,
                  rect.height + 2 * margin) &
         frame;
}

// The fraction of the plate's inner edge (just inside the rim band) that shows the plate's
// model with the backdrop's model just outside it: the plate seen against the backdrop.
double VisiblePlateEdge(const cv::Mat& image, const cv::Mat& plate, const cv::Mat& rim,
                        const ColourModel& backdrop, const ColourModel& plate_colour,
                        const Classifier& classifier) {
  // All within the rim band's box, grown by the rings.
  constexpr int kRing = 3;
  cv::Rect box = cv::boundingRect(rim);
  if (box.area() == 0) return 0.0;
  box = Grown(box, kRing, cv::Rect(0, 0, image.cols, image.rows));
  const cv::Mat rim_box = rim(box);
  const cv::Mat plate_box = plate(box);
  cv::Mat near_rim;
  cv::dilate(rim_box, near_rim,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * kRing + 1, 2 * kRing + 1)));
  const cv::Mat inner = near_rim & plate_box & ~rim_box;
  const cv::Mat outer = near_rim & ~plate_box & ~rim_box;
  cv::Mat inner_ok = cv::Mat::zeros(box.size(), CV_8UC1);
  cv::Mat outer_ok = cv::Mat::zeros(box.size(), CV_8UC1);
  for (int y = 0; y < box.height; ++y) {
    const auto* in = image.ptr<cv::Vec3b>(y + box.y) + box.x;
    const auto* i_row = inner.ptr<std::uint8_t>(y);
    const auto* o_row = outer.ptr<std::uint8_t>(y);
    const double ny = (y + box.y + 0.5) / image.rows * 2.0 - 1.0;
    for (int x = 0; x < box.width; ++x) {
      if (!i_row[x] && !o_row[x]) continue;
      const double nx = (x + box.x + 0.5) / image.cols * 2.0 - 1.0;
      const cv::Vec3f c(in[x][0], in[x][1], in[x][2]);
      if (i_row[x] && classifier.IsBackground(c, plate_colour.At(nx, ny)))
        inner_ok.at<std::uint8_t>(y, x) = 255;
      if (o_row[x] && classifier.IsBackground(c, backdrop.At(nx, ny)))
        outer_ok.at<std::uint8_t>(y, x) = 255;
    }
  }
  const double inner_total = cv::countNonZero(inner);
  if (inner_total == 0) return 0.0;
  // Across the rim band: its width is its area over the outline's length (the inner ring is
  // kRing pixels wide). A square reach (separable, fast on 18-Mpx photos) is close enough.
  const double band_width = cv::countNonZero(rim_box) / (inner_total / kRing);
  const int reach = static_cast<int>(std::ceil(band_width)) + kRing + 1;
  cv::Mat outer_near;
  cv::dilate(outer_ok, outer_near,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * reach + 1, 2 * reach + 1)));
  return cv::countNonZero(inner_ok & outer_near) / inner_total;
}

// Returns the largest component's area, pixels.
int RemoveSmallComponents(cv::Mat* fg, double min_fraction, int* kept) {
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
  return largest;
}

// Fills the background holes of at most `max_area` pixels that the object encloses, but not
// those mostly of the backdrop's own colour (`backdrop`, CV_8UC1, 255 where the colour test
// found the expected background; optional): an opening (a tab's loop) stays open.
void FillSmallHoles(cv::Mat* fg, double max_area, const cv::Mat& backdrop = {}) {
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
  if (!backdrop.empty()) {
    std::vector<int> plain(static_cast<std::size_t>(n), 0);
    for (int y = 0; y < fg->rows; ++y) {
      const int* l = labels.ptr<int>(y);
      const std::uint8_t* b = backdrop.ptr<std::uint8_t>(y);
      for (int x = 0; x < fg->cols; ++x)
        if (fill[l[x]] && b[x]) ++plain[static_cast<std::size_t>(l[x])];
    }
    for (int i = 1; i < n; ++i)
      if (fill[i] && 2 * plain[static_cast<std::size_t>(i)] >= stats.at<int>(i, cv::CC_STAT_AREA))
        fill[i] = 0;
  }
  for (int y = 0; y < fg->rows; ++y) {
    const int* l = labels.ptr<int>(y);
    std::uint8_t* m = fg->ptr<std::uint8_t>(y);
    for (int x = 0; x < fg->cols; ++x) m[x] = static_cast<std::uint8_t>(m[x] | fill[l[x]]);
  }
}

// The frame's border band, pixels: a silhouette never reaches into it (a view whose object
// does is rejected by CheckClearOfBorder), so all of it is backdrop, cloth or stand.
int BorderBand(cv::Size size) { return std::max(3, std::min(size.width, size.height) / 100); }

// The expected background colour at a full-resolution pixel.
using ExpectedBackground = std::function<cv::Vec3f(int x, int y)>;

// The colour residuals (photo minus expected background) of the frame's border band, as
// clusters: how the backdrop departs from its smooth model (cloth folds, a stand, a dark
// cloth's sheen) where it is surely backdrop. A residual is compared where it occurs, so a
// white part before a darker patch of a white backdrop stays apart from the backdrop's
// brighter top. `usable` (same size, CV_8UC1) marks the pixels that may be sampled.
class BorderResiduals {
 public:
  BorderResiduals(const cv::Mat& image, const ExpectedBackground& expected, const cv::Mat& usable,
                  int band) {
    cv::Mat samples(0, 3, CV_32F);
    const int step = std::max(
        1, static_cast<int>(std::sqrt(2.0 * band * (image.cols + image.rows) / kMaxSamples)));
    for (int y = 0; y < image.rows; y += step) {
      for (int x = 0; x < image.cols; x += step) {
        const bool in_band =
            x < band || y < band || x >= image.cols - band || y >= image.rows - band;
        if (!in_band || !usable.at<std::uint8_t>(y, x)) continue;
        const auto& c = image.at<cv::Vec3b>(y, x);
        const cv::Vec3f b = expected(x, y);
        const float row[3] = {c[0] - b[0], c[1] - b[1], c[2] - b[2]};
        samples.push_back(cv::Mat(1, 3, CV_32F, const_cast<float*>(row)));
      }
    }
    if (samples.rows < 4 * kClusters) return;
    cv::Mat labels, centres;
    cv::setRNGSeed(1);  // deterministic clusters
    cv::kmeans(samples, kClusters, labels,
               cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 12, 0.5), 1,
               cv::KMEANS_PP_CENTERS, centres);
    std::vector<double> sum_sq(kClusters, 0.0);
    std::vector<int> count(kClusters, 0);
    for (int i = 0; i < samples.rows; ++i) {
      const int k = labels.at<int>(i);
      sum_sq[k] += cv::norm(samples.row(i), centres.row(k), cv::NORM_L2SQR);
      ++count[k];
    }
    for (int k = 0; k < kClusters; ++k) {
      if (count[k] < 3) continue;
      const cv::Vec3f centre(centres.at<float>(k, 0), centres.at<float>(k, 1),
                             centres.at<float>(k, 2));
      clusters_.push_back({centre, std::sqrt(sum_sq[k] / count[k])});
    }
  }
  // Whether residual c is one of the border's: within 3 standard deviations (at least
  // `floor_levels`) of a cluster.
  bool Contains(const cv::Vec3f& c, double floor_levels) const {
    for (const auto& cluster : clusters_) {
      const double reach = std::max(floor_levels, 3.0 * cluster.spread);
      const cv::Vec3f d = c - cluster.centre;
      if (d.dot(d) <= reach * reach) return true;
    }
    return false;
  }

 private:
  static constexpr int kClusters = 6;
  static constexpr double kMaxSamples = 6000.0;
  struct Cluster {
    cv::Vec3f centre;
    double spread;
  };
  std::vector<Cluster> clusters_;
};

// A colour mixture of kMixtureComponents Gaussians (full covariance, 8-bit BGR), as GrabCut's.
constexpr int kMixtureComponents = 5;
// Colour samples a mixture is learned from, at most (a regular subset of the side's pixels).
constexpr int kMixtureSamples = 10000;

class ColourMixture {
 public:
  // Learns the mixture from `samples` (CV_32FC3 rows) and their component (`component`, one
  // int per sample). Components without samples keep weight 0.
  void Learn(const cv::Mat& samples, const std::vector<int>& component) {
    std::array<Eigen::Vector3d, kMixtureComponents> sum;
    std::array<Eigen::Matrix3d, kMixtureComponents> prod;
    std::array<int, kMixtureComponents> count{};
    for (int k = 0; k < kMixtureComponents; ++k) {
      sum[k].setZero();
      prod[k].setZero();
    }
    for (int i = 0; i < samples.rows; ++i) {
      const auto& c = samples.at<cv::Vec3f>(i);
      const Eigen::Vector3d x(c[0], c[1], c[2]);
      const auto k = static_cast<std::size_t>(component[static_cast<std::size_t>(i)]);
      sum[k] += x;
      prod[k] += x * x.transpose();
      ++count[k];
    }
    for (std::size_t k = 0; k < kMixtureComponents; ++k) {
      Gaussian& g = gaussians_[k];
      g.weight = samples.rows > 0 ? static_cast<double>(count[k]) / samples.rows : 0.0;
      if (count[k] == 0) continue;
      g.mean = sum[k] / count[k];
      Eigen::Matrix3d cov = prod[k] / count[k] - g.mean * g.mean.transpose();
      // A component of one flat colour (a clipped highlight, the backdrop's own level) is
      // widened to stay invertible, as GrabCut does.
      cov.diagonal().array() += 0.01;
      const double det = cov.determinant();
      if (!(det > 1e-12)) cov.diagonal().array() += 1.0;
      g.inverse = cov.inverse();
      g.norm = 1.0 / std::sqrt(std::max(cov.determinant(), 1e-12));
    }
  }
  // The mixture's density at colour x (up to the constant (2 pi)^-3/2).
  double Density(const Eigen::Vector3d& x) const {
    double p = 0.0;
    for (const Gaussian& g : gaussians_) {
      if (g.weight <= 0.0) continue;
      const Eigen::Vector3d d = x - g.mean;
      p += g.weight * g.norm * std::exp(-0.5 * d.dot(g.inverse * d));
    }
    return p;
  }
  // The component most likely to have produced x.
  int Component(const Eigen::Vector3d& x) const {
    int best = 0;
    double best_p = -1.0;
    for (int k = 0; k < kMixtureComponents; ++k) {
      const Gaussian& g = gaussians_[static_cast<std::size_t>(k)];
      if (g.weight <= 0.0) continue;
      const Eigen::Vector3d d = x - g.mean;
      const double p = g.weight * g.norm * std::exp(-0.5 * d.dot(g.inverse * d));
      if (p > best_p) {
        best_p = p;
        best = k;
      }
    }
    return best;
  }

 private:
  struct Gaussian {
    double weight = 0.0;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    Eigen::Matrix3d inverse = Eigen::Matrix3d::Identity();
    double norm = 1.0;
  };
  std::array<Gaussian, kMixtureComponents> gaussians_;
};

// A regular subset (at most kMixtureSamples) of the pixels of `image` whose label is one of
// the side's (object: GC_FGD / GC_PR_FGD, background: GC_BGD / GC_PR_BGD), as CV_32FC3 rows.
cv::Mat MixtureSamples(const cv::Mat& image, const cv::Mat& labels, bool object) {
  int count = 0;
  for (int y = 0; y < labels.rows; ++y) {
    const auto* l = labels.ptr<std::uint8_t>(y);
    for (int x = 0; x < labels.cols; ++x) count += ((l[x] & 1) != 0) == object ? 1 : 0;
  }
  const int stride = std::max(1, (count + kMixtureSamples - 1) / kMixtureSamples);
  cv::Mat samples(0, 1, CV_32FC3);
  samples.reserve(static_cast<std::size_t>(count / stride) + 1);
  int seen = 0;
  for (int y = 0; y < labels.rows; ++y) {
    const auto* l = labels.ptr<std::uint8_t>(y);
    const auto* c = image.ptr<cv::Vec3b>(y);
    for (int x = 0; x < labels.cols; ++x) {
      if ((((l[x] & 1) != 0) != object) || seen++ % stride != 0) continue;
      samples.push_back(cv::Vec3f(c[x][0], c[x][1], c[x][2]));
    }
  }
  return samples;
}

// GrabCut's iterated graph cut (a colour mixture per side; an 8-connected, contrast-sensitive
// smoothness term; each iteration re-learns the mixtures from the last cut), solved over the
// undecided pixels only: the sure ones (GC_FGD, GC_BGD) are the terminals, so the cut is the
// one over the whole region, while OpenCV's grabCut pays for every pixel. The mixtures are
// learned from a regular subset of each side's pixels. `labels` (GC codes) is updated.
void IteratedGraphCut(const cv::Mat& image, int iterations, cv::Mat* labels) {
  const int rows = image.rows;
  const int cols = image.cols;
  const auto colour = [&](int y, int x) {
    const auto& c = image.at<cv::Vec3b>(y, x);
    return Eigen::Vector3d(c[0], c[1], c[2]);
  };
  // The neighbours before a pixel in scan order (left, up-left, up, up-right), as GrabCut.
  constexpr std::array<std::array<int, 2>, 4> kBefore{{{0, -1}, {-1, -1}, {-1, 0}, {-1, 1}}};
  // Smoothness: gamma exp(-beta |dI|^2) / distance, beta from the mean squared difference.
  constexpr double kGamma = 50.0;
  double sum_sq = 0.0;
  std::int64_t pairs = 0;
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) {
      for (const auto& d : kBefore) {
        const int ny = y + d[0];
        const int nx = x + d[1];
        if (ny < 0 || nx < 0 || nx >= cols) continue;
        sum_sq += (colour(y, x) - colour(ny, nx)).squaredNorm();
        ++pairs;
      }
    }
  }
  const double beta = sum_sq > 0.0 ? 0.5 * static_cast<double>(pairs) / sum_sq : 0.0;
  const auto smoothness = [&](int y, int x, int ny, int nx) {
    const double w = kGamma * std::exp(-beta * (colour(y, x) - colour(ny, nx)).squaredNorm());
    return (ny != y && nx != x) ? w / std::numbers::sqrt2 : w;
  };
  // The undecided pixels, numbered.
  cv::Mat index(rows, cols, CV_32SC1, cv::Scalar(-1));
  int undecided = 0;
  for (int y = 0; y < rows; ++y) {
    const auto* l = labels->ptr<std::uint8_t>(y);
    auto* i = index.ptr<int>(y);
    for (int x = 0; x < cols; ++x)
      if (l[x] == cv::GC_PR_FGD || l[x] == cv::GC_PR_BGD) i[x] = undecided++;
  }
  if (undecided == 0) return;
  // Mixtures started from k-means (seeded: a photo's silhouette must not depend on the worker
  // or on what it segmented before).
  std::array<ColourMixture, 2> mixtures;  // background, object
  std::array<cv::Mat, 2> samples;
  for (int side = 0; side < 2; ++side) {
    samples[side] = MixtureSamples(image, *labels, side == 1);
    if (samples[side].rows < kMixtureComponents) return;  // nothing to learn a side from
    cv::Mat assignment;
    cv::RNG& rng = cv::theRNG();
    const std::uint64_t saved_state = rng.state;
    rng.state = 0x2545F4914F6CDD1DULL;
    cv::kmeans(samples[side].reshape(1), kMixtureComponents, assignment,
               cv::TermCriteria(cv::TermCriteria::MAX_ITER, 10, 0.0), 1, cv::KMEANS_PP_CENTERS);
    rng.state = saved_state;
    mixtures[side].Learn(samples[side],
                         std::vector<int>(assignment.begin<int>(), assignment.end<int>()));
  }
  // The links, the same in every iteration (only undecided pixels change side): between two
  // undecided pixels an edge; to a sure one, its weight is added to that terminal's (cutting it
  // costs w when the undecided pixel takes the other side; source = object). Both directions
  // of every neighbour pair once: the pair's later pixel looks back.
  struct Link {
    int here, there;
    double weight;
  };
  std::vector<Link> links;
  std::vector<double> to_object(static_cast<std::size_t>(undecided), 0.0);
  std::vector<double> to_background(static_cast<std::size_t>(undecided), 0.0);
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) {
      const int here = index.at<int>(y, x);
      for (const auto& d : kBefore) {
        const int ny = y + d[0];
        const int nx = x + d[1];
        if (ny < 0 || nx < 0 || nx >= cols) continue;
        const int there = index.at<int>(ny, nx);
        if (here < 0 && there < 0) continue;  // both sure: no say in the cut
        const double w = smoothness(y, x, ny, nx);
        if (here >= 0 && there >= 0) {
          links.push_back({here, there, w});
          continue;
        }
        const auto open = static_cast<std::size_t>(here >= 0 ? here : there);
        const std::uint8_t sure =
            here >= 0 ? labels->at<std::uint8_t>(ny, nx) : labels->at<std::uint8_t>(y, x);
        (sure == cv::GC_FGD ? to_object : to_background)[open] += w;
      }
    }
  }
  for (int iteration = 0; iteration < iterations; ++iteration) {
    if (iteration > 0) {
      for (int side = 0; side < 2; ++side) {
        samples[side] = MixtureSamples(image, *labels, side == 1);
        if (samples[side].rows < kMixtureComponents) return;
      }
    }
    // Each sample to its most likely component, then the mixtures learned again.
    for (int side = 0; side < 2; ++side) {
      std::vector<int> component(static_cast<std::size_t>(samples[side].rows));
      for (int i = 0; i < samples[side].rows; ++i) {
        const auto& c = samples[side].at<cv::Vec3f>(i);
        component[static_cast<std::size_t>(i)] =
            mixtures[side].Component(Eigen::Vector3d(c[0], c[1], c[2]));
      }
      mixtures[side].Learn(samples[side], component);
    }
    // The graph: the undecided pixels with their colours' costs on either side, and the links.
    cv::detail::GCGraph<double> graph(static_cast<unsigned>(undecided),
                                      static_cast<unsigned>(2 * links.size()));
    for (int y = 0; y < rows; ++y) {
      const auto* i = index.ptr<int>(y);
      for (int x = 0; x < cols; ++x) {
        if (i[x] < 0) continue;
        const Eigen::Vector3d c = colour(y, x);
        const auto v = static_cast<std::size_t>(i[x]);
        graph.addVtx();
        graph.addTermWeights(
            i[x], -std::log(std::max(mixtures[0].Density(c), 1e-300)) + to_object[v],
            -std::log(std::max(mixtures[1].Density(c), 1e-300)) + to_background[v]);
      }
    }
    for (const Link& link : links) graph.addEdges(link.here, link.there, link.weight, link.weight);
    graph.maxFlow();
    for (int y = 0; y < rows; ++y) {
      const auto* i = index.ptr<int>(y);
      auto* l = labels->ptr<std::uint8_t>(y);
      for (int x = 0; x < cols; ++x)
        if (i[x] >= 0) l[x] = graph.inSourceSegment(i[x]) ? cv::GC_PR_FGD : cv::GC_PR_BGD;
    }
  }
}

// Segmentation by graph cut (GrabCut's model: colour mixtures for object and background,
// min-cut with a contrast-sensitive smoothness term; IteratedGraphCut), at a working
// resolution, on the region around the candidates. `candidates` (CV_8UC1, 255 = not the expected
// backdrop) seeds it: a candidate whose colour is also one of the border band's is probably
// background (cloth, a stand), the others probably object; the border band is background. The
// border's colours are not sampled where the expected colour is `unsure` (CV_8UC1, 255; may be
// empty): in the plate's rim band, where the backdrop shows beside a plate that reaches the
// frame's edge, the plate's expected colour would make the backdrop's white a border colour,
// and a white sole on the plate backdrop. Returns the full-size binary mask (255 = object), and
// in *grid_step the graph cut's pixel in the image's.
cv::Mat SegmentByGraphCut(const cv::Mat& image, const cv::Mat& candidates, const cv::Mat& unsure,
                          const ExpectedBackground& expected, const SilhouetteOptions& options,
                          const cv::Mat& prior, const std::string& name, double* largest_piece,
                          double* grid_step) {
  const cv::Size full = image.size();
  // The region: the candidates' pieces that matter (and what the other views say is object),
  // with a margin.
  // (Found on a copy of at most kPieceSize pixels: connected components of 18-Mpx photos are
  // slow.)
  const double coarse = std::min(1.0, kPieceSize / std::max(full.width, full.height));
  cv::Mat pieces;
  cv::resize(candidates, pieces, cv::Size(), coarse, coarse, cv::INTER_AREA);
  pieces = pieces >= 128;
  int unused = 0;
  *largest_piece = RemoveSmallComponents(&pieces, 0.01, &unused) / (coarse * coarse);
  if (!prior.empty()) {
    cv::Mat small_prior;
    cv::resize(prior, small_prior, pieces.size(), 0, 0, cv::INTER_NEAREST);
    pieces |= small_prior >= 192;
  }
  if (cv::countNonZero(pieces) == 0) return cv::Mat::zeros(full, CV_8UC1);
  const cv::Rect coarse_roi = cv::boundingRect(pieces);
  cv::Rect roi(static_cast<int>(coarse_roi.x / coarse), static_cast<int>(coarse_roi.y / coarse),
               static_cast<int>(std::ceil(coarse_roi.width / coarse)) + 1,
               static_cast<int>(std::ceil(coarse_roi.height / coarse)) + 1);
  const int margin = std::max(8, std::max(roi.width, roi.height) / 10);
  roi = Grown(roi, margin, cv::Rect(cv::Point(0, 0), full));
  const double scale =
      std::min(1.0, static_cast<double>(kGraphCutSize) / std::max(roi.width, roi.height));
  *grid_step = 1.0 / scale;
  const int band_full = BorderBand(full);
  // Border colours, sampled at full resolution (every band pixel when the object must stay
  // clear of the border; otherwise only where the smooth backdrop model holds).
  cv::Mat usable =
      options.check_border ? cv::Mat(full, CV_8UC1, cv::Scalar(255)) : cv::Mat(~candidates);
  if (!unsure.empty()) usable.setTo(0, unsure);
  const BorderResiduals border(image, expected, usable, band_full);

  cv::Mat small, small_candidates;
  if (scale < 1.0) {
    cv::resize(image(roi), small, cv::Size(), scale, scale, cv::INTER_AREA);
    cv::resize(candidates(roi), small_candidates, small.size(), 0, 0, cv::INTER_AREA);
  } else {
    small = image(roi).clone();
    small_candidates = candidates(roi).clone();
  }
  const double floor = std::max(12.0, 2.0 * options.noise_threshold);
  const double noise_sq = options.noise_threshold * options.noise_threshold;
  cv::Mat labels(small.size(), CV_8UC1);
  int object_seeds = 0;
  for (int y = 0; y < small.rows; ++y) {
    const auto* in = small.ptr<cv::Vec3b>(y);
    const auto* cand = small_candidates.ptr<std::uint8_t>(y);
    auto* out = labels.ptr<std::uint8_t>(y);
    const int full_y = std::min(full.height - 1, roi.y + static_cast<int>((y + 0.5) / scale));
    for (int x = 0; x < small.cols; ++x) {
      const int full_x = std::min(full.width - 1, roi.x + static_cast<int>((x + 0.5) / scale));
      const cv::Vec3f c = cv::Vec3f(in[x][0], in[x][1], in[x][2]) - expected(full_x, full_y);
      if (cand[x] < 128) {
        // The backdrop itself, within the sensor's noise, is surely background: a
        // see-through hole (a handle's, a tab's loop) stays open against the smoothness term.
        out[x] = c.dot(c) <= noise_sq ? cv::GC_BGD : cv::GC_PR_BGD;
        continue;
      }
      const bool object = !border.Contains(c, floor);
      out[x] = object ? cv::GC_PR_FGD : cv::GC_PR_BGD;
      object_seeds += object ? 1 : 0;
    }
  }
  {
    // Surely background where a whole neighbourhood is: a dark object's shadowed crease on a
    // dark backdrop is not.
    cv::Mat sure = labels == cv::GC_BGD;
    cv::erode(sure, sure, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
    labels.setTo(cv::GC_PR_BGD, (labels == cv::GC_BGD) & ~sure);
  }
  {
    // The seeds' interior (specks and thin cloth folds eroded away) is surely object: colour
    // models of the whole region would otherwise take a white part before a white backdrop's
    // darker patch for backdrop. With the other views' hull, only within it (a spill beside
    // the object is left to the colours).
    cv::Mat sure = labels == cv::GC_PR_FGD;
    cv::erode(sure, sure, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5)));
    if (!prior.empty()) {
      cv::Mat small_prior;
      cv::resize(prior(roi), small_prior, small.size(), 0, 0, cv::INTER_NEAREST);
      sure &= small_prior >= 192;
    }
    labels.setTo(cv::GC_FGD, sure);
  }
  if (!prior.empty()) {
    // The other views' hull decides instead: nothing outside it is object, and what lies deep
    // inside it is object whatever its colour (an eye's white, a highlight, a print matching
    // the backdrop; a see-through hole there would be seen by the neighbouring views too and
    // carved from it). Inside it but near its outline, the backdrop's colour probably is the
    // object's own, and plain backdrop stays (a loop seen through by few views). Elsewhere
    // the colours decide.
    cv::Mat small_prior;
    cv::resize(prior(roi), small_prior, small.size(), 0, 0, cv::INTER_NEAREST);
    labels.setTo(cv::GC_PR_FGD, (small_prior == 192) & (labels == cv::GC_PR_BGD));
    labels.setTo(cv::GC_FGD, small_prior == 255);
    labels.setTo(cv::GC_BGD, small_prior == 0);
  }
  if (options.check_border) {
    // The band, in working pixels (where the region reaches it).
    const double band = band_full * scale;
    const int left = roi.x < band_full ? static_cast<int>(std::ceil(band - roi.x * scale)) : 0;
    const int top = roi.y < band_full ? static_cast<int>(std::ceil(band - roi.y * scale)) : 0;
    const int right_gap = full.width - roi.br().x;
    const int bottom_gap = full.height - roi.br().y;
    const int right =
        right_gap < band_full ? static_cast<int>(std::ceil(band - right_gap * scale)) : 0;
    const int bottom =
        bottom_gap < band_full ? static_cast<int>(std::ceil(band - bottom_gap * scale)) : 0;
    if (left > 0) labels.colRange(0, std::min(left, labels.cols)).setTo(cv::GC_BGD);
    if (top > 0) labels.rowRange(0, std::min(top, labels.rows)).setTo(cv::GC_BGD);
    if (right > 0) labels.colRange(std::max(0, labels.cols - right), labels.cols).setTo(cv::GC_BGD);
    if (bottom > 0)
      labels.rowRange(std::max(0, labels.rows - bottom), labels.rows).setTo(cv::GC_BGD);
  }
  // The region's own edge is background where it is not the frame's.
  if (roi.x > 0) labels.col(0).setTo(cv::GC_BGD);
  if (roi.y > 0) labels.row(0).setTo(cv::GC_BGD);
  if (roi.br().x < full.width) labels.col(labels.cols - 1).setTo(cv::GC_BGD);
  if (roi.br().y < full.height) labels.row(labels.rows - 1).setTo(cv::GC_BGD);
  if (object_seeds == 0 && cv::countNonZero(labels & 1) == 0) return cv::Mat::zeros(full, CV_8UC1);
  try {
    IteratedGraphCut(small, kGraphCutIterations, &labels);
  } catch (const cv::Exception& e) {
    throw FormatError(name, std::string("silhouette segmentation failed: ") + e.what());
  }
  cv::Mat object = (labels == cv::GC_FGD) | (labels == cv::GC_PR_FGD);
  cv::Mat result = cv::Mat::zeros(full, CV_8UC1);
  if (scale < 1.0) {
    cv::Mat up;
    cv::resize(object, up, roi.size(), 0, 0, cv::INTER_LINEAR);
    result(roi).setTo(255, up >= 128);
  } else {
    object.copyTo(result(roi));
  }
  return result;
}

// A silhouette that reaches the frame's border band is cut by the frame: the hull would lose
// what lies outside. \throw FormatError naming the photo.
void CheckClearOfBorder(const cv::Mat& fg, const std::string& name) {
  const int band = BorderBand(fg.size());
  const int inner_w = fg.cols - 2 * band;
  const int inner_h = fg.rows - 2 * band;
  if (inner_w <= 2 || inner_h <= 2) return;
  // The first ring of pixels inside the band.
  const cv::Rect inner(band, band, inner_w, inner_h);
  const cv::Mat ring = fg(inner);
  const int perimeter = 2 * (inner_w + inner_h);
  const int touching = cv::countNonZero(ring.row(0)) + cv::countNonZero(ring.row(inner_h - 1)) +
                       cv::countNonZero(ring.col(0)) + cv::countNonZero(ring.col(inner_w - 1));
  if (touching > std::max(3, perimeter / 200)) {
    std::ostringstream reason;
    reason << "the object touches the image border (" << touching
           << " pixels of its outline lie within " << band
           << " pixels of the frame's edge); its silhouette would be cut, so frame it with a "
              "margin (zoom out or move the camera back)";
    throw FormatError(name, reason.str());
  }
}

// The fraction of a silhouette's outline that runs along the turntable plate's rim band: where
// a product as light as the backdrop stops being seen (it stands out before the plate only).
double RimOutlineFraction(const cv::Mat& fg, const cv::Mat& rim) {
  cv::Mat outline;
  cv::morphologyEx(fg, outline, cv::MORPH_GRADIENT,
                   cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
  outline &= fg;
  const double length = cv::countNonZero(outline);
  return length > 0.0 ? cv::countNonZero(outline & rim) / length : 0.0;
}

// A photo whose object is mostly clipped white has lost its outline against a light backdrop.
// \throw FormatError naming the photo.
void CheckExposure(const cv::Mat& image, const cv::Mat& fg, const std::string& name) {
  cv::Mat clipped;
  cv::inRange(image, cv::Scalar::all(kClippedLevel), cv::Scalar::all(255), clipped);
  const double clipped_image = cv::countNonZero(clipped) / static_cast<double>(image.total());
  const double object = cv::countNonZero(fg);
  const double clipped_object = object > 0 ? cv::countNonZero(clipped & fg) / object : 0.0;
  if (clipped_image > 0.4 || clipped_object > 0.6) {
    std::ostringstream reason;
    reason << "over-exposed: " << cvRound(100.0 * clipped_image) << "% of the photo and "
           << cvRound(100.0 * clipped_object)
           << "% of the object are clipped at white; lower the exposure";
    throw FormatError(name, reason.str());
  }
}

// For each pixel, the nearest pixel marked in `sure` (CV_8UC1, 255), as a position in `sure`
// (CV_32SC2; (-1, -1) where none is): where the local colour of one side of an outline is
// taken, where that side is surely itself and nearest the pixel, so shading across the object
// does not bias it.
cv::Mat NearestSure(const cv::Mat& sure) {
  cv::Mat distance, labels;
  cv::distanceTransform(~sure, distance, labels, cv::DIST_L2, cv::DIST_MASK_5,
                        cv::DIST_LABEL_PIXEL);
  // Labels number the marked pixels in scan order.
  std::vector<cv::Point> position_of_label(1, cv::Point(-1, -1));
  for (int y = 0; y < sure.rows; ++y) {
    const auto* m = sure.ptr<std::uint8_t>(y);
    const auto* l = labels.ptr<int>(y);
    for (int x = 0; x < sure.cols; ++x) {
      if (!m[x]) continue;
      const auto k = static_cast<std::size_t>(l[x]);
      if (k >= position_of_label.size()) position_of_label.resize(k + 1, cv::Point(-1, -1));
      position_of_label[k] = cv::Point(x, y);
    }
  }
  cv::Mat nearest(sure.size(), CV_32SC2);
  for (int y = 0; y < sure.rows; ++y) {
    const auto* l = labels.ptr<int>(y);
    auto* out = nearest.ptr<cv::Point>(y);
    for (int x = 0; x < sure.cols; ++x) {
      const auto k = static_cast<std::size_t>(l[x]);
      out[x] = k < position_of_label.size() ? position_of_label[k] : cv::Point(-1, -1);
    }
  }
  return nearest;
}

// The colour (of `colour`, CV_32FC3, as `at`'s positions) at each of `at`'s positions (black
// where there is none).
cv::Mat ColourAt(const cv::Mat& colour, const cv::Mat& at) {
  cv::Mat out(at.size(), CV_32FC3);
  for (int y = 0; y < at.rows; ++y) {
    const auto* p = at.ptr<cv::Point>(y);
    auto* o = out.ptr<cv::Vec3f>(y);
    for (int x = 0; x < at.cols; ++x) o[x] = p[x].x >= 0 ? colour.at<cv::Vec3f>(p[x]) : cv::Vec3f();
  }
  return out;
}

// A curve on [0, 1] tabulated at 4096 steps and interpolated linearly (within 0.0001 of the
// sRGB curves): the matte and the backlit shot evaluate one per pixel.
class TabulatedCurve {
 public:
  explicit TabulatedCurve(double (*curve)(double)) {
    for (int i = 0; i <= kSteps; ++i)
      table_[static_cast<std::size_t>(i)] =
          static_cast<float>(curve(static_cast<double>(i) / kSteps));
  }
  float operator()(float x) const {
    const float at = std::clamp(x, 0.0f, 1.0f) * kSteps;
    const int i = std::min(static_cast<int>(at), kSteps - 1);
    const float f = at - static_cast<float>(i);
    return table_[static_cast<std::size_t>(i)] * (1.0f - f) +
           table_[static_cast<std::size_t>(i) + 1] * f;
  }

 private:
  static constexpr int kSteps = 4096;
  std::array<float, kSteps + 1> table_{};
};

double SrgbToLinear(double c) {
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}
double LinearToSrgb(double l) {
  return l <= 0.0031308 ? 12.92 * l : 1.055 * std::pow(l, 1.0 / 2.4) - 0.055;
}

// An 8-bit sRGB level as linear light (0..255 scale).
float LinearLevel(float srgb) {
  static const TabulatedCurve curve(SrgbToLinear);
  return 255.0f * curve(srgb / 255.0f);
}

// Linear light (0..255 scale) back to sRGB codes (0..255).
cv::Vec3f SrgbCode(const cv::Vec3f& linear) {
  static const TabulatedCurve curve(LinearToSrgb);
  return {255.0f * curve(linear[0] / 255.0f), 255.0f * curve(linear[1] / 255.0f),
          255.0f * curve(linear[2] / 255.0f)};
}

// The 8-bit sRGB levels as linear light (0..255 scale).
const std::array<float, 256>& LinearTable() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i)
      t[static_cast<std::size_t>(i)] = static_cast<float>(255.0 * SrgbToLinear(i / 255.0));
    return t;
  }();
  return table;
}

// A photo's 8-bit sRGB colour as linear light (0..255 scale).
cv::Vec3f LinearPixel(const cv::Vec3b& bgr) {
  const std::array<float, 256>& table = LinearTable();
  return {table[bgr[0]], table[bgr[1]], table[bgr[2]]};
}

// A photo's 8-bit sRGB colours as linear light (0..255 scale, CV_32FC3): where the object
// covers part of a pixel, the sensor mixed the two colours' light, not their sRGB codes (a
// half-covered pixel before a light backdrop looks lighter than halfway in sRGB).
cv::Mat LinearColour(const cv::Mat& bgr) {
  const std::array<float, 256>& table = LinearTable();
  cv::Mat out(bgr.size(), CV_32FC3);
  for (int y = 0; y < bgr.rows; ++y) {
    const auto* in = bgr.ptr<cv::Vec3b>(y);
    auto* o = out.ptr<cv::Vec3f>(y);
    for (int x = 0; x < bgr.cols; ++x)
      o[x] = cv::Vec3f(table[in[x][0]], table[in[x][1]], table[in[x][2]]);
  }
  return out;
}

// Whether linear colour i is background colour b scaled (a shadow on it, a sheen), within a
// chromaticity distortion of kMaxBackgroundChroma of b's brightness.
bool BackgroundLike(const cv::Vec3f& i, const cv::Vec3f& b) {
  const double bb = b.dot(b);
  if (bb < 1e-6) return i.dot(i) < 4.0;
  const double k = i.dot(b) / bb;
  if (k < kMinBackgroundScale || k > kMaxBackgroundScale) return false;
  const cv::Vec3f off = i - b * static_cast<float>(k);
  return off.dot(off) <= kMaxBackgroundChroma * kMaxBackgroundChroma * k * k * bb;
}

// A pixel's coverage by the object from its colour i and the object's and the background's
// colours f and b beside it (linear light): alpha = <i - b, f - b> / |f - b|^2, 8-bit, into
// *out; unchanged where f and b differ by less than `min_contrast`. A colour that is no mix of
// the two is a rim of another colour than the object's inside (a label's edge, a seam): object,
// unless it is the background darkened or lightened (a shadow, the backdrop's sheen); with
// `third_colours` false such a pixel keeps its value.
void MatteAlpha(const cv::Vec3f& i, const cv::Vec3f& f, const cv::Vec3f& b, double min_contrast,
                bool third_colours, std::uint8_t* out) {
  const cv::Vec3f fb = f - b;
  const double contrast_sq = fb.dot(fb);
  // Enough contrast to matte, judged as the photo's noise is: in 8-bit sRGB levels.
  const cv::Vec3f code_difference = SrgbCode(f) - SrgbCode(b);
  if (code_difference.dot(code_difference) < min_contrast * min_contrast) return;
  const cv::Vec3f ib = i - b;
  const double alpha = std::clamp(ib.dot(fb) / contrast_sq, 0.0, 1.0);
  const cv::Vec3f residual = ib - fb * static_cast<float>(alpha);
  if (residual.dot(residual) > kThirdColour * kThirdColour * contrast_sq) {
    if (third_colours) *out = BackgroundLike(i, b) ? 0 : 255;
    return;
  }
  *out = cv::saturate_cast<std::uint8_t>(255.0 * alpha);
}

// A photo to matte and its matte: `alpha` starts as the binary silhouette (CV_8UC1, the
// photo's size). With `third_colours`, a colour that is no mix of the two sides is decided
// (MatteAlpha).
struct MatteShot {
  const cv::Mat* image;
  bool third_colours;
  cv::Mat* alpha;
};

// Boundary refinement to an alpha matte: in a band around the outline, each pixel's coverage
// alpha = <I - B, F - B> / |F - B|^2 with F and B the object's and the background's colours
// nearest to it where each is sure (just beyond the band), in linear light, 8-bit; elsewhere 0
// or 255. Done tile by tile, only where the outline passes (a photo's object is mostly not
// outline); a tile is processed with a margin that holds the band's reach and the sure colours
// beyond it, and where a side has no sure pixel within it (a part thinner than the band) the
// binary mask stays. Each pass reads the mask as the previous one left it: the tiles' results
// are kept aside and written when the pass is done. Several shots of one outline (the same
// binary silhouette) share the band and where its nearest sure pixels lie. `grid_step`: the
// pixel the binary silhouette was decided on, in the photo's; `box`: the binary silhouette's
// bounding box. Returns the box the mattes may differ from it in.
cv::Rect RefineToAlpha(const std::vector<MatteShot>& shots, const SilhouetteOptions& options,
                       double grid_step, cv::Rect box) {
  const cv::Mat& binary = *shots.front().alpha;  // unchanged until the first pass is done
  const cv::Size size = binary.size();
  // The band covers half the segmentation's pixel (`grid_step`, photo pixels) with a pixel to
  // spare either side, and never more than half a graph cut's pixel over the whole photo.
  const int band = std::min(1 + static_cast<int>(std::ceil(std::max(size.width, size.height) /
                                                           (kGraphCutSize * 1.0) * 0.5)),
                            2 + static_cast<int>(std::ceil(0.5 * grid_step)));
  const int pad = 2 * band + 2;
  const cv::Rect frame(0, 0, size.width, size.height);
  if (box.area() == 0) return {};
  const cv::Rect roi = Grown(box, pad, frame);
  const double min_contrast = 2.0 * std::max(options.noise_threshold, 4.0);
  constexpr int kTile = 64;
  struct Tile {
    cv::Rect core;
    std::vector<cv::Mat> alpha;  // per shot, the pass's result for the core
  };
  std::vector<Tile> tiles;
  for (int ty = roi.y; ty < roi.br().y; ty += kTile) {
    for (int tx = roi.x; tx < roi.br().x; tx += kTile) {
      const cv::Rect core = cv::Rect(tx, ty, kTile, kTile) & roi;
      // The outline passes when the core, grown by the band, holds both sides.
      const cv::Rect reach = Grown(core, band, frame);
      const int object_px = cv::countNonZero(binary(reach));
      if (object_px == 0 || object_px == reach.area()) continue;
      const int margin = pad + band;
      const cv::Rect region = Grown(core, margin, frame);
      const cv::Mat fg_region = binary(region);
      // The band's two edges: the object shrunk and grown by a disc of the band's radius (by
      // distance: a morphology with a disc is many times slower on 18-Mpx photos' outlines).
      cv::Mat to_background, to_object;
      cv::distanceTransform(fg_region, to_background, cv::DIST_L2, cv::DIST_MASK_3);
      cv::distanceTransform(~fg_region, to_object, cv::DIST_L2, cv::DIST_MASK_3);
      cv::Mat shrunk = to_background > static_cast<float>(band);
      cv::Mat grown = to_object <= static_cast<float>(band);
      // Within a band of the region's edge the distances did not see all they needed: neither
      // side is sure there.
      if (region.width > 2 * band && region.height > 2 * band) {
        cv::Mat edge(region.size(), CV_8UC1, cv::Scalar(255));
        edge(cv::Rect(band, band, region.width - 2 * band, region.height - 2 * band))
            .setTo(cv::Scalar(0));
        shrunk.setTo(0, edge);
        grown.setTo(255, edge);
      }
      if (cv::countNonZero(shrunk) == 0 || cv::countNonZero(grown) == region.area()) continue;
      // The sure pixels nearest each pixel, within their reach of the core (a band pixel's
      // nearest sure pixel lies within twice the band).
      const cv::Rect inner = Grown(core, pad, frame);
      const cv::Rect in_region(inner.tl() - region.tl(), inner.size());
      const cv::Mat nearest_object = NearestSure(shrunk(in_region));
      const cv::Mat nearest_background = NearestSure(~grown(in_region));
      const cv::Point offset = core.tl() - region.tl();
      const cv::Point inner_offset = core.tl() - inner.tl();
      // Their colours smoothed over 3x3 (read one pixel further), per shot.
      const cv::Rect read = Grown(inner, 1, frame);
      Tile tile{core, {}};
      for (const MatteShot& shot : shots) {
        cv::Mat smooth;
        cv::blur(LinearColour((*shot.image)(read)), smooth, cv::Size(3, 3));
        smooth = smooth(cv::Rect(inner.tl() - read.tl(), inner.size()));
        const cv::Mat object = ColourAt(smooth, nearest_object);
        const cv::Mat background = ColourAt(smooth, nearest_background);
        cv::Mat alpha = binary(core).clone();
        for (int y = 0; y < core.height; ++y) {
          const int ry = y + offset.y;
          const int iy = y + inner_offset.y;
          const auto* g = grown.ptr<std::uint8_t>(ry) + offset.x;
          const auto* sh = shrunk.ptr<std::uint8_t>(ry) + offset.x;
          const auto* f_row = object.ptr<cv::Vec3f>(iy) + inner_offset.x;
          const auto* b_row = background.ptr<cv::Vec3f>(iy) + inner_offset.x;
          const auto* i_row = shot.image->ptr<cv::Vec3b>(core.y + y) + core.x;
          auto* out = alpha.ptr<std::uint8_t>(y);
          for (int x = 0; x < core.width; ++x) {
            if (!g[x] || sh[x]) continue;
            MatteAlpha(LinearPixel(i_row[x]), f_row[x], b_row[x], min_contrast, shot.third_colours,
                       &out[x]);
          }
        }
        tile.alpha.push_back(std::move(alpha));
      }
      tiles.push_back(std::move(tile));
    }
  }
  for (const Tile& tile : tiles)
    for (std::size_t s = 0; s < shots.size(); ++s)
      tile.alpha[s].copyTo((*shots[s].alpha)(tile.core));
  // Second pass: each partly covered pixel matted again against the colours right at the
  // outline (the nearest pixels the first pass found wholly object and wholly background, if
  // within kLocalReach): an edge lit otherwise than the inside (a rim glow before a lit panel,
  // a grazing highlight, a shaded crease) is matted against its own colour. Only the first
  // pass's tiles hold such pixels.
  const std::vector<cv::Point> local = [] {
    std::vector<cv::Point> offsets;
    const int reach = static_cast<int>(kLocalReach);
    for (int dy = -reach; dy <= reach; ++dy)
      for (int dx = -reach; dx <= reach; ++dx)
        if ((dx != 0 || dy != 0) && dx * dx + dy * dy <= kLocalReach * kLocalReach)
          offsets.emplace_back(dx, dy);
    std::stable_sort(offsets.begin(), offsets.end(), [](cv::Point a, cv::Point b) {
      return a.x * a.x + a.y * a.y < b.x * b.x + b.y * b.y;
    });
    return offsets;
  }();
  for (std::size_t s = 0; s < shots.size(); ++s) {
    const cv::Mat& image = *shots[s].image;
    const cv::Mat& first = *shots[s].alpha;
    for (Tile& tile : tiles) {
      const cv::Rect core = tile.core;
      cv::Mat& result = tile.alpha[s];
      const cv::Mat core_first = first(core);
      if (cv::countNonZero((core_first > 0) & (core_first < 255)) == 0) {
        result.release();
        continue;
      }
      core_first.copyTo(result);
      for (int y = 0; y < core.height; ++y) {
        const auto* a = core_first.ptr<std::uint8_t>(y);
        auto* out = result.ptr<std::uint8_t>(y);
        for (int x = 0; x < core.width; ++x) {
          if (a[x] == 0 || a[x] == 255) continue;
          const cv::Point p(core.x + x, core.y + y);
          // The nearest wholly object and wholly background pixels, searched nearest first.
          const cv::Point* object = nullptr;
          const cv::Point* background = nullptr;
          for (const cv::Point& o : local) {
            const cv::Point q = p + o;
            if (!frame.contains(q)) continue;
            const std::uint8_t v = first.at<std::uint8_t>(q);
            if (v == 255 && object == nullptr) object = &o;
            if (v == 0 && background == nullptr) background = &o;
            if (object != nullptr && background != nullptr) break;
          }
          if (object == nullptr || background == nullptr) continue;
          MatteAlpha(LinearPixel(image.at<cv::Vec3b>(p)),
                     LinearPixel(image.at<cv::Vec3b>(p + *object)),
                     LinearPixel(image.at<cv::Vec3b>(p + *background)), min_contrast,
                     shots[s].third_colours, &out[x]);
        }
      }
    }
    for (const Tile& tile : tiles)
      if (!tile.alpha[s].empty()) tile.alpha[s].copyTo((*shots[s].alpha)(tile.core));
  }
  return roi;
}

}  // namespace

SilhouetteMethod ParseSilhouetteMethod(const std::string& name) {
  if (name == "auto") return SilhouetteMethod::kAuto;
  if (name == "key") return SilhouetteMethod::kKey;
  if (name == "difference") return SilhouetteMethod::kDifference;
  if (name == "backlit") return SilhouetteMethod::kBacklit;
  throw InvalidArgument("unknown silhouette method '" + name +
                        "' (expected auto, key, difference or backlit)");
}

const char* SilhouetteMethodName(SilhouetteMethod method) {
  switch (method) {
    case SilhouetteMethod::kAuto:
      return "auto";
    case SilhouetteMethod::kKey:
      return "key";
    case SilhouetteMethod::kDifference:
      return "difference";
    case SilhouetteMethod::kBacklit:
      return "backlit";
  }
  return "?";
}

SilhouetteMethod ResolveSilhouetteMethod(SilhouetteMethod method, std::size_t views,
                                         std::size_t mask_shots) {
  if (method != SilhouetteMethod::kAuto) return method;
  return views > 0 && mask_shots == views ? SilhouetteMethod::kBacklit : SilhouetteMethod::kKey;
}

const OptionTable<SilhouetteOptions>& SilhouetteOptions::Fields() {
  using O = SilhouetteOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.AddChoice(&O::method,
                {.name = "method",
                 .help = "silhouettes from the backlit mask shots (backlit), by keying against "
                         "the backdrop (key), or by differencing against background plates "
                         "(difference: backgrounds/cam<C>.jpg); auto: backlit when the session "
                         "has mask shots, else key"},
                {{"auto", SilhouetteMethod::kAuto},
                 {"key", SilhouetteMethod::kKey},
                 {"difference", SilhouetteMethod::kDifference},
                 {"backlit", SilhouetteMethod::kBacklit}});
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
          {.name = "refine-boundary",
           .help = "boundary refinement to an alpha matte by local alpha estimation"});
    t.Add(&O::check_border,
          {.name = "check-border",
           .help = "stop when a silhouette reaches the frame's border (the frame cuts the object)",
           .advanced = true});
    t.Add(&O::multi_view,
          {.name = "multi-view",
           .help = "segment again a view whose silhouette disagrees with the other views' hull"});
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

namespace {

// A working copy's binary silhouette (CV_8UC1, 0 or 255) at the photo's `size`: interpolated
// linearly and thresholded at half; *box receives the result's bounding box. Where `size` is
// the working size times an integer, only the silhouette's bounding box (with the pixel either
// side the interpolation reads) is upsampled: the same pixels as upsampling the whole, for the
// part of an 18-Mpx photo the object covers.
cv::Mat Upsampled(const cv::Mat& small, cv::Size size, cv::Rect* box) {
  cv::Mat out;
  const int factor = size.width / small.cols;
  const cv::Rect small_box = cv::boundingRect(small);
  if (factor < 2 || small.cols * factor != size.width || small.rows * factor != size.height ||
      small_box.area() == 0) {
    cv::resize(small, out, size, 0, 0, cv::INTER_LINEAR);
    cv::threshold(out, out, 127, 255, cv::THRESH_BINARY);
    *box = cv::boundingRect(out);
    return out;
  }
  const cv::Rect read = Grown(small_box, 1, cv::Rect(0, 0, small.cols, small.rows));
  const cv::Rect written(read.x * factor, read.y * factor, read.width * factor,
                         read.height * factor);
  out = cv::Mat::zeros(size, CV_8UC1);
  cv::Mat part = out(written);
  cv::resize(small(read), part, written.size(), 0, 0, cv::INTER_LINEAR);
  cv::threshold(part, part, 127, 255, cv::THRESH_BINARY);
  *box = cv::boundingRect(part) + written.tl();
  return out;
}

// `image` averaged down to `size` by area. By an even integer factor in steps of 2: OpenCV's
// 2x2 area average is vectorised, its 4x4 is not (18 -> 8 ms on an 18-Mpx photo); the result
// is the same box average but for rounding.
cv::Mat AreaReduced(const cv::Mat& image, cv::Size size) {
  cv::Mat reduced = image;
  while (reduced.cols % 2 == 0 && reduced.rows % 2 == 0 && reduced.cols / 2 >= size.width &&
         reduced.rows / 2 >= size.height && (reduced.cols / size.width) % 2 == 0 &&
         reduced.cols % size.width == 0 && reduced.rows % size.height == 0 &&
         reduced.cols / size.width == reduced.rows / size.height) {
    cv::Mat half;
    cv::resize(reduced, half, cv::Size(reduced.cols / 2, reduced.rows / 2), 0, 0, cv::INTER_AREA);
    reduced = half;
  }
  if (reduced.size() == size) return reduced;
  cv::Mat out;
  cv::resize(reduced, out, size, 0, 0, cv::INTER_AREA);
  return out;
}

// The silhouette of a photo at its working size (inputs checked by ComputeSilhouette; `image`,
// `background` and `prior` all of `camera`'s size): binary (255 = object), before the boundary
// refinement.
cv::Mat SegmentAtWorkingSize(const cv::Mat& image, const CameraModel& camera,
                             const SilhouetteOptions& options, double rim_px,
                             const cv::Mat& background, const std::string& name,
                             SilhouetteStats* stats, const cv::Mat& prior, double* grid_step,
                             const PlateKeying* imposed) {
  const bool difference = options.method == SilhouetteMethod::kDifference;
  const int width = image.cols;
  const int height = image.rows;
  cv::Mat plate, rim;
  PlateRegions(camera, difference ? 0.0 : options.plate_radius_m, options.plate_rim_m, rim_px,
               &plate, &rim);

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
    const auto min_plate = std::max<std::size_t>(10, plate_samples.size() / 5);
    const PlateKeying::State told = imposed != nullptr ? imposed->state : PlateKeying::State::kNone;
    if (plate_samples.empty()) {
      // No plate in the frame.
    } else if (told == PlateKeying::State::kFitted) {
      // The colour the other views of this camera agree on seeds the fit; where too little of
      // the plate shows to fit, it is keyed against that colour as it is.
      const ColourModel agreed = PlateModel(*imposed);
      for (std::size_t i = 0; i < plate_samples.size(); ++i)
        plate_seed[i] = cv::norm(plate_samples[i].colour -
                                 agreed.At(plate_samples[i].x, plate_samples[i].y)) <= 2.5 * floor;
      have_plate = FitColourModel(plate_samples, plate_seed, 3, floor, min_plate, &plate_colour) ||
                   FitColourModel(plate_samples, plate_seed, 1, floor, min_plate, &plate_colour);
      if (!have_plate) plate_colour = agreed;
      have_plate = true;
    } else if (told != PlateKeying::State::kHidden) {
      // All plate pixels seed the fit, which starts from those near their median colour:
      // the object may cover part of the plate.
      have_plate = FitColourModel(plate_samples, plate_seed, 3, floor, min_plate, &plate_colour) ||
                   FitColourModel(plate_samples, plate_seed, 1, floor, min_plate, &plate_colour);
      // A product larger than the plate hides it, and the fit then found the product's own
      // colour: the plate counts only where some of its edge is seen against the backdrop.
      if (have_plate && VisiblePlateEdge(image, plate, rim, backdrop, plate_colour,
                                         Classifier(options)) < kMinVisiblePlateEdge)
        have_plate = false;
      if (!have_plate) CAROUSEL_LOG_DEBUG(name << ": the turntable plate looks hidden");
    }
    if (stats != nullptr && !plate_samples.empty()) {
      if (have_plate) {
        stats->plate = FittedPlate(plate_colour, plate_samples);
      } else {
        stats->plate = {};
        stats->plate.state = PlateKeying::State::kHidden;
      }
    }
  }

  // --- classification --------------------------------------------------------------------------
  const Classifier classifier(options);
  const double rim_tolerance = options.noise_threshold + options.chroma_threshold;
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
  const ExpectedBackground expected = [&](int x, int y) -> cv::Vec3f {
    if (difference) {
      const auto& b = smoothed_background.at<cv::Vec3b>(y, x);
      return {static_cast<float>(b[0]), static_cast<float>(b[1]), static_cast<float>(b[2])};
    }
    const double nx = (x + 0.5) / width * 2.0 - 1.0;
    const double ny = (y + 0.5) / height * 2.0 - 1.0;
    if (have_plate && plate.at<std::uint8_t>(y, x)) return plate_colour.At(nx, ny);
    return backdrop.At(nx, ny);
  };
  double largest = 0.0;
  const cv::Mat backdrop_colour = fg == 0;  // what the colour test took for the background
  fg = SegmentByGraphCut(image, fg, have_plate ? rim : cv::Mat(), expected, options, prior, name,
                         &largest, grid_step);
  // Pieces and holes are looked for within the object's box and a pixel of background around
  // it (a hole that reaches the box's edge is open to the backdrop beyond).
  const cv::Rect found = cv::boundingRect(fg);
  const cv::Rect box = Grown(found, 1, cv::Rect(0, 0, width, height));
  cv::Mat fg_box = fg(box);
  RemoveSmallComponents(&fg_box, options.min_component_fraction, &components);
  const double object_area = cv::countNonZero(fg_box);
  if (options.check_border && prior.empty()) {
    // Candidates that reach the border, whose colours the border band shows, were all taken
    // for backdrop: when that leaves almost nothing of them, the object itself crosses the
    // frame's border.
    if (largest > kMinObjectFraction * static_cast<double>(fg.total()) &&
        object_area < kMinKeptOfCandidates * largest) {
      std::ostringstream reason;
      reason << "the object touches the image border: the frame's edge shows the colours of "
             << cvRound(100.0 * (1.0 - object_area / largest))
             << "% of what differs from the backdrop, so it is cut by the frame (or the "
                "backdrop is cluttered); frame the object with a margin";
      throw FormatError(name, reason.str());
    }
  }
  if (object_area < kMinObjectFraction * static_cast<double>(fg.total()))
    throw FormatError(name,
                      "no object found: the photo shows only the backdrop (or the object "
                      "matches it everywhere)");
  FillSmallHoles(&fg_box, options.max_hole_fraction * object_area, backdrop_colour(box));
  if (options.check_border) CheckClearOfBorder(fg, name);
  CheckExposure(image, fg, name);
  if (stats != nullptr) {
    stats->rim_outline_fraction = have_plate ? RimOutlineFraction(fg, rim) : 0.0;
    stats->backdrop_residual = backdrop.rms;
    stats->components = components;
  }
  return fg;
}

// The prior's decisions (OthersHullPriors' codes): 0 = not object, 255 = object.
void ApplyPrior(const cv::Mat& prior, cv::Mat* fg) {
  if (prior.empty()) return;
  fg->setTo(0, prior == 0);
  fg->setTo(255, prior == 255);
}

// The silhouette in a backlit mask shot at its working size (kBacklit): binary, before the
// boundary refinement.
cv::Mat SegmentBacklitAtWorkingSize(const cv::Mat& image, const SilhouetteOptions& options,
                                    const std::string& name, SilhouetteStats* stats,
                                    const cv::Mat& prior) {
  const int width = image.cols;
  const int height = image.rows;
  // The lit panel: a smooth model fitted from the border inwards, the product's dark pixels
  // rejected (as the keyed backdrop's).
  ColourModel panel;
  {
    const double scale = std::min(1.0, static_cast<double>(kFitSize) / std::max(width, height));
    cv::Mat small;
    cv::resize(image, small, cv::Size(), scale, scale, cv::INTER_AREA);
    std::vector<Sample> samples;
    std::vector<bool> seed;
    const int border = std::max(2, small.cols / 12);
    for (int y = 0; y < small.rows; ++y) {
      for (int x = 0; x < small.cols; ++x) {
        const auto& c = small.at<cv::Vec3b>(y, x);
        samples.push_back({((x + 0.5) / scale) / width * 2.0 - 1.0,
                           ((y + 0.5) / scale) / height * 2.0 - 1.0, cv::Vec3f(c[0], c[1], c[2])});
        seed.push_back(x < border || y < border || x >= small.cols - border ||
                       y >= small.rows - border);
      }
    }
    const double floor = std::max(12.0, 2.0 * options.noise_threshold);
    if (!FitColourModel(samples, seed, 6, floor, std::max<std::size_t>(50, samples.size() / 10),
                        &panel))
      throw FormatError(name,
                        "no lit backdrop in the mask shot: fewer than 10% of its pixels agree "
                        "with a smooth bright panel (is the backlight on, the product framed "
                        "with a margin?)");
  }
  const cv::Vec3f centre = panel.At(0.0, 0.0);
  const double centre_level = (centre[0] + centre[1] + centre[2]) / 3.0;
  if (centre_level < kMinBacklitLevel) {
    std::ostringstream reason;
    reason << "the mask shot's backdrop is dark (" << cvRound(centre_level)
           << " of 255 at the centre): the backlight did not light it";
    throw FormatError(name, reason.str());
  }
  // Per pixel, in linear light: the shot's brightness as a fraction r of the panel's there.
  // The product's fraction from its surely dark pixels (r < 0.5), or, when it lets most of the
  // light through (glass, clear plastic), from its darkest: its outline.
  cv::Mat ratio(height, width, CV_32FC1);
  std::vector<cv::Vec3f> row(width);
  std::vector<float> sampled;
  sampled.reserve(static_cast<std::size_t>(width) * height / 3 + 1);
  {
    const cv::Mat linear = LinearColour(image);
    for (int y = 0; y < height; ++y) {
      EvaluateRow(panel, (y + 0.5) / height * 2.0 - 1.0, width, &row);
      const auto* in = linear.ptr<cv::Vec3f>(y);
      auto* r = ratio.ptr<float>(y);
      for (int x = 0; x < width; ++x) {
        const float p = LinearLevel((row[x][0] + row[x][1] + row[x][2]) / 3.0f);
        r[x] = (in[x][0] + in[x][1] + in[x][2]) / (3.0f * std::max(p, 1.0f));
        if ((x + y) % 3 == 0) sampled.push_back(r[x]);
      }
    }
  }
  // (Order statistics by selection: sorting a third of an 18-Mpx shot's pixels is slow.)
  const auto dark_end =
      std::partition(sampled.begin(), sampled.end(), [](float r) { return r < 0.5f; });
  const auto dark = static_cast<std::size_t>(dark_end - sampled.begin());
  const std::size_t min_dark = std::max<std::size_t>(20, sampled.size() / 2000);
  // The median of the dark pixels, or the darkest few.
  const std::size_t pick = dark >= min_dark ? dark / 2 : std::min(sampled.size() - 1, min_dark / 4);
  const auto pick_at = sampled.begin() + static_cast<std::ptrdiff_t>(pick);
  std::nth_element(sampled.begin(), pick_at, dark >= min_dark ? dark_end : sampled.end());
  const float object_ratio = *pick_at;
  if (object_ratio > kMaxSeeThroughRatio)
    throw FormatError(name,
                      "no object found: the mask shot shows only the lit panel (or the "
                      "product lets all of its light through)");
  cv::Mat alpha(height, width, CV_32FC1);
  for (int y = 0; y < height; ++y) {
    const auto* r = ratio.ptr<float>(y);
    auto* a = alpha.ptr<float>(y);
    for (int x = 0; x < width; ++x)
      a[x] = std::clamp((1.0f - r[x]) / (1.0f - object_ratio), 0.0f, 1.0f);
  }
  cv::Mat fg = alpha >= 0.5f;
  int components = 0;
  RemoveSmallComponents(&fg, options.min_component_fraction, &components);
  double object_area = cv::countNonZero(fg);
  if (object_area < kMinObjectFraction * static_cast<double>(fg.total()))
    throw FormatError(name,
                      "no object found: the mask shot shows only the lit panel (or the "
                      "product lets all of its light through)");
  // Holes the object encloses: a see-through part dims the panel behind it (filled: the
  // product is solid there), an opening shows it as it is (kept). Looked for within the
  // object's box and a pixel of background around it (a hole that reaches the box's edge is
  // open to the panel beyond).
  {
    const cv::Rect found = cv::boundingRect(fg);
    const cv::Rect box = Grown(found, 1, cv::Rect(0, 0, width, height));
    cv::Mat background = ~fg(box);
    cv::Mat labels, stats_mat, centroids;
    const int n =
        cv::connectedComponentsWithStats(background, labels, stats_mat, centroids, 4, CV_32S);
    std::vector<double> alpha_sum(static_cast<std::size_t>(n), 0.0);
    for (int y = 0; y < box.height; ++y) {
      const int* l = labels.ptr<int>(y);
      const float* a = alpha.ptr<float>(box.y + y) + box.x;
      for (int x = 0; x < box.width; ++x) alpha_sum[static_cast<std::size_t>(l[x])] += a[x];
    }
    std::vector<std::uint8_t> fill(static_cast<std::size_t>(n), 0);
    const double max_small = options.max_hole_fraction * object_area;
    for (int i = 1; i < n; ++i) {
      const int x = stats_mat.at<int>(i, cv::CC_STAT_LEFT);
      const int y = stats_mat.at<int>(i, cv::CC_STAT_TOP);
      const int w = stats_mat.at<int>(i, cv::CC_STAT_WIDTH);
      const int h = stats_mat.at<int>(i, cv::CC_STAT_HEIGHT);
      if (x == 0 || y == 0 || x + w == box.width || y + h == box.height) continue;  // open
      const double area = stats_mat.at<int>(i, cv::CC_STAT_AREA);
      const double mean_alpha = alpha_sum[static_cast<std::size_t>(i)] / area;
      if (area <= max_small || mean_alpha >= kSeeThroughAlpha)
        fill[static_cast<std::size_t>(i)] = 255;
    }
    for (int y = 0; y < box.height; ++y) {
      const int* l = labels.ptr<int>(y);
      std::uint8_t* m = fg.ptr<std::uint8_t>(box.y + y) + box.x;
      for (int x = 0; x < box.width; ++x)
        m[x] = static_cast<std::uint8_t>(m[x] | fill[static_cast<std::size_t>(l[x])]);
    }
  }
  if (!prior.empty()) {
    // The other views' hull removes what lies outside it; what lies deep inside it is object
    // unless this shot sees the lit panel there undimmed (an opening only some views see
    // through).
    fg.setTo(0, prior == 0);
    fg.setTo(255, (prior == 255) & (alpha >= kSeeThroughAlpha));
  }
  object_area = cv::countNonZero(fg);
  if (object_area < kMinObjectFraction * static_cast<double>(fg.total()))
    throw FormatError(name, "no object found in the mask shot");
  if (options.check_border) CheckClearOfBorder(fg, name);
  if (stats != nullptr) {
    stats->backdrop_residual = panel.rms;
    stats->components = components;
  }
  return fg;
}

// Views whose silhouette disagrees with the hull of the other views.
struct Disagreement {
  std::vector<std::size_t> holes;  // with holes
  std::vector<std::size_t> any;    // with holes or spills
};

// The views whose silhouette disagrees with the hull of the other views (`priors`, from
// OthersHullPriors; enclosed backdrop left at 255 there, open backdrop lowered to 192): object
// where no other view allows it (a spill), or backdrop where every other view says object (a
// hole). A view that disagrees over more than kMaxRepairFraction of its silhouette is left for
// the hull to name.
Disagreement DisagreeingViews(const std::vector<View>& views, SilhouettesResult* result,
                              int threads, std::vector<cv::Mat>* priors) {
  // The views that disagree with the others' hull: object where no other view allows it, or
  // backdrop where every other view says object. Decided at the priors' size (the grid is
  // coarse), in parallel.
  std::vector<std::uint8_t> holes(views.size(), 0), disagrees(views.size(), 0);
  ParallelFor(views.size(), 1, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t v = begin; v < end; ++v) {
      // Sampled at the pixel centres, as OthersHullPriors does.
      cv::Mat object = result->masks[v];
      if (object.size() != (*priors)[v].size())
        cv::resize(object, object, (*priors)[v].size(), 0, 0, cv::INTER_NEAREST_EXACT);
      object = object >= 128;
      // Deep inside the others' hull, only holes enclosed by the object are filled regardless
      // of colour; backdrop open to the outside (under a sole's arch) is a concavity the
      // others' hull may not have carved.
      cv::Mat open_backdrop = ~object;
      cv::Mat labels;
      const int n = cv::connectedComponents(open_backdrop, labels, 4, CV_32S);
      std::vector<std::uint8_t> touches(static_cast<std::size_t>(n), 0);
      for (int x = 0; x < labels.cols; ++x) {
        touches[static_cast<std::size_t>(labels.at<int>(0, x))] = 1;
        touches[static_cast<std::size_t>(labels.at<int>(labels.rows - 1, x))] = 1;
      }
      for (int y = 0; y < labels.rows; ++y) {
        touches[static_cast<std::size_t>(labels.at<int>(y, 0))] = 1;
        touches[static_cast<std::size_t>(labels.at<int>(y, labels.cols - 1))] = 1;
      }
      touches[0] = 0;  // the object
      for (int y = 0; y < labels.rows; ++y) {
        const int* l = labels.ptr<int>(y);
        std::uint8_t* o = open_backdrop.ptr<std::uint8_t>(y);
        for (int x = 0; x < labels.cols; ++x)
          o[x] = touches[static_cast<std::size_t>(l[x])] ? 255 : 0;
      }
      (*priors)[v].setTo(192, ((*priors)[v] == 255) & open_backdrop);
      // Slivers along the outline do not count: the grid is coarse.
      const cv::Mat sliver = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
      // Holes well inside the others' hull count whatever their shape (a highlight along a
      // glossy lace keyed as backdrop leaves a hair-thin hole).
      cv::Mat spill_map, hole_map;
      cv::erode(object & ((*priors)[v] == 0), spill_map, sliver);
      cv::erode(~object & ~open_backdrop & ((*priors)[v] >= 192), hole_map, sliver);
      hole_map |= ~object & ~open_backdrop & ((*priors)[v] == 255);
      const int spill = cv::countNonZero(spill_map);
      const int hole = cv::countNonZero(hole_map);
      result->stats[v].outside_others = spill;
      result->stats[v].hole_in_others = hole;
      const double area = cv::countNonZero(object);
      // A hole carves a tunnel through the hull whatever its size; a spill is only carved. A
      // view that disagrees about much of its object is not a segmentation slip but a wrong
      // pose or photo: made to agree, it would hide that; the hull names it instead.
      const bool hole_slip = hole > kMinDisagreementPx;
      const bool slip =
          hole_slip || spill > std::max(kMinDisagreementPx, kMinDisagreementFraction * area);
      if (slip && hole + spill > kMaxRepairFraction * area) {
        CAROUSEL_LOG_WARN(views[v].name()
                          << ": the silhouette disagrees with the other views' hull over "
                          << cvRound(100.0 * (hole + spill) / std::max(1.0, area))
                          << "% of its area: not repaired (a wrong camera pose or photo?)");
        continue;
      }
      holes[v] = hole_slip;
      disagrees[v] = slip;
    }
  });
  Disagreement found;
  for (std::size_t v = 0; v < views.size(); ++v) {
    if (holes[v]) found.holes.push_back(v);
    if (disagrees[v]) found.any.push_back(v);
  }
  return found;
}

// Keyed silhouettes that stop at the plate's rim in most views: the product above the plate
// matches the backdrop. \throw FormatError naming the view that shows it most.
void CheckNotCutByThePlate(const std::vector<View>& views,
                           const std::vector<SilhouetteStats>& stats) {
  if (stats.size() < 3) return;
  std::vector<double> fractions;
  fractions.reserve(stats.size());
  for (const SilhouetteStats& s : stats) fractions.push_back(s.rim_outline_fraction);
  std::vector<double> sorted = fractions;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2),
                   sorted.end());
  const double median = sorted[sorted.size() / 2];
  if (median < kMaxRimOutline) return;
  const std::size_t worst = static_cast<std::size_t>(
      std::max_element(fractions.begin(), fractions.end()) - fractions.begin());
  std::ostringstream reason;
  reason << "the silhouettes stop at the turntable plate's rim (" << cvRound(100.0 * median)
         << "% of their outline runs along it in half of the views, "
         << cvRound(100.0 * fractions[worst])
         << "% here): above the plate the product looks like the backdrop, so keying keeps only "
            "what stands before the plate; take backlit mask shots (--mask-shots backlit) or use "
            "a backdrop of another colour";
  throw FormatError(views[worst].name(), reason.str());
}

}  // namespace

cv::Mat ComputeSilhouette(const cv::Mat& image, const CameraModel& camera,
                          const SilhouetteOptions& options, const cv::Mat& background,
                          const std::string& name, SilhouetteStats* stats, const cv::Mat& prior,
                          const cv::Mat& photo, const PlateKeying* plate) {
  options.Validate();
  CAROUSEL_THROW_IF(!prior.empty() && prior.type() != CV_8UC1, InvalidArgument,
                    name << ": the silhouette prior must be 8-bit");
  CAROUSEL_THROW_IF(image.empty() || image.type() != CV_8UC3, InvalidArgument,
                    name << ": silhouettes need an 8-bit BGR photo");
  CAROUSEL_THROW_IF(image.cols != camera.width || image.rows != camera.height, InvalidArgument,
                    name << ": photo is " << image.cols << "x" << image.rows
                         << " but its camera is " << camera.width << "x" << camera.height);
  const bool difference = options.method == SilhouetteMethod::kDifference;
  const bool backlit = options.method == SilhouetteMethod::kBacklit;
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
  // Everything but the boundary refinement runs on a working copy of at most kWorkPixels: the
  // graph cut decides at a coarser size anyway, and the refinement, at full size, only in the
  // band along the outline.
  // By an integer factor where it is 2 or more: OpenCV's area resampling is then a plain box
  // average, several times faster than at a fractional scale on 18-Mpx photos.
  double work_scale = std::min(1.0, std::sqrt(kWorkPixels / static_cast<double>(image.total())));
  if (const long factor = std::lround(1.0 / work_scale); factor >= 2) work_scale = 1.0 / factor;
  cv::Mat fg;
  cv::Rect box;  // the silhouette's bounding box, once known
  // The segmentation's pixel, in the working copy's (the graph cut decides on a coarser grid).
  double grid_step = 1.0;
  if (work_scale < 1.0) {
    const CameraModel work_camera = camera.Scaled(work_scale);
    const cv::Size work_size(work_camera.width, work_camera.height);
    cv::Mat work_image, work_background, work_prior;
    work_image = AreaReduced(image, work_size);
    if (difference) work_background = AreaReduced(background, work_size);
    if (!prior.empty()) cv::resize(prior, work_prior, work_size, 0, 0, cv::INTER_NEAREST);
    const cv::Mat work_fg =
        backlit ? SegmentBacklitAtWorkingSize(work_image, options, name, stats, work_prior)
                : SegmentAtWorkingSize(work_image, work_camera, options,
                                       options.plate_rim_px * work_scale, work_background, name,
                                       stats, work_prior, &grid_step, plate);
    fg = Upsampled(work_fg, image.size(), &box);
  } else {
    cv::Mat full_prior = prior;
    if (!prior.empty() && prior.size() != image.size())
      cv::resize(prior, full_prior, image.size(), 0, 0, cv::INTER_NEAREST);
    fg = backlit ? SegmentBacklitAtWorkingSize(image, options, name, stats, full_prior)
                 : SegmentAtWorkingSize(image, camera, options, options.plate_rim_px, background,
                                        name, stats, full_prior, &grid_step, plate);
    box = cv::boundingRect(fg);
  }
  if (options.refine_boundary) {
    if (backlit && !photo.empty()) {
      // The outline matted in both shots; each pixel takes the larger coverage: a glossy rim
      // reflects the lit panel in the mask shot (too little coverage there) but the dark studio
      // in the photo, and a product as light as the backdrop has no contrast in the photo
      // (where the mask shot's matte stays).
      // The photo only where its colours are a mix of the two sides (whatever else shows
      // through an opening there, a shadow, the plate, is not the product's).
      cv::Mat in_photo = fg.clone();
      const cv::Rect changed = RefineToAlpha({{&image, true, &fg}, {&photo, false, &in_photo}},
                                             options, grid_step / work_scale, box);
      cv::Mat larger = fg(changed);
      cv::max(larger, in_photo(changed), larger);
      box |= changed;
    } else {
      box |= RefineToAlpha({{&image, true, &fg}}, options, grid_step / work_scale, box);
    }
  }
  if (stats != nullptr) {
    // Counted in place, within the box (a comparison would write 18 MB).
    std::size_t object = 0;
    const cv::Rect counted = box;
    for (int y = counted.y; y < counted.br().y; ++y) {
      const auto* m = fg.ptr<std::uint8_t>(y);
      for (int x = counted.x; x < counted.br().x; ++x) object += m[x] >= 128 ? 1 : 0;
    }
    stats->object_fraction = static_cast<double>(object) / static_cast<double>(fg.total());
  }
  return fg;
}

namespace {

// The views of one camera in one pass: the table turns about its axis, so the plate's centre
// and a point above it project to the same pixels in each.
std::vector<std::vector<std::size_t>> ViewsByCamera(const std::vector<View>& views,
                                                    const std::vector<std::size_t>& indices) {
  struct Group {
    CameraModel camera;
    Eigen::Vector2d centre, above;
    std::vector<std::size_t> views;
  };
  std::vector<Group> groups;
  for (const std::size_t i : indices) {
    const CameraModel& camera = views[i].camera();
    const auto centre = camera.Project(Eigen::Vector3d::Zero());
    const auto above = camera.Project(Eigen::Vector3d(0.0, 0.0, 0.05));
    if (!centre || !above) continue;
    auto same = [&](const Group& g) {
      return g.camera.width == camera.width && g.camera.height == camera.height &&
             std::abs(g.camera.fx - camera.fx) < 1e-6 * camera.fx &&
             (g.centre - *centre).norm() < 0.5 && (g.above - *above).norm() < 0.5;
    };
    auto it = std::find_if(groups.begin(), groups.end(), same);
    if (it == groups.end()) it = groups.insert(groups.end(), {camera, *centre, *above, {}});
    it->views.push_back(i);
  }
  std::vector<std::vector<std::size_t>> out;
  out.reserve(groups.size());
  for (Group& g : groups) out.push_back(std::move(g.views));
  return out;
}

// The views of each camera agree on the plate (see PlateKeying): what each view should be
// keyed against, where it differs from what the view found alone (state kNone: keep it).
std::vector<PlateKeying> AgreedPlates(const std::vector<View>& views,
                                      const SilhouetteOptions& options,
                                      const std::vector<SilhouetteStats>& stats) {
  std::vector<PlateKeying> told(views.size());
  std::vector<std::size_t> keyed;
  for (std::size_t i = 0; i < views.size(); ++i)
    if (stats[i].plate.state != PlateKeying::State::kNone) keyed.push_back(i);
  // Two fits of the same plate differ by noise and by the product's shadow on it.
  const double tolerance = 1.5 * std::max(12.0, 2.0 * options.noise_threshold);
  for (const std::vector<std::size_t>& camera : ViewsByCamera(views, keyed)) {
    if (camera.size() < kMinPlateAgreementViews) continue;
    std::vector<std::size_t> fitted;
    for (const std::size_t i : camera)
      if (stats[i].plate.state == PlateKeying::State::kFitted) fitted.push_back(i);
    auto agree = [&](std::size_t a, std::size_t b) {
      return cv::norm(stats[a].plate.mean_bgr - stats[b].plate.mean_bgr) <= tolerance;
    };
    // The fit most others confirm.
    std::size_t best = 0;
    int best_support = 0;
    for (const std::size_t i : fitted) {
      const auto support = std::count_if(fitted.begin(), fitted.end(),
                                         [&](std::size_t j) { return j != i && agree(i, j); });
      if (support > best_support) {
        best = i;
        best_support = static_cast<int>(support);
      }
    }
    if (best_support + 1 >= kMinPlateAgreement) {
      for (const std::size_t i : camera)
        if (stats[i].plate.state != PlateKeying::State::kFitted || !agree(i, best))
          told[i] = stats[best].plate;
      continue;
    }
    // No colour seen twice: what was fitted is the product's own colour.
    for (const std::size_t i : fitted) told[i].state = PlateKeying::State::kHidden;
    if (fitted.empty()) {
      CAROUSEL_LOG_WARN(views[camera.front()].name()
                        << " and the other " << camera.size() - 1
                        << " views of its camera: the turntable plate is hidden; it is keyed "
                           "as backdrop");
    } else {
      CAROUSEL_LOG_WARN(views[camera.front()].name()
                        << " and the other " << camera.size() - 1
                        << " views of its camera: the turntable plate is hidden; the colour "
                        << (fitted.size() == 1 ? "one view" : "some views")
                        << " took for it agrees with no other view's, so it is the product's; "
                           "the plate is keyed as backdrop");
    }
  }
  return told;
}

}  // namespace

SilhouettesResult ComputeSilhouettes(const std::vector<View>& views,
                                     const std::vector<cv::Mat>& backgrounds,
                                     const SilhouetteOptions& requested, Progress& progress,
                                     const VisualHullOptions& hull,
                                     const std::vector<View>& mask_shots) {
  requested.Validate();
  SilhouetteOptions options = requested;
  options.method = ResolveSilhouetteMethod(requested.method, views.size(), mask_shots.size());
  CAROUSEL_THROW_IF(
      options.method == SilhouetteMethod::kBacklit && mask_shots.size() != views.size(),
      InvalidArgument,
      "the backlit method needs a backlit mask shot for each of the "
          << views.size() << " views (got " << mask_shots.size()
          << "; capture with --mask-shots backlit)");
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
      const View& source = options.method == SilhouetteMethod::kBacklit ? mask_shots[i] : view;
      const bool backlit = options.method == SilhouetteMethod::kBacklit;
      result.masks[i] =
          ComputeSilhouette(source.Image(), view.camera(), options, background, source.name(),
                            &result.stats[i], {}, backlit ? view.Image() : cv::Mat());
      source.ReleasePixels();
      view.ReleasePixels();
      progress.Report(++done, views.size());
    }
  });
  // The views of a camera agree on the plate: those that saw it otherwise are keyed again.
  if (options.method == SilhouetteMethod::kKey) {
    const std::vector<PlateKeying> told = AgreedPlates(views, options, result.stats);
    std::vector<std::size_t> again;
    for (std::size_t i = 0; i < views.size(); ++i)
      if (told[i].state != PlateKeying::State::kNone) again.push_back(i);
    ParallelFor(again.size(), 1, options.threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t k = begin; k < end; ++k) {
        progress.CheckCancelled();
        const View& view = views[again[k]];
        SilhouetteStats stats;
        result.masks[again[k]] = ComputeSilhouette(view.Image(), view.camera(), options, {},
                                                   view.name(), &stats, {}, {}, &told[again[k]]);
        result.stats[again[k]] = stats;
        view.ReleasePixels();
        CAROUSEL_LOG_DEBUG(view.name() << ": keyed again against the plate its camera's views "
                                          "agree on");
      }
    });
  }
  progress.EndStage();
  CheckNotCutByThePlate(views, result.stats);
  if (options.multi_view && views.size() >= kMinConsistencyViews)
    MakeConsistent(views, backgrounds, options, hull, &result, progress, mask_shots);
  return result;
}

void MakeConsistent(const std::vector<View>& views, const std::vector<cv::Mat>& backgrounds,
                    const SilhouetteOptions& requested, const VisualHullOptions& hull,
                    SilhouettesResult* result, Progress& progress,
                    const std::vector<View>& mask_shots) {
  SilhouetteOptions options = requested;
  options.method = ResolveSilhouetteMethod(requested.method, views.size(), mask_shots.size());
  VisualHullOptions hull_options = hull;
  hull_options.threads = options.threads;
  // Two passes: first the views with holes (a false hole carves a tunnel through every other
  // view's prior, which would then "repair" their silhouettes to agree with it), then, against
  // priors made from the repaired masks, every view that still disagrees.
  std::vector<cv::Mat> priors;
  Disagreement found;
  bool stale = true;
  for (int pass = 0; pass < 2; ++pass) {
    if (stale) {
      priors = OthersHullPriors(views, result->masks, hull_options);
      if (priors.empty()) return;  // an empty silhouette: the hull names it
      found = DisagreeingViews(views, result, options.threads, &priors);
      stale = false;
    }
    const std::vector<std::size_t> disagreeing = pass == 0 ? found.holes : found.any;
    if (disagreeing.empty()) continue;
    stale = true;
    progress.BeginStage("silhouettes: multi-view consistency");
    std::atomic<std::size_t> done{0};
    ParallelFor(disagreeing.size(), 1, options.threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t k = begin; k < end; ++k) {
        progress.CheckCancelled();
        const std::size_t v = disagreeing[k];
        const View& view = views[v];
        const cv::Mat background =
            options.method == SilhouetteMethod::kDifference ? backgrounds[v] : cv::Mat();
        SilhouetteStats stats = result->stats[v];
        const cv::Mat before = result->masks[v] >= 128;
        if (stats.given) {
          // A given mask: repaired geometrically, at its own size (nothing to segment again).
          cv::Mat prior;
          cv::resize(priors[v], prior, before.size(), 0, 0, cv::INTER_NEAREST);
          ApplyPrior(prior, &result->masks[v]);
        } else {
          const bool backlit = options.method == SilhouetteMethod::kBacklit;
          const View& source = backlit ? mask_shots[v] : view;
          const PlateKeying plate = result->stats[v].plate;
          result->masks[v] =
              ComputeSilhouette(source.Image(), view.camera(), options, background, source.name(),
                                &stats, priors[v], backlit ? view.Image() : cv::Mat(),
                                plate.state != PlateKeying::State::kNone ? &plate : nullptr);
          source.ReleasePixels();
          view.ReleasePixels();
        }
        const cv::Mat after = result->masks[v] >= 128;
        stats.outside_others = result->stats[v].outside_others;
        stats.hole_in_others = result->stats[v].hole_in_others;
        stats.redecided = true;
        stats.pixels_removed = result->stats[v].pixels_removed + cv::countNonZero(before & ~after);
        stats.pixels_added = result->stats[v].pixels_added + cv::countNonZero(~before & after);
        result->stats[v] = stats;
        CAROUSEL_LOG_INFO(view.name()
                          << ": silhouette re-decided against the other views' hull ("
                          << cv::countNonZero(before & ~after) << " pixels outside it removed, "
                          << cv::countNonZero(~before & after) << " added)");
        progress.Report(++done, disagreeing.size());
      }
    });
    progress.EndStage();
  }
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
