#include "carousel/texture/charts.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <queue>
#include <random>

#include "carousel/core/error.h"
#include "carousel/core/timer.h"
#include "chart_growth.h"
#include "face_graph.h"

namespace carousel::texture {
namespace {

// The initial seed count: `seeds`, or one per faces_per_seed faces up to max_seeds if more.
int InitialSeeds(const ChartOptions& options, int faces) {
  return std::max(options.seeds, std::min(options.max_seeds, faces / options.faces_per_seed));
}

using internal::FaceGraph;

constexpr int kSmoothingPasses = 8;  // boundary straightening passes at most

// Edges `face` shares with faces of `chart`.
int SharedEdges(const FaceGraph& g, const std::vector<int>& chart_of, int face, int chart) {
  int shared = 0;
  for (const int next : g.neighbours[face]) shared += next >= 0 && chart_of[next] == chart ? 1 : 0;
  return shared;
}

bool TouchesChart(const FaceGraph& g, const std::vector<int>& chart_of, int v, int chart,
                  int except) {
  for (int i = g.fan_start[v]; i < g.fan_start[v + 1]; ++i)
    if (g.fan[i] != except && chart_of[g.fan[i]] == chart) return true;
  return false;
}

// How `face`'s edges (edge k joins corners k and k + 1) meet `chart`: the number shared, one
// shared edge and one not shared (-1 if none).
struct EdgesWith {
  int shared = 0;
  int one = -1;
  int unshared = -1;
};
EdgesWith ClassifyEdges(const FaceGraph& g, const std::vector<int>& chart_of, int face, int chart) {
  EdgesWith e;
  for (int k = 0; k < 3; ++k) {
    const int next = g.neighbours[face][k];
    if (next >= 0 && chart_of[next] == chart) {
      ++e.shared;
      e.one = k;
    } else {
      e.unshared = k;
    }
  }
  return e;
}

// Whether `chart` (a disk) stays a disk when `face`, next to it, joins it: one boundary loop,
// no pinched vertex. O(valence).
bool KeepsDiskWhenJoining(const FaceGraph& g, const std::vector<int>& chart_of, int face,
                          int chart) {
  const EdgesWith e = ClassifyEdges(g, chart_of, face, chart);
  const auto& t = g.faces[face];
  // One edge shared: the opposite vertex must be new to the chart (else a pinch).
  if (e.shared == 1) return !TouchesChart(g, chart_of, t[(e.one + 2) % 3], chart, face);
  if (e.shared == 2) {
    // Two edges shared: their common vertex must become interior (its fan complete).
    const int middle = t[(e.unshared + 2) % 3];
    for (int i = g.fan_start[middle]; i < g.fan_start[middle + 1]; ++i)
      if (g.fan[i] != face && chart_of[g.fan[i]] != chart) return false;
    return true;
  }
  return false;  // 0 shared (not adjacent) or 3 (would close the surface)
}

// Whether `chart` (a disk holding `face`) stays a disk without it.
bool KeepsDiskWhenLeaving(const FaceGraph& g, const std::vector<int>& chart_of, int face,
                          int chart) {
  const EdgesWith e = ClassifyEdges(g, chart_of, face, chart);
  const auto& t = g.faces[face];
  // A leaf: its free vertex must belong to no other face of the chart.
  if (e.shared == 1) return !TouchesChart(g, chart_of, t[(e.one + 2) % 3], chart, face);
  if (e.shared == 2) {
    // A notch appears at the common vertex of the shared edges: it must be interior now.
    const int middle = t[(e.unshared + 2) % 3];
    if (g.boundary_vertex[middle]) return false;
    for (int i = g.fan_start[middle]; i < g.fan_start[middle + 1]; ++i)
      if (chart_of[g.fan[i]] != chart) return false;
    return true;
  }
  return false;  // the chart's only face, or an interior face (a hole)
}

// Straightens chart boundaries: a face that shares more edges with a neighbouring chart than
// with its own moves there when both stay disks. Removes the fingers and notches noisy
// normals leave; shorter boundaries flatten better and pack tighter. Faces with chart < 0
// are left alone.
void SmoothChartBoundaries(const FaceGraph& g, std::vector<int>* chart_of, int passes) {
  std::vector<int>& of = *chart_of;
  for (int pass = 0; pass < passes; ++pass) {
    int moved = 0;
    for (int f = 0; f < g.face_count(); ++f) {
      const int own = of[f];
      if (own < 0) continue;
      const int own_shared = SharedEdges(g, of, f, own);
      int target = -1;
      int target_shared = own_shared;
      for (const int next : g.neighbours[f]) {
        if (next < 0 || of[next] < 0 || of[next] == own) continue;
        const int shared = SharedEdges(g, of, f, of[next]);
        if (shared > target_shared) {
          target = of[next];
          target_shared = shared;
        }
      }
      if (target < 0 || !KeepsDiskWhenLeaving(g, of, f, own) ||
          !KeepsDiskWhenJoining(g, of, f, target))
        continue;
      of[f] = target;
      ++moved;
    }
    if (moved == 0) break;
  }
}

// Per face, the area-weighted normal of itself and its neighbours: a sliver's own normal is
// noise.
std::vector<Eigen::Vector3d> SmoothedNormals(const FaceGraph& g) {
  std::vector<Eigen::Vector3d> normals(g.faces.size());
  for (std::size_t f = 0; f < g.faces.size(); ++f) {
    Eigen::Vector3d sum = g.areas[f] * g.normals[f];
    for (const int next : g.neighbours[f])
      if (next >= 0) sum += g.areas[next] * g.normals[next];
    const double norm = sum.norm();
    normals[f] = norm > 0.0 ? Eigen::Vector3d(sum / norm) : g.normals[f];
  }
  return normals;
}

// Re-cuts the boundary between two neighbouring charts along the shortest edge path between
// its ends (the corners where a third chart or the mesh's boundary meets them), through the
// two charts' interior. Growth leaves boundaries that wander with the noise; straight ones
// flatten into charts with straight sides, which pack far tighter. A pair is re-cut only when
// it shares one arc, both charts stay disks and the faces that change chart lie, on average
// (area-weighted mean normal), within the normal bound of their new chart. Faces with
// chart < 0 are left alone.
class BoundaryRecutter {
 public:
  BoundaryRecutter(const FaceGraph& g, std::vector<Eigen::Vector3d> normals,
                   double max_deviation_deg, std::vector<int>* chart_of)
      : g_(g),
        normals_(std::move(normals)),
        min_dot_(std::cos(max_deviation_deg * std::numbers::pi / 180.0)),
        of_(*chart_of) {
    int charts = 0;
    for (const int c : of_) charts = std::max(charts, c + 1);
    faces_of_.resize(charts);
    for (int f = 0; f < g_.face_count(); ++f)
      if (of_[f] >= 0) faces_of_[of_[f]].push_back(f);
    region_.assign(g_.face_count(), 0);
    component_.assign(g_.face_count(), -1);
    vertex_stamp_.assign(g_.vertex_count(), 0);
    degree_.assign(g_.vertex_count(), 0);
    distance_.assign(g_.vertex_count(), 0.0);
    previous_.assign(g_.vertex_count(), -1);
    path_index_.assign(g_.vertex_count(), -1);
  }

  // Re-cuts every pair of neighbouring charts once; returns the number re-cut.
  int RecutAll(Progress& progress) {
    std::vector<std::pair<int, int>> pairs;
    for (int f = 0; f < g_.face_count(); ++f)
      for (const int next : g_.neighbours[f])
        if (next >= 0 && of_[f] >= 0 && of_[next] > of_[f]) pairs.emplace_back(of_[f], of_[next]);
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    int recut = 0;
    for (const auto& [a, b] : pairs) {
      progress.CheckCancelled();
      recut += Recut(a, b) ? 1 : 0;
    }
    return recut;
  }

 private:
  bool Recut(int a, int b) {
    // The shared edges must form one open arc u .. v of at least two edges (two ends, no
    // branch, one edge fewer than vertices; a closed loop besides the arc would need one
    // chart to enclose the other, which disks sharing an arc cannot).
    const int arc_mark = ++vertex_mark_;
    std::vector<int> touched;
    int edges = 0;
    for (const int f : faces_of_[a])
      for (int k = 0; k < 3; ++k) {
        const int next = g_.neighbours[f][k];
        if (next < 0 || of_[next] != b) continue;
        ++edges;
        for (const int v : {g_.faces[f][k], g_.faces[f][(k + 1) % 3]}) {
          if (vertex_stamp_[v] != arc_mark) {
            vertex_stamp_[v] = arc_mark;
            degree_[v] = 0;
            touched.push_back(v);
          }
          ++degree_[v];
        }
      }
    std::vector<int> ends;
    for (const int v : touched) {
      if (degree_[v] > 2) return false;
      if (degree_[v] == 1) ends.push_back(v);
    }
    if (ends.size() != 2 || edges != static_cast<int>(touched.size()) - 1 || edges < 2)
      return false;
    const int region = ++region_id_;
    for (const int f : faces_of_[a]) region_[f] = region;
    for (const int f : faces_of_[b]) region_[f] = region;
    const std::vector<int> path = ShortestPath(ends[0], ends[1]);
    if (path.empty()) return false;
    const int path_mark = ++vertex_mark_;
    for (std::size_t i = 0; i < path.size(); ++i) {
      vertex_stamp_[path[i]] = path_mark;
      path_index_[path[i]] = static_cast<int>(i);
    }
    auto on_path = [&](int x, int y) {
      return vertex_stamp_[x] == path_mark && vertex_stamp_[y] == path_mark &&
             std::abs(path_index_[x] - path_index_[y]) == 1;
    };
    // The two sides of the path: flood fill across the region's other edges.
    std::vector<int> region_faces = faces_of_[a];
    region_faces.insert(region_faces.end(), faces_of_[b].begin(), faces_of_[b].end());
    for (const int f : region_faces) component_[f] = -1;
    std::vector<double> area_of_a;  // per component, the area it takes from chart a
    std::vector<double> area;
    std::vector<int> stack;
    for (const int start : region_faces) {
      if (component_[start] >= 0) continue;
      const int c = static_cast<int>(area.size());
      if (c == 2) return false;
      area.push_back(0.0);
      area_of_a.push_back(0.0);
      component_[start] = c;
      stack.push_back(start);
      while (!stack.empty()) {
        const int f = stack.back();
        stack.pop_back();
        area[c] += g_.areas[f] + 1e-30;
        if (of_[f] == a) area_of_a[c] += g_.areas[f] + 1e-30;
        for (int k = 0; k < 3; ++k) {
          const int next = g_.neighbours[f][k];
          if (next < 0 || region_[next] != region || component_[next] >= 0) continue;
          if (on_path(g_.faces[f][k], g_.faces[f][(k + 1) % 3])) continue;
          component_[next] = c;
          stack.push_back(next);
        }
      }
    }
    if (area.size() != 2) return false;
    const int side_a = area_of_a[0] / area[0] >= area_of_a[1] / area[1] ? 0 : 1;
    // The faces that change chart must suit their new chart's normal (on average: a sliver's
    // normal is noise even smoothed).
    std::vector<int> new_a;
    std::vector<int> new_b;
    std::vector<int> to_a;
    std::vector<int> to_b;
    for (const int f : region_faces) {
      const bool in_a = component_[f] == side_a;
      (in_a ? new_a : new_b).push_back(f);
      if (in_a != (of_[f] == a)) (in_a ? to_a : to_b).push_back(f);
    }
    if ((to_a.empty() && to_b.empty()) || new_a.empty() || new_b.empty()) return false;
    if (!to_a.empty() && MeanNormal(to_a).dot(MeanNormal(faces_of_[a])) < min_dot_) return false;
    if (!to_b.empty() && MeanNormal(to_b).dot(MeanNormal(faces_of_[b])) < min_dot_) return false;
    for (const int f : new_a) component_[f] = 0;
    for (const int f : new_b) component_[f] = 1;
    if (!IsDisk(new_a, 0) || !IsDisk(new_b, 1)) return false;
    for (const int f : new_a) of_[f] = a;
    for (const int f : new_b) of_[f] = b;
    faces_of_[a] = std::move(new_a);
    faces_of_[b] = std::move(new_b);
    return true;
  }

  // Shortest edge path u .. v through the region's inside (Dijkstra, edge lengths), or empty.
  std::vector<int> ShortestPath(int u, int v) {
    using Item = std::pair<double, int>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
    const int region = region_id_;
    const int search = ++vertex_mark_;
    // Inside the region: the whole fan in it, not on the mesh's boundary.
    auto inside = [&](int x) {
      if (g_.boundary_vertex[x]) return false;
      for (int i = g_.fan_start[x]; i < g_.fan_start[x + 1]; ++i)
        if (region_[g_.fan[i]] != region) return false;
      return true;
    };
    auto relax = [&](int x, double d, int from) {
      if (vertex_stamp_[x] == search && distance_[x] <= d) return;
      vertex_stamp_[x] = search;
      distance_[x] = d;
      previous_[x] = from;
      queue.emplace(d, x);
    };
    relax(u, 0.0, -1);
    bool reached = false;
    while (!queue.empty()) {
      const auto [d, w] = queue.top();
      queue.pop();
      if (d > distance_[w]) continue;
      if (w == v) {
        reached = true;
        break;
      }
      if (w != u && !inside(w)) continue;
      for (int i = g_.fan_start[w]; i < g_.fan_start[w + 1]; ++i) {
        const int f = g_.fan[i];
        if (region_[f] != region) continue;
        for (const int x : g_.faces[f]) {
          if (x == w) continue;
          // From a corner, the first step must enter the inside (the arc is not a shortcut).
          if (w == u && x != v && !inside(x)) continue;
          if (w == u && x == v) continue;
          relax(x, d + (g_.positions[x] - g_.positions[w]).norm(), w);
        }
      }
    }
    std::vector<int> path;
    if (!reached) return path;
    for (int x = v; x >= 0; x = previous_[x]) path.push_back(x);
    std::reverse(path.begin(), path.end());
    return path;
  }

  Eigen::Vector3d MeanNormal(const std::vector<int>& faces) const {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const int f : faces) sum += g_.areas[f] * normals_[f];
    const double norm = sum.norm();
    return norm > 0.0 ? Eigen::Vector3d(sum / norm) : sum;
  }

  // Whether `faces` (connected across edges, each with component_ == `side`) is a disk: its
  // Euler characteristic V - E + F is 1 (a pinched vertex or a handle lowers it).
  bool IsDisk(const std::vector<int>& faces, int side) {
    const int mark = ++vertex_mark_;
    long vertices = 0;
    long boundary_edges = 0;
    for (const int f : faces) {
      for (int k = 0; k < 3; ++k) {
        const int v = g_.faces[f][k];
        if (vertex_stamp_[v] != mark) {
          vertex_stamp_[v] = mark;
          ++vertices;
        }
        const int next = g_.neighbours[f][k];
        if (next < 0 || region_[next] != region_id_ || component_[next] != side) ++boundary_edges;
      }
    }
    const long face_count = static_cast<long>(faces.size());
    const long edge_count = (3 * face_count + boundary_edges) / 2;
    return vertices - edge_count + face_count == 1;
  }

  const FaceGraph& g_;
  std::vector<Eigen::Vector3d> normals_;
  double min_dot_;
  std::vector<int>& of_;
  std::vector<std::vector<int>> faces_of_;
  int region_id_ = 0;
  int vertex_mark_ = 0;
  std::vector<int> region_;        // == region_id_: the face belongs to the pair being re-cut
  std::vector<int> component_;     // side of the path
  std::vector<int> vertex_stamp_;  // stamp of the vertex arrays below
  std::vector<int> degree_;
  std::vector<double> distance_;
  std::vector<int> previous_;
  std::vector<int> path_index_;
};

struct Entry {
  double cost;
  int face;
  int chart;
  int from;  // the chart's face next to `face`
  bool operator>(const Entry& other) const { return cost > other.cost; }
};

class ChartGrower {
 public:
  ChartGrower(const FaceGraph& graph, const ChartOptions& options)
      : g_(graph),
        options_(options),
        min_dot_(std::cos(options.max_normal_deviation_deg * std::numbers::pi / 180.0)) {
    double total_area = 0.0;
    for (const double a : g_.areas) total_area += a;
    scale_ = std::sqrt(std::max(total_area, 1e-30) / InitialSeeds(options, g_.face_count()));
    normals_ = SmoothedNormals(g_);
  }

  // Grows charts from `seeds` (chart i from seeds[i]) over the whole mesh, or over `region`
  // only when given (the other faces keep chart -2); faces no chart can take start new
  // charts, whose seeds are appended to `seeds`. Returns the chart of each face.
  std::vector<int> Grow(std::vector<int>* seeds, Progress& progress,
                        const std::vector<int>* region = nullptr) {
    const int n = g_.face_count();
    if (region == nullptr) {
      chart_of_.assign(n, -1);
    } else {
      chart_of_.assign(n, -2);
      for (const int f : *region) chart_of_[f] = -1;
    }
    normal_sum_.clear();
    seed_centroid_.clear();
    heap_ = decltype(heap_)();
    for (const int seed : *seeds) StartChart(seed);
    std::size_t scan = 0;
    const std::size_t scan_end = region == nullptr ? static_cast<std::size_t>(n) : region->size();
    auto scanned = [&](std::size_t i) {
      return region == nullptr ? static_cast<int>(i) : (*region)[i];
    };
    std::size_t popped = 0;
    while (true) {
      while (!heap_.empty()) {
        const Entry e = heap_.top();
        heap_.pop();
        if ((++popped & 0xffff) == 0) progress.CheckCancelled();
        if (chart_of_[e.face] != -1) continue;
        const double now = Cost(e.face, e.chart, e.from);
        if (now > e.cost * (1.0 + 1e-9) + 1e-300) {  // the chart's normal moved: re-queue
          heap_.push({now, e.face, e.chart, e.from});
          continue;
        }
        if (!Accepts(e.face, e.chart)) continue;  // another chart, or a new seed, takes it
        Assign(e.face, e.chart);
      }
      // Faces every chart turned down: one that a neighbouring chart can take as a disk joins
      // it regardless of its normal (noise, slivers); the rest seed new charts.
      for (std::size_t i = scan; i < scan_end; ++i) {
        const int face = scanned(i);
        if (chart_of_[face] != -1) continue;
        for (const int next : g_.neighbours[face]) {
          if (next < 0 || chart_of_[next] < 0) continue;
          if (Accepts(face, chart_of_[next], /*check_normal=*/false)) {
            Assign(face, chart_of_[next], /*spread=*/false);
            break;
          }
        }
      }
      while (scan < scan_end && chart_of_[scanned(scan)] >= 0) ++scan;
      if (scan == scan_end) break;
      seeds->push_back(scanned(scan));
      StartChart(scanned(scan));
    }
    return chart_of_;
  }

 private:
  void StartChart(int seed) {
    const int chart = static_cast<int>(normal_sum_.size());
    normal_sum_.push_back(Eigen::Vector3d::Zero());
    seed_centroid_.push_back(g_.centroids[seed]);
    Assign(seed, chart);
  }

  void Assign(int face, int chart, bool spread = true) {
    chart_of_[face] = chart;
    normal_sum_[chart] += g_.areas[face] * normals_[face];
    if (!spread) return;
    for (const int next : g_.neighbours[face])
      if (next >= 0 && chart_of_[next] == -1)
        heap_.push({Cost(next, chart, face), next, chart, face});
  }

  Eigen::Vector3d ChartNormal(int chart) const {
    const double norm = normal_sum_[chart].norm();
    return norm > 0.0 ? Eigen::Vector3d(normal_sum_[chart] / norm)
                      : Eigen::Vector3d(Eigen::Vector3d::Zero());
  }

  double Cost(int face, int chart, int from) const {
    const double flatness = 1.0 - ChartNormal(chart).dot(normals_[face]);
    const double spread = (g_.centroids[face] - seed_centroid_[chart]).norm() / scale_;
    return (flatness + options_.compactness * spread) *
           (g_.centroids[face] - g_.centroids[from]).norm();
  }

  // Whether `face` may join `chart`: normal close enough, and the chart stays a disk.
  bool Accepts(int face, int chart, bool check_normal = true) const {
    // The normal test applies to faces at the front only: a face the chart already holds on
    // two sides fills a notch (noise would otherwise leave it a chart of its own).
    if (check_normal && SharedEdges(g_, chart_of_, face, chart) == 1 &&
        ChartNormal(chart).dot(normals_[face]) < min_dot_)
      return false;
    return KeepsDiskWhenJoining(g_, chart_of_, face, chart);
  }

  const FaceGraph& g_;
  const ChartOptions& options_;
  double min_dot_;
  double scale_ = 1.0;
  std::vector<Eigen::Vector3d> normals_;  // per face, smoothed over its neighbours
  std::vector<int> chart_of_;
  std::vector<Eigen::Vector3d> normal_sum_;
  std::vector<Eigen::Vector3d> seed_centroid_;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<>> heap_;
};

// Each chart's face farthest from the chart's boundary (peeling rings inward; Cost2 =
// centroid distance), by a Dijkstra from all boundary faces at once.
std::vector<int> UpgradeSeeds(const FaceGraph& g, const std::vector<int>& chart_of, int charts) {
  const int n = g.face_count();
  std::vector<double> distance(n, std::numeric_limits<double>::infinity());
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
  for (int f = 0; f < n; ++f) {
    for (const int next : g.neighbours[f]) {
      if (next < 0 || chart_of[next] != chart_of[f]) {
        distance[f] = 0.0;
        queue.emplace(0.0, f);
        break;
      }
    }
  }
  while (!queue.empty()) {
    const auto [d, f] = queue.top();
    queue.pop();
    if (d > distance[f]) continue;
    for (const int next : g.neighbours[f]) {
      if (next < 0 || chart_of[next] != chart_of[f]) continue;
      const double nd = d + (g.centroids[next] - g.centroids[f]).norm();
      if (nd < distance[next]) {
        distance[next] = nd;
        queue.emplace(nd, next);
      }
    }
  }
  std::vector<int> seeds(charts, -1);
  for (int f = 0; f < n; ++f) {
    const int c = chart_of[f];
    // Ties go to the lowest face index: deterministic.
    if (seeds[c] < 0 || distance[f] > distance[seeds[c]]) seeds[c] = f;
  }
  return seeds;
}

}  // namespace

namespace internal {

std::vector<int> SplitChart(const FaceGraph& graph, const std::vector<int>& faces,
                            const ChartOptions& options, Progress& progress) {
  // Two seeds far apart: the face farthest (by centroid) from the first, then the face
  // farthest from that one.
  auto farthest_from = [&](int from) {
    int best = faces.front();
    double best_d = -1.0;
    for (const int f : faces) {
      const double d = (graph.centroids[f] - graph.centroids[from]).squaredNorm();
      if (d > best_d) {
        best_d = d;
        best = f;
      }
    }
    return best;
  };
  const int a = farthest_from(faces.front());
  const int b = farthest_from(a);
  std::vector<int> seeds{a, b};
  if (a == b) seeds.pop_back();
  ChartOptions split_options = options;
  split_options.seeds = 2;
  split_options.max_normal_deviation_deg = 180.0;  // the split only needs disks
  ChartGrower grower(graph, split_options);
  std::vector<int> chart_of = grower.Grow(&seeds, progress, &faces);
  SmoothChartBoundaries(graph, &chart_of, kSmoothingPasses);
  std::vector<int> local(faces.size());
  for (std::size_t i = 0; i < faces.size(); ++i) local[i] = chart_of[faces[i]];
  return local;
}

}  // namespace internal

const OptionTable<ChartOptions>& ChartOptions::Fields() {
  using O = ChartOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::seeds, {.name = "seeds", .help = "chart growth seeds (at least)", .min = 1});
    t.Add(&O::faces_per_seed, {.name = "faces-per-seed",
                               .help = "... but at least one seed per this many faces",
                               .unit = "faces",
                               .min = 100,
                               .advanced = true});
    t.Add(&O::max_seeds, {.name = "max-seeds",
                          .help = "... and up to this many by that rule",
                          .min = 1,
                          .advanced = true});
    t.Add(&O::max_normal_deviation_deg,
          {.name = "chart-normal-deviation",
           .help = "a face joins a chart only if its normal is this close to the chart's",
           .unit = "deg",
           .min = 0,
           .max = 180,
           .min_exclusive = true,
           .advanced = true});
    t.Add(&O::compactness, {.name = "compactness",
                            .help = "weight of the distance from the seed in chart growth "
                                    "(round charts pack tightly)",
                            .min = 0,
                            .advanced = true});
    t.Add(&O::max_iterations, {.name = "chart-iterations",
                               .help = "seed upgrades at most",
                               .min = 1,
                               .special = 0,
                               .special_meaning = "grow once from the initial seeds",
                               .advanced = true});
    t.Add(&O::random_seed, {.name = "chart-random-seed",
                            .help = "random seed of the initial seed choice",
                            .advanced = true});
    t.Add(&O::layouts, {.name = "chart-layouts",
                        .help = "chart layouts tried on small meshes (from consecutive random "
                                "seeds), the tightest packed kept",
                        .min = 1,
                        .max = 16,
                        .advanced = true});
    t.Add(&O::layout_faces, {.name = "chart-layout-faces",
                             .help = "meshes of at most this many faces get several layouts",
                             .unit = "faces",
                             .min = 0,
                             .advanced = true});
    return t;
  }();
  return table;
}

void ChartOptions::Validate() const {
  Fields().Check(*this);
  CAROUSEL_THROW_IF(!std::isfinite(compactness), InvalidArgument,
                    "--compactness must be finite, got " << compactness);
}

ChartsResult ComputeCharts(const Mesh& mesh, const ChartOptions& options, Progress& progress) {
  options.Validate();
  CAROUSEL_THROW_IF(mesh.n_faces() == 0, InvalidArgument, "charts: the mesh has no faces");
  Stopwatch stopwatch;
  progress.BeginStage("atlas: charts");
  const FaceGraph graph = internal::BuildFaceGraph(mesh);
  const int n = graph.face_count();

  // Initial seeds: distinct random faces, preferring faces with an area.
  std::mt19937_64 random(options.random_seed);
  std::vector<int> order(n);
  for (int f = 0; f < n; ++f) order[f] = f;
  std::shuffle(order.begin(), order.end(), random);
  std::stable_partition(order.begin(), order.end(), [&](int f) { return graph.areas[f] > 0.0; });
  const int seed_count = std::min(n, InitialSeeds(options, n));
  std::vector<int> seeds(order.begin(), order.begin() + seed_count);

  ChartGrower grower(graph, options);
  ChartsResult result;
  for (int iteration = 0;; ++iteration) {
    std::vector<int> grown_from = seeds;
    result.chart_of_face = grower.Grow(&grown_from, progress);
    result.charts = static_cast<int>(grown_from.size());
    result.iterations = iteration + 1;
    progress.Report(static_cast<double>(iteration + 1) / (options.max_iterations + 1));
    if (iteration == options.max_iterations) break;
    std::vector<int> upgraded = UpgradeSeeds(graph, result.chart_of_face, result.charts);
    if (upgraded == grown_from) {
      result.converged = true;
      break;
    }
    seeds = std::move(upgraded);
  }
  SmoothChartBoundaries(graph, &result.chart_of_face, kSmoothingPasses);
  BoundaryRecutter recutter(graph, SmoothedNormals(graph), options.max_normal_deviation_deg,
                            &result.chart_of_face);
  result.boundaries_recut = recutter.RecutAll(progress);
  SmoothChartBoundaries(graph, &result.chart_of_face, kSmoothingPasses);
  progress.EndStage();
  result.seconds = stopwatch.ElapsedSeconds();
  return result;
}

std::vector<int> CountChartBoundaryLoops(const Mesh& mesh, const std::vector<int>& chart_of_face,
                                         int charts) {
  CAROUSEL_THROW_IF(chart_of_face.size() != mesh.n_faces(), InvalidArgument,
                    "CountChartBoundaryLoops: one chart per face expected");
  // Boundary halfedges of each chart (the face across is another chart or none), linked
  // head to tail; loops counted by walking them.
  std::vector<int> loops(charts, 0);
  std::vector<char> visited(mesh.n_halfedges(), 0);
  auto on_boundary = [&](Mesh::HalfedgeHandle h, int chart) {
    if (mesh.is_boundary(h)) return false;
    if (chart_of_face[mesh.face_handle(h).idx()] != chart) return false;
    const auto across = mesh.opposite_face_handle(h);
    return !across.is_valid() || chart_of_face[across.idx()] != chart;
  };
  for (const auto h0 : mesh.halfedges()) {
    if (visited[h0.idx()] || mesh.is_boundary(h0)) continue;
    const int chart = chart_of_face[mesh.face_handle(h0).idx()];
    if (!on_boundary(h0, chart)) continue;
    ++loops[chart];
    auto h = h0;
    while (!visited[h.idx()]) {
      visited[h.idx()] = 1;
      // Next boundary halfedge of this chart: rotate around the end vertex.
      auto next = mesh.next_halfedge_handle(h);
      while (!on_boundary(next, chart))
        next = mesh.next_halfedge_handle(mesh.opposite_halfedge_handle(next));
      h = next;
    }
  }
  return loops;
}

}  // namespace carousel::texture
