#include "carousel/texture/packing.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>
#include <string>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/timer.h"

namespace carousel::texture {
namespace {

// A chart turned into its box: its corners' positions relative to the box's lower corner.
struct Placed {
  std::vector<int> faces;
  Eigen::Vector2d size = Eigen::Vector2d::Zero();  // metres
  double area = 0.0;                                // flattened area, m^2
};

// Skyline bottom-left packing of rectangles into a width x height bin.
class Skyline {
 public:
  Skyline(int width, int height) : width_(width), height_(height) { segments_.push_back({0, 0, width}); }

  // Places a w x h rectangle (or h x w); returns false when it does not fit.
  bool Place(int w, int h, int* x, int* y, bool* rotated) {
    int best_y = std::numeric_limits<int>::max();
    int best_x = 0;
    std::size_t best_i = 0;
    int best_w = 0;
    int best_h = 0;
    for (const bool turn : {false, true}) {
      const int rw = turn ? h : w;
      const int rh = turn ? w : h;
      for (std::size_t i = 0; i < segments_.size(); ++i) {
        const int left = segments_[i].x;
        if (left + rw > width_) break;
        int top = 0;
        int covered = 0;
        for (std::size_t j = i; j < segments_.size() && covered < rw; ++j) {
          top = std::max(top, segments_[j].y);
          covered = segments_[j].x + segments_[j].width - left;
        }
        if (top + rh > height_) continue;
        if (top + rh < best_y + best_h || (top + rh == best_y + best_h && left < best_x)) {
          best_y = top;
          best_x = left;
          best_i = i;
          best_w = rw;
          best_h = rh;
          *rotated = turn;
        }
      }
    }
    if (best_y == std::numeric_limits<int>::max()) return false;
    *x = best_x;
    *y = best_y;
    // Raise the skyline over [best_x, best_x + best_w).
    std::vector<Segment> next(segments_.begin(), segments_.begin() + static_cast<long>(best_i));
    next.push_back({best_x, best_y + best_h, best_w});
    for (std::size_t j = best_i; j < segments_.size(); ++j) {
      const Segment& s = segments_[j];
      const int end = s.x + s.width;
      if (end <= best_x + best_w) continue;
      const int start = std::max(s.x, best_x + best_w);
      next.push_back({start, s.y, end - start});
    }
    // Merge neighbours of equal height.
    segments_.clear();
    for (const Segment& s : next) {
      if (!segments_.empty() && segments_.back().y == s.y)
        segments_.back().width += s.width;
      else
        segments_.push_back(s);
    }
    return true;
  }

 private:
  struct Segment {
    int x, y, width;
  };
  int width_;
  int height_;
  std::vector<Segment> segments_;
};

struct Layout {
  std::vector<Eigen::Vector2i> origin;  // texel position of each chart's box (inside its gutter)
  std::vector<char> rotated;
};

// Packs the boxes at `density` texels per metre; false when they do not all fit.
bool TryPack(const std::vector<Placed>& charts, const std::vector<int>& order, double density,
             const PackingOptions& options, Layout* layout) {
  Skyline skyline(options.size, options.size);
  layout->origin.assign(charts.size(), Eigen::Vector2i::Zero());
  layout->rotated.assign(charts.size(), 0);
  const int g = options.gutter_texels;
  for (const int c : order) {
    const int w = static_cast<int>(std::ceil(charts[c].size.x() * density)) + g;
    const int h = static_cast<int>(std::ceil(charts[c].size.y() * density)) + g;
    int x = 0;
    int y = 0;
    bool rotated = false;
    if (!skyline.Place(w, h, &x, &y, &rotated)) return false;
    layout->origin[c] = Eigen::Vector2i(x + g / 2, y + g / 2);
    layout->rotated[c] = rotated ? 1 : 0;
  }
  return true;
}

}  // namespace

PackingMode ParsePackingMode(const std::string& name) {
  if (name == "obb") return PackingMode::kObb;
  if (name == "aabb") return PackingMode::kAabb;
  throw InvalidArgument("unknown packing '" + name + "' (expected obb or aabb)");
}

const char* PackingModeName(PackingMode mode) { return mode == PackingMode::kObb ? "obb" : "aabb"; }

void PackingOptions::Validate() const {
  auto check = [](bool ok, const char* field, const char* rule) {
    if (!ok) throw InvalidArgument(std::string("PackingOptions.") + field + " must be " + rule);
  };
  check(size >= 64 && size <= 32768, "size", "in [64, 32768]");
  check(gutter_texels >= 0 && gutter_texels <= 64, "gutter_texels", "in [0, 64]");
}

PackingResult PackCharts(const std::vector<std::array<Eigen::Vector2d, 3>>& uv,
                         const std::vector<int>& chart_of_face, int charts,
                         const PackingOptions& options, Progress& progress) {
  options.Validate();
  CAROUSEL_THROW_IF(uv.size() != chart_of_face.size() || charts < 1, InvalidArgument,
                    "packing: " << uv.size() << " faces with UVs, " << chart_of_face.size()
                                << " chart ids, " << charts << " charts");
  Stopwatch stopwatch;
  progress.BeginStage("atlas: packing");
  PackingResult result;
  result.uv = uv;
  std::vector<Placed> placed(charts);
  for (std::size_t f = 0; f < uv.size(); ++f) {
    const int c = chart_of_face[f];
    CAROUSEL_THROW_IF(c < 0 || c >= charts, InvalidArgument,
                      "packing: chart id " << c << " outside 0.." << charts - 1);
    placed[c].faces.push_back(static_cast<int>(f));
  }
  // Each chart into its box: rotated (OBB) and moved to the origin.
  for (Placed& chart : placed) {
    if (chart.faces.empty()) continue;
    std::vector<cv::Point2f> points;
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    for (const int f : chart.faces)
      for (const auto& p : uv[f]) centre += p;
    centre /= 3.0 * static_cast<double>(chart.faces.size());
    for (const int f : chart.faces)
      for (const auto& p : uv[f])
        points.emplace_back(static_cast<float>(p.x() - centre.x()),
                            static_cast<float>(p.y() - centre.y()));
    Eigen::Matrix2d turn = Eigen::Matrix2d::Identity();
    if (options.mode == PackingMode::kObb) {
      const cv::RotatedRect box = cv::minAreaRect(points);
      turn = Eigen::Rotation2Dd(-box.angle * std::numbers::pi / 180.0).toRotationMatrix();
    }
    Eigen::AlignedBox2d bounds;
    for (const int f : chart.faces)
      for (auto& p : result.uv[f]) {
        p = turn * (p - centre);
        bounds.extend(p);
      }
    for (const int f : chart.faces) {
      for (auto& p : result.uv[f]) p -= bounds.min();
      const auto& t = result.uv[f];
      chart.area += 0.5 * ((t[1] - t[0]).x() * (t[2] - t[0]).y() - (t[1] - t[0]).y() * (t[2] - t[0]).x());
    }
    chart.size = bounds.sizes();
  }
  // Largest boxes first (by height, then width).
  std::vector<int> order(charts);
  std::iota(order.begin(), order.end(), 0);
  std::erase_if(order, [&](int c) { return placed[c].faces.empty(); });
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    const double ha = std::max(placed[a].size.x(), placed[a].size.y());
    const double hb = std::max(placed[b].size.x(), placed[b].size.y());
    return ha != hb ? ha > hb : a < b;
  });
  // The largest density that fits: bisection between an area bound and a safe lower bound.
  double total_area = 0.0;
  double longest = 0.0;
  for (const Placed& chart : placed) {
    total_area += chart.size.x() * chart.size.y();
    longest = std::max({longest, chart.size.x(), chart.size.y()});
  }
  const double usable = options.size - options.gutter_texels;
  double high = std::min(std::sqrt(usable * usable / std::max(total_area, 1e-30)),
                         usable / std::max(longest, 1e-30));
  double low = 0.0;
  Layout layout;
  Layout best;
  for (int iteration = 0; iteration < 30; ++iteration) {
    progress.CheckCancelled();
    const double density = iteration == 0 ? high : 0.5 * (low + high);
    if (TryPack(placed, order, density, options, &layout)) {
      low = density;
      best = layout;
      if (iteration == 0) break;
    } else {
      high = density;
    }
    if (high - low < 1e-4 * high) break;
    progress.Report(static_cast<double>(iteration + 1) / 30.0);
  }
  CAROUSEL_THROW_IF(!(low > 0.0), InvalidArgument,
                    "packing: " << charts << " charts with a " << options.gutter_texels
                                << "-texel gutter do not fit a " << options.size << " atlas");
  result.texels_per_metre = low;
  // Texel positions -> [0, 1] UVs.
  double chart_texels = 0.0;
  for (const int c : order) {
    const Placed& chart = placed[c];
    chart_texels += chart.area * low * low;
    for (const int f : chart.faces)
      for (auto& p : result.uv[f]) {
        Eigen::Vector2d t = p * low;  // texels inside the box
        if (best.rotated[c]) t = Eigen::Vector2d(std::ceil(chart.size.y() * low) - t.y(), t.x());
        const Eigen::Vector2d texel = best.origin[c].cast<double>() + t;
        // The packer's rows count from the bottom: v up, orientation kept (a 90-degree turn
        // is a rotation).
        p = texel / options.size;
      }
  }
  result.utilization = chart_texels / (static_cast<double>(options.size) * options.size);
  progress.EndStage();
  result.seconds = stopwatch.ElapsedSeconds();
  return result;
}

}  // namespace carousel::texture
