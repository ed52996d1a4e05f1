#include "carousel/texture/packing.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <random>
#include <string>
#include <tuple>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/timer.h"
#include "carousel/texture/atlas_size.h"

namespace carousel::texture {
namespace {

// One way to lay a chart in the atlas: a rotation (orientation kept) and the chart's outline
// in the frame of its rotated bounding box (lower corner at 0).
struct Pose {
  Eigen::Matrix2d rotation = Eigen::Matrix2d::Identity();
  Eigen::Vector2d lower = Eigen::Vector2d::Zero();  // box corner in the rotated frame
  Eigen::Vector2d size = Eigen::Vector2d::Zero();   // metres
  // Boundary edges, box frame (metres): the chart is a filled disk, so its extent in any
  // vertical slab is reached on its boundary.
  std::vector<std::array<Eigen::Vector2d, 2>> outline;
};

struct Placed {
  std::vector<int> faces;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  // of its flattened corners
  std::vector<Pose> poses;
  double area = 0.0;   // flattened area, m^2
  double scale = 1.0;  // its density over the common one, 1..max_density_spread
};

// A chart at a density and turn, as the packer sees it: per column of `block` texels, the
// lowest and highest texel row it occupies (its gutter included), relative to its origin.
struct Profile {
  std::vector<double> bottom, top;  // +inf / -inf for empty columns
  double height = 0.0;
};

constexpr double kEmpty = std::numeric_limits<double>::infinity();
constexpr int kPackingOrders = 200;  // orders the rectangle packer tries per density
// Growing charts into the room left: the largest kGrownCharts, in kGrowingPasses passes of
// kGrowingStep enlargements, each tried with the last box packer and kGrowingPackers box
// orders (on random blobs, 20 orders find 95 % of what all 200 do at a tenth of the time),
// placing at most as many charts in all as the bisection's packer runs did (deterministic;
// bounds the time: a growing step's runs place nearly every chart, the bisection's failing
// runs stop early).
constexpr std::size_t kGrownCharts = 40;
constexpr int kGrowingPasses = 3;
constexpr double kGrowingStep = 1.02;
constexpr int kGrowingPackers = 20;

Profile MakeProfile(const Pose& pose, double density, int block, double margin) {
  const double width = pose.size.x() * density + 2 * margin;
  const int columns = std::max(1, static_cast<int>(std::ceil(width / block)));
  Profile profile;
  profile.bottom.assign(columns, kEmpty);
  profile.top.assign(columns, -kEmpty);
  profile.height = pose.size.y() * density + 2 * margin;
  auto extend = [&](int column, double y) {
    if (column < 0 || column >= columns) return;
    profile.bottom[column] = std::min(profile.bottom[column], y);
    profile.top[column] = std::max(profile.top[column], y);
  };
  for (const auto& edge : pose.outline) {
    const Eigen::Vector2d a = edge[0] * density + Eigen::Vector2d(margin, margin);
    const Eigen::Vector2d b = edge[1] * density + Eigen::Vector2d(margin, margin);
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
  std::vector<Eigen::Vector2d> origin;  // texel position of each chart's posed box
  std::vector<int> pose;                // its pose
  int placed = 0;                       // charts the packer placed (all, or before one failed)
};

// Places the charts, largest first, each at the column where it comes to rest lowest (its
// profile dropped onto the atlas's skyline, Tetris-like), trying every pose; false
// when one does not fit.
bool TryPack(const std::vector<Placed>& charts, const std::vector<int>& order, double density,
             int size, const PackingOptions& options, Layout* layout) {
  const int block = std::max(1, size / 512);
  const int columns = size / block;
  std::vector<double> skyline(columns, 0.0);
  layout->origin.assign(charts.size(), Eigen::Vector2d::Zero());
  layout->pose.assign(charts.size(), 0);
  layout->placed = 0;
  const double margin = 0.5 * options.gutter_texels;
  std::vector<Profile> profiles;
  for (const int c : order) {
    double best_score = kEmpty;
    int best_column = 0;
    int best_pose = 0;
    double best_y = 0.0;
    const int poses = static_cast<int>(charts[c].poses.size());
    profiles.resize(poses);
    for (int pose = 0; pose < poses; ++pose) {
      profiles[pose] = MakeProfile(charts[c].poses[pose], density * charts[c].scale, block, margin);
      const Profile& profile = profiles[pose];
      const int width = static_cast<int>(profile.bottom.size());
      for (int x = 0; x + width <= columns; ++x) {
        double y = 0.0;
        for (int i = 0; i < width; ++i)
          if (profile.bottom[i] != kEmpty) y = std::max(y, skyline[x + i] - profile.bottom[i]);
        if (y + profile.height > size) continue;
        // Lowest rest first; then the least space left under the chart.
        double waste = 0.0;
        for (int i = 0; i < width; ++i)
          if (profile.bottom[i] != kEmpty) waste += y + profile.bottom[i] - skyline[x + i];
        const double score = (y + profile.height) * size * 4.0 + waste;
        if (score < best_score) {
          best_score = score;
          best_column = x;
          best_pose = pose;
          best_y = y;
        }
      }
    }
    if (best_score == kEmpty) return false;
    const Profile& profile = profiles[best_pose];
    for (std::size_t i = 0; i < profile.top.size(); ++i)
      if (profile.top[i] != -kEmpty) skyline[best_column + i] = best_y + profile.top[i];
    layout->origin[c] =
        Eigen::Vector2d(static_cast<double>(best_column) * block + margin, best_y + margin);
    layout->pose[c] = best_pose;
    ++layout->placed;
  }
  return true;
}

struct Rect {
  double x, y, w, h;
};

// MaxRects (Jylanki 2010): each chart's box (its gutter included) in the free rectangle that
// leaves the shortest side over (best short side fit), in either of its two orientations.
bool TryPackRects(const std::vector<Placed>& charts, const std::vector<int>& order, double density,
                  int atlas_size, const PackingOptions& options, Layout* layout,
                  int* failed = nullptr) {
  const double margin = 0.5 * options.gutter_texels;
  const double size = atlas_size;
  layout->origin.assign(charts.size(), Eigen::Vector2d::Zero());
  layout->pose.assign(charts.size(), 0);
  layout->placed = 0;
  std::vector<Rect> free{{0.0, 0.0, size, size}};
  for (const int c : order) {
    double best_score = kEmpty;
    double best_tie = kEmpty;
    int best_pose = -1;
    Rect best{};
    const int poses = std::min<int>(2, static_cast<int>(charts[c].poses.size()));
    for (int pose = 0; pose < poses; ++pose) {
      const double w = charts[c].poses[pose].size.x() * density * charts[c].scale + 2 * margin;
      const double h = charts[c].poses[pose].size.y() * density * charts[c].scale + 2 * margin;
      for (const Rect& r : free) {
        if (w > r.w || h > r.h) continue;
        const double dw = r.w - w;
        const double dh = r.h - h;
        const double score = std::min(dw, dh);
        const double tie = std::max(dw, dh);
        if (score < best_score || (score == best_score && tie < best_tie)) {
          best_score = score;
          best_tie = tie;
          best_pose = pose;
          best = {r.x, r.y, w, h};
        }
      }
    }
    if (best_pose < 0) {
      if (failed) *failed = c;
      return false;
    }
    layout->origin[c] = Eigen::Vector2d(best.x + margin, best.y + margin);
    layout->pose[c] = best_pose;
    ++layout->placed;
    // Split every free rectangle the box overlaps into its maximal remainders; drop the pieces
    // inside another rectangle (the untouched ones are inside none already).
    std::vector<Rect> kept;
    std::vector<Rect> pieces;
    kept.reserve(free.size());
    for (const Rect& r : free) {
      if (best.x >= r.x + r.w || best.x + best.w <= r.x || best.y >= r.y + r.h ||
          best.y + best.h <= r.y) {
        kept.push_back(r);
        continue;
      }
      if (best.x > r.x) pieces.push_back({r.x, r.y, best.x - r.x, r.h});
      if (best.x + best.w < r.x + r.w)
        pieces.push_back({best.x + best.w, r.y, r.x + r.w - best.x - best.w, r.h});
      if (best.y > r.y) pieces.push_back({r.x, r.y, r.w, best.y - r.y});
      if (best.y + best.h < r.y + r.h)
        pieces.push_back({r.x, best.y + best.h, r.w, r.y + r.h - best.y - best.h});
    }
    auto inside = [](const Rect& a, const Rect& b) {
      return a.x >= b.x && a.y >= b.y && a.x + a.w <= b.x + b.w && a.y + a.h <= b.y + b.h;
    };
    free.clear();
    for (std::size_t i = 0; i < pieces.size(); ++i) {
      bool covered = std::any_of(kept.begin(), kept.end(),
                                 [&](const Rect& k) { return inside(pieces[i], k); });
      // Of two equal pieces, the first is kept.
      for (std::size_t j = 0; j < pieces.size() && !covered; ++j)
        covered =
            j != i && inside(pieces[i], pieces[j]) && (j < i || !inside(pieces[j], pieces[i]));
      if (!covered) free.push_back(pieces[i]);
    }
    // An untouched rectangle is inside no piece: it was inside no rectangle a piece came from.
    free.insert(free.end(), kept.begin(), kept.end());
  }
  return true;
}

// Each chart's centre, area, outline and poses: in OBB mode its minimum-area box in four
// quarter turns, in AABB mode as it is.
void PoseCharts(const std::vector<std::array<Eigen::Vector2d, 3>>& uv, PackingMode mode,
                std::vector<Placed>* placed) {
  for (Placed& chart : *placed) {
    if (chart.faces.empty()) continue;
    for (const int f : chart.faces)
      for (const auto& p : uv[f]) chart.centre += p;
    chart.centre /= 3.0 * static_cast<double>(chart.faces.size());
    std::vector<cv::Point2f> points;
    for (const int f : chart.faces) {
      for (const auto& p : uv[f])
        points.emplace_back(static_cast<float>(p.x() - chart.centre.x()),
                            static_cast<float>(p.y() - chart.centre.y()));
      const auto& t = uv[f];
      chart.area +=
          0.5 * ((t[1] - t[0]).x() * (t[2] - t[0]).y() - (t[1] - t[0]).y() * (t[2] - t[0]).x());
    }
    // Boundary edges: those of one face only (a chart's shared corners have equal UVs).
    std::map<std::array<double, 4>, int> edges;
    for (const int f : chart.faces)
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector2d a = uv[f][k] - chart.centre;
        const Eigen::Vector2d b = uv[f][(k + 1) % 3] - chart.centre;
        const bool forward = std::tie(a.x(), a.y()) < std::tie(b.x(), b.y());
        const Eigen::Vector2d& lo = forward ? a : b;
        const Eigen::Vector2d& hi = forward ? b : a;
        ++edges[{lo.x(), lo.y(), hi.x(), hi.y()}];
      }
    std::vector<std::array<Eigen::Vector2d, 2>> outline;
    for (const auto& [key, count] : edges)
      if (count == 1)
        outline.push_back({Eigen::Vector2d(key[0], key[1]), Eigen::Vector2d(key[2], key[3])});
    // Turns (radians, the chart turned by -angle): its box's, in four quarter turns.
    std::vector<double> angles = {0.0};
    if (mode == PackingMode::kObb) {
      const double box = cv::minAreaRect(points).angle * std::numbers::pi / 180.0;
      angles = {box, box + 0.5 * std::numbers::pi, box + std::numbers::pi,
                box + 1.5 * std::numbers::pi};
    }
    for (const double angle : angles) {
      Pose pose;
      pose.rotation = Eigen::Rotation2Dd(-angle).toRotationMatrix();
      // Over every corner, not only the outline's: a folded chart from a caller stays inside.
      Eigen::AlignedBox2d bounds;
      for (const int f : chart.faces)
        for (const auto& p : uv[f]) bounds.extend(pose.rotation * (p - chart.centre));
      pose.lower = bounds.min();
      pose.size = bounds.sizes();
      pose.outline.reserve(outline.size());
      for (const auto& edge : outline)
        pose.outline.push_back(
            {pose.rotation * edge[0] - pose.lower, pose.rotation * edge[1] - pose.lower});
      chart.poses.push_back(std::move(pose));
    }
  }
}

}  // namespace

PackingMode ParsePackingMode(const std::string& name) {
  if (name == "obb") return PackingMode::kObb;
  if (name == "aabb") return PackingMode::kAabb;
  throw InvalidArgument("unknown packing '" + name + "' (expected obb or aabb)");
}

const char* PackingModeName(PackingMode mode) { return mode == PackingMode::kObb ? "obb" : "aabb"; }

const OptionTable<PackingOptions>& PackingOptions::Fields() {
  using O = PackingOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.AddChoice(&O::mode,
                {.name = "packing",
                 .help = "charts packed as their oriented boxes (obb, tighter) or as they lie "
                         "(aabb, the paper's comparison)"},
                {{"obb", PackingMode::kObb}, {"aabb", PackingMode::kAabb}});
    t.Add(&O::gutter_texels, {.name = "gutter",
                              .help = "empty texels between two charts",
                              .unit = "texels",
                              .min = 0,
                              .max = 64});
    t.Add(&O::max_density_spread,
          {.name = "density-spread",
           .help = "charts may get up to this times the common texel density, to fill the room "
                   "the packing leaves; 1 = every chart at one density",
           .min = 1,
           .max = 2,
           .advanced = true});
    return t;
  }();
  return table;
}

void PackingOptions::Validate() const { Fields().Check(*this); }

PackingResult PackCharts(const std::vector<std::array<Eigen::Vector2d, 3>>& uv,
                         const std::vector<int>& chart_of_face, int charts, int size,
                         const PackingOptions& options, Progress& progress) {
  options.Validate();
  CheckAtlasSize(size);
  CAROUSEL_THROW_IF(uv.size() != chart_of_face.size() || charts < 1, InvalidArgument,
                    "packing: " << uv.size() << " faces with UVs, " << chart_of_face.size()
                                << " chart ids, " << charts << " charts");
  Stopwatch stopwatch;
  progress.BeginStage("atlas: packing");
  PackingResult result;
  result.size = size;
  result.uv = uv;
  std::vector<Placed> placed(charts);
  for (std::size_t f = 0; f < uv.size(); ++f) {
    const int c = chart_of_face[f];
    CAROUSEL_THROW_IF(c < 0 || c >= charts, InvalidArgument,
                      "packing: chart id " << c << " outside 0.." << charts - 1);
    placed[c].faces.push_back(static_cast<int>(f));
  }
  PoseCharts(uv, options.mode, &placed);
  // Largest boxes first (by height, then width).
  std::vector<int> order(charts);
  std::iota(order.begin(), order.end(), 0);
  std::erase_if(order, [&](int c) { return placed[c].faces.empty(); });
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    const double ha = placed[a].poses.front().size.maxCoeff();
    const double hb = placed[b].poses.front().size.maxCoeff();
    return ha != hb ? ha > hb : a < b;
  });
  // Orders for the rectangle packer: largest first by longest side, by area and by shortest
  // side, then the first with neighbours swapped at random (a fixed seed: deterministic).
  std::vector<std::vector<int>> orders{order};
  auto add_order = [&](auto key) {
    std::vector<int> sorted = order;
    std::stable_sort(sorted.begin(), sorted.end(), [&](int a, int b) { return key(a) > key(b); });
    orders.push_back(std::move(sorted));
  };
  add_order([&](int c) { return placed[c].area; });
  add_order([&](int c) { return placed[c].poses.front().size.minCoeff(); });
  std::mt19937 random(1);
  while (static_cast<int>(orders.size()) < kPackingOrders) {
    std::vector<int> shuffled = order;
    for (std::size_t k = 0; k + 1 < shuffled.size(); ++k)
      if (random() % 3 == 0) std::swap(shuffled[k], shuffled[k + 1]);
    orders.push_back(std::move(shuffled));
  }
  // Packer k: 0 Tetris-like in the first order (charts interlock), k >= 1 as boxes in
  // orders[k - 1]. The charts fit at a density when any of them places them all.
  const int packers = 1 + static_cast<int>(orders.size());
  long work = 0;  // charts placed by all packer runs so far
  auto try_packer = [&](int k, double density, Layout* layout) {
    const bool fit = k == 0 ? TryPack(placed, order, density, size, options, layout)
                            : TryPackRects(placed, orders[k - 1], density, size, options, layout);
    work += layout->placed;
    return fit;
  };
  int placed_by = 0;  // the packer of the last success
  auto fits = [&](double density, Layout* layout) {
    for (int k = 0; k < packers; ++k)
      if (try_packer(k, density, layout)) {
        placed_by = k;
        return true;
      }
    return false;
  };
  // The largest density that fits: bisection between an area bound and a safe lower bound.
  double total_area = 0.0;
  double longest = 0.0;
  for (const Placed& chart : placed) {
    total_area += chart.area;
    for (const Pose& pose : chart.poses) longest = std::max(longest, pose.size.maxCoeff());
  }
  const double usable = size - options.gutter_texels;
  double high = std::min(std::sqrt(usable * usable / std::max(total_area, 1e-30)),
                         usable / std::max(longest, 1e-30));
  double low = 0.0;
  Layout layout;
  Layout best;
  for (int iteration = 0; iteration < 30; ++iteration) {
    progress.CheckCancelled();
    const double density = iteration == 0 ? high : 0.5 * (low + high);
    if (fits(density, &layout)) {
      low = density;
      best = layout;
      if (iteration == 0) break;
    } else {
      high = density;
    }
    if (high - low < 4e-3 * high) break;
    progress.Report(static_cast<double>(iteration + 1) / 30.0);
  }
  // The room the packing leaves, handed out: the largest charts in turn are enlarged while the
  // charts still fit at the common density.
  const long bisection_work = work;
  if (low > 0.0 && options.max_density_spread > 1.0) {
    std::vector<int> by_area = order;
    std::stable_sort(by_area.begin(), by_area.end(),
                     [&](int a, int b) { return placed[a].area > placed[b].area; });
    if (by_area.size() > kGrownCharts) by_area.resize(kGrownCharts);
    // The box packer that placed the charts last first, then the first kGrowingPackers box
    // orders (the Tetris-like packer is many times slower per chart).
    auto still_fits = [&](Layout* trial) {
      if (placed_by > 0 && try_packer(placed_by, low, trial)) return true;
      for (int k = 1; k <= kGrowingPackers && k < packers; ++k)
        if (k != placed_by && try_packer(k, low, trial)) {
          placed_by = k;
          return true;
        }
      return false;
    };
    for (int pass = 0; pass < kGrowingPasses; ++pass)
      for (const int c : by_area)
        while (placed[c].scale * kGrowingStep <= options.max_density_spread &&
               work - bisection_work < bisection_work) {
          progress.CheckCancelled();
          placed[c].scale *= kGrowingStep;
          if (still_fits(&layout)) {
            best = layout;
            continue;
          }
          placed[c].scale /= kGrowingStep;
          break;
        }
  }
  CAROUSEL_THROW_IF(!(low > 0.0), InvalidArgument,
                    "packing: " << charts << " charts with a " << options.gutter_texels
                                << "-texel gutter do not fit a " << size << " atlas");
  result.texels_per_metre = low;
  result.chart_texels_per_metre.assign(charts, 0.0);
  for (const int c : order) result.chart_texels_per_metre[c] = low * placed[c].scale;
  // Texel positions -> [0, 1] UVs.
  double chart_texels = 0.0;
  for (const int c : order) {
    const Placed& chart = placed[c];
    chart_texels += chart.area * low * low * chart.scale * chart.scale;
    const Pose& pose = chart.poses[best.pose[c]];
    for (const int f : chart.faces)
      for (auto& p : result.uv[f]) {
        const Eigen::Vector2d texel =
            best.origin[c] + (pose.rotation * (p - chart.centre) - pose.lower) * low * chart.scale;
        // The packer's rows count from the bottom: v up, orientation kept (a 90-degree turn
        // is a rotation).
        p = texel / size;
      }
  }
  result.utilization = chart_texels / (static_cast<double>(size) * size);
  progress.EndStage();
  result.seconds = stopwatch.ElapsedSeconds();
  return result;
}

}  // namespace carousel::texture
