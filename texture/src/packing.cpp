#include "carousel/texture/packing.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <string>
#include <tuple>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/timer.h"

namespace carousel::texture {
namespace {

// A chart turned into its box: its corners' positions relative to the box's lower corner.
struct Placed {
  std::vector<int> faces;
  // Boundary edges in the box frame (metres): the chart is a filled disk, so its extent in
  // any vertical slab is reached on its boundary.
  std::vector<std::array<Eigen::Vector2d, 2>> outline;
  Eigen::Vector2d size = Eigen::Vector2d::Zero();  // metres
  double area = 0.0;                               // flattened area, m^2
};

// The chart turned by `quarter` quarter turns inside its box (a rotation: orientation kept).
Eigen::Vector2d Turn(const Eigen::Vector2d& p, const Eigen::Vector2d& size, int quarter) {
  switch (quarter) {
    case 1:
      return {size.y() - p.y(), p.x()};
    case 2:
      return {size.x() - p.x(), size.y() - p.y()};
    case 3:
      return {p.y(), size.x() - p.x()};
    default:
      return p;
  }
}

// A chart at a density and turn, as the packer sees it: per column of `block` texels, the
// lowest and highest texel row it occupies (its gutter included), relative to its origin.
struct Profile {
  std::vector<double> bottom, top;  // +inf / -inf for empty columns
  double height = 0.0;
};

constexpr double kEmpty = std::numeric_limits<double>::infinity();

Profile MakeProfile(const Placed& chart, double density, int quarter, int block, double margin) {
  const Eigen::Vector2d turned_size =
      quarter % 2 == 0 ? chart.size : Eigen::Vector2d(chart.size.y(), chart.size.x());
  const double width = turned_size.x() * density + 2 * margin;
  const int columns = std::max(1, static_cast<int>(std::ceil(width / block)));
  Profile profile;
  profile.bottom.assign(columns, kEmpty);
  profile.top.assign(columns, -kEmpty);
  profile.height = turned_size.y() * density + 2 * margin;
  auto extend = [&](int column, double y) {
    if (column < 0 || column >= columns) return;
    profile.bottom[column] = std::min(profile.bottom[column], y);
    profile.top[column] = std::max(profile.top[column], y);
  };
  for (const auto& edge : chart.outline) {
    const Eigen::Vector2d a =
        Turn(edge[0], chart.size, quarter) * density + Eigen::Vector2d(margin, margin);
    const Eigen::Vector2d b =
        Turn(edge[1], chart.size, quarter) * density + Eigen::Vector2d(margin, margin);
    // The edge's y extent in each column slab it spans: its ends, and where it crosses the
    // slabs' sides.
    extend(static_cast<int>(a.x() / block), a.y());
    extend(static_cast<int>(b.x() / block), b.y());
    const double lo = std::min(a.x(), b.x());
    const double hi = std::max(a.x(), b.x());
    for (int side = static_cast<int>(std::ceil(lo / block)); side * block <= hi; ++side) {
      const double x = static_cast<double>(side) * block;
      const double w = hi > lo ? (x - a.x()) / (b.x() - a.x()) : 0.0;
      const double y = a.y() + std::clamp(w, 0.0, 1.0) * (b.y() - a.y());
      extend(side - 1, y);
      extend(side, y);
    }
  }
  // The gutter: half of it on every side of the chart (the other half is the neighbour's).
  const int spread = static_cast<int>(std::ceil(margin / block));
  std::vector<double> bottom = profile.bottom;
  std::vector<double> top = profile.top;
  for (int c = 0; c < columns; ++c)
    for (int d = -spread; d <= spread; ++d) {
      if (c + d < 0 || c + d >= columns) continue;
      bottom[c] = std::min(bottom[c], profile.bottom[c + d]);
      top[c] = std::max(top[c], profile.top[c + d]);
    }
  for (int c = 0; c < columns; ++c) {
    if (bottom[c] == kEmpty) continue;
    profile.bottom[c] = std::max(0.0, bottom[c] - margin);
    profile.top[c] = std::min(profile.height, top[c] + margin);
  }
  return profile;
}

struct Layout {
  std::vector<Eigen::Vector2d> origin;  // texel position of each chart's turned box
  std::vector<int> quarter;             // its turn
};

// Places the charts, largest first, each at the column where it comes to rest lowest (its
// profile dropped onto the atlas's skyline, Tetris-like), trying every allowed turn; false
// when one does not fit.
bool TryPack(const std::vector<Placed>& charts, const std::vector<int>& order, double density,
             const PackingOptions& options, Layout* layout) {
  const int block = std::max(1, options.size / 512);
  const int columns = options.size / block;
  std::vector<double> skyline(columns, 0.0);
  layout->origin.assign(charts.size(), Eigen::Vector2d::Zero());
  layout->quarter.assign(charts.size(), 0);
  const double margin = 0.5 * options.gutter_texels;
  const int turns = options.mode == PackingMode::kObb ? 4 : 1;
  for (const int c : order) {
    double best_score = kEmpty;
    int best_column = 0;
    int best_quarter = 0;
    double best_y = 0.0;
    std::array<Profile, 4> profiles;
    for (int quarter = 0; quarter < turns; ++quarter) {
      profiles[quarter] = MakeProfile(charts[c], density, quarter, block, margin);
      const Profile& profile = profiles[quarter];
      const int width = static_cast<int>(profile.bottom.size());
      for (int x = 0; x + width <= columns; ++x) {
        double y = 0.0;
        for (int i = 0; i < width; ++i)
          if (profile.bottom[i] != kEmpty) y = std::max(y, skyline[x + i] - profile.bottom[i]);
        if (y + profile.height > options.size) continue;
        // Lowest rest first; then the least space left under the chart.
        double waste = 0.0;
        for (int i = 0; i < width; ++i)
          if (profile.bottom[i] != kEmpty) waste += y + profile.bottom[i] - skyline[x + i];
        const double score = (y + profile.height) * options.size * 4.0 + waste;
        if (score < best_score) {
          best_score = score;
          best_column = x;
          best_quarter = quarter;
          best_y = y;
        }
      }
    }
    if (best_score == kEmpty) return false;
    const Profile& profile = profiles[best_quarter];
    for (std::size_t i = 0; i < profile.top.size(); ++i)
      if (profile.top[i] != -kEmpty) skyline[best_column + i] = best_y + profile.top[i];
    layout->origin[c] =
        Eigen::Vector2d(static_cast<double>(best_column) * block + margin, best_y + margin);
    layout->quarter[c] = best_quarter;
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
      chart.area +=
          0.5 * ((t[1] - t[0]).x() * (t[2] - t[0]).y() - (t[1] - t[0]).y() * (t[2] - t[0]).x());
    }
    chart.size = bounds.sizes();
    // Boundary edges: those of one face only (a chart's shared corners have equal UVs).
    std::map<std::array<double, 4>, int> edges;
    for (const int f : chart.faces)
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector2d& a = result.uv[f][k];
        const Eigen::Vector2d& b = result.uv[f][(k + 1) % 3];
        const bool forward = std::tie(a.x(), a.y()) < std::tie(b.x(), b.y());
        const Eigen::Vector2d& lo = forward ? a : b;
        const Eigen::Vector2d& hi = forward ? b : a;
        ++edges[{lo.x(), lo.y(), hi.x(), hi.y()}];
      }
    for (const auto& [key, count] : edges)
      if (count == 1)
        chart.outline.push_back({Eigen::Vector2d(key[0], key[1]), Eigen::Vector2d(key[2], key[3])});
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
    total_area += chart.area;
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
    if (high - low < 4e-3 * high) break;
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
        const Eigen::Vector2d texel = best.origin[c] + Turn(p, chart.size, best.quarter[c]) * low;
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
