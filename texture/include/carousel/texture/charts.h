// Chart growth partitioning (texture paper, section 1): the mesh cut into disk-like charts,
// each as flat and compact as it can be, ready to be flattened.
//
// Seeds (faces) grow into charts through a priority queue ordered by
//   Cost1(F, F') = (1 - N_C . N_F') |P_F' - P_F|        (+ compactness, below)
// with N_C the chart's mean (area-weighted) normal, N_F' the candidate's normal and P the face
// centroids. A face joins a chart only if the chart stays a topological disk (one boundary
// loop, no pinched vertex; checked in O(valence) per face) and, as our extension, only if its
// normal lies within max_normal_deviation_deg of the chart's: flat charts flatten with little
// stretch. Faces no chart can take become new seeds. Seed upgrade: each chart is peeled from
// its boundary inward in rings (Dijkstra over face centroids, Cost2 = |P_F' - P_F|); the face
// of the last ring is its new seed; all charts regrow from the new seeds until no seed moves.
// Costs are evaluated lazily: an entry whose chart normal changed since it was queued is
// re-queued with its current cost when it reaches the top of the heap. Finally the chart
// boundaries are straightened, as our extension (noise leaves ragged boundaries that flatten
// into ragged charts, which pack badly): the boundary two charts share is re-cut along the
// shortest edge path between its two ends (the corners where a third chart meets them), when
// both stay disks and the faces that change chart suit their new chart's normal; and a face
// sharing more edges with a neighbouring chart than with its own moves there when both stay
// disks.
#pragma once

#include <cstdint>
#include <vector>

#include "carousel/core/mesh.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"

namespace carousel::texture {

struct ChartOptions {
  // Initial seeds (the paper's default: 10), >= 1 ...
  int seeds = 10;
  // ... but at least one per this many faces, >= 100: the paper's meshes have 4,500 faces; on
  // a 200k-face reconstruction 10 charts would be huge, slow to flatten and hard to pack.
  int faces_per_seed = 1250;
  // ... up to this many, >= 1 (seeds wins when larger): past it, more charts cost more in
  // gutters and packing than they save in flattening (random 200k-face blobs: 40 seeds give
  // utilization 81 % at the least, 160 give 78 %; the surface's curvature still adds charts).
  int max_seeds = 40;
  // A face joins a chart only if its normal is within this angle of the chart's mean normal,
  // degrees, (0, 180]; 180 = the paper's unbounded growth.
  double max_normal_deviation_deg = 70.0;
  // Weight of the distance from the chart's seed in the growth cost (relative to the chart
  // size the seed count implies), >= 0: keeps charts round, so they pack tightly.
  double compactness = 0.3;
  // Seed upgrades at most, >= 0 (0: grow once from the initial seeds).
  int max_iterations = 8;
  // Random seed of the initial seed choice (deterministic results).
  std::uint64_t random_seed = 1;
  // On meshes of at most layout_faces faces, >= 0, the charts are laid out this many times,
  // 1..16, from random seeds random_seed, random_seed + 1, ..., and the layout that packs
  // tightest is kept (AtlasBuilder::Layout): with few charts, how well their boxes pack varies
  // a lot with where they start (random 5k-face blobs, 10 charts: one blob's utilization
  // 72.6 .. 80.4 % over 5 seeds), and a small mesh's layout takes a few hundredths of a
  // second.
  int layouts = 5;
  int layout_faces = 20000;
  // The description of every field above (core/options.h): flags, widgets, range checks.
  static const OptionTable<ChartOptions>& Fields();
  void Validate() const;
};

struct ChartsResult {
  std::vector<int> chart_of_face;  // per face, 0 .. charts - 1
  int charts = 0;
  int iterations = 0;        // growths run (1 + seed upgrades)
  bool converged = false;    // the seeds stopped moving
  int boundaries_recut = 0;  // chart pairs whose shared boundary was re-cut straight
  double seconds = 0.0;
};

// \pre a triangle mesh with at least one face.
// \throw InvalidArgument (options, empty mesh), Cancelled.
ChartsResult ComputeCharts(const Mesh& mesh, const ChartOptions& options, Progress& progress);

// Boundary loops of each chart (0 for a closed chart, 1 for a disk). For tests and checks.
std::vector<int> CountChartBoundaryLoops(const Mesh& mesh, const std::vector<int>& chart_of_face,
                                         int charts);

}  // namespace carousel::texture
