// Chart flattening (texture paper, section 2): each chart mapped to the plane with its angles
// kept as close to the surface's as the constraints allow.
//
// ABF++ (Sheffer, Levy, Mogilnitsky, Bogomyakov 2005): unknown 2D angles alpha per triangle
// corner minimise sum w (alpha - beta)^2, w = 1 / beta^2, beta the 3D angles (those around an
// interior vertex scaled to sum to 2 pi), subject to
//   triangle consistency   alpha_1 + alpha_2 + alpha_3 = pi             per triangle
//   vertex consistency     sum of the alphas around v = 2 pi           per interior vertex
//   wheel consistency      sum log sin(alpha_next) = sum log sin(alpha_prev)  per interior v
// solved by Newton (SQP) steps in which the triangle constraints are eliminated analytically
// (their block is diagonal) and the remaining Schur complement, 2 x interior vertices square,
// is factorised by Eigen's sparse Cholesky. Then the least-squares vertex reconstruction of the
// paper's Eq. 4 (LSCM-style): for each triangle (e1, e2, e3) with angles (a1, a2, a3),
//   sin a3 (e3 - e1) = sin a2 R(a1) (e2 - e1),
// two boundary vertices pinned, solved by sparse Cholesky of the normal equations.
// Every chart is checked: no flipped or degenerate UV triangle and a boundary that does not
// cross itself (with both, the map is one-to-one), and a stretch under max_chart_stretch (an
// angle-preserving map can shrink a protrusion a hundredfold). A chart that fails is split in two
// (regrown from two far-apart seeds, each half a disk) and flattened again; it is never shipped.
// Sliver and zero-area triangles get clamped angles (no NaNs). UVs are in metres: each chart
// is scaled so that its flattened area equals its surface area.
//
// Rectification (our extension, in the spirit of Liu et al. 2019, "Atlas refinement with
// bounded packing efficiency"): an angle-preserving chart is round and fills about three
// quarters of its box; rectangles pack with little waste. Each valid chart's boundary is
// pulled towards its minimum-area rectangle (its four nearest vertices onto the corners, arc
// length kept between them; ear tips follow their neighbours), the interior following by
// mean-value harmonic interpolation (Floater 2003: positive weights, exact for affine maps, so
// slivers stay unflipped), in up to four steps of half the remaining way (a step that fails
// is halved), while the chart stays valid and its L2 stretch stays under rectify_max_stretch
// (or under its own unrectified stretch, if that is higher). It trades a little stretch and
// shear for texels: on a 50k marching-cubes blob, utilization 69 % -> 79 % for L2 1.002 ->
// 1.037 and angle distortion 0.6 -> 7 degrees.
//
// Unbending (ours): a strip around a rim or a ring cut open flattens into a bent band that
// fills a tenth to a half of its box, and no rectangle around it is one to pull it onto. Its
// four corners are where its boundary turns most sharply (over half the band's width); its
// boundary goes onto a rectangle with the mean lengths of the opposite sides, the interior by
// the same harmonic interpolation, in one step; rectification then squares it up. A band of a
// developable surface (a cylinder's side) comes out with less stretch than its conformal
// annulus; a band bent in the plane gains some. Those are taken within an atlas-wide budget
// (ParameterizationOptions). A chart that still fills under 60 % of its box (a C around a
// concavity, an L) is tried split in two (regrown from two far-apart seeds) and kept split
// when the parts' boxes together take under 85 % of its own. Atlas utilization on the shared
// models: the shoe 68 % -> 83 %, the duck 72 % -> 77 %, the water bottle 72 % -> 79 %.
#pragma once

#include <array>
#include <vector>

#include <Eigen/Core>

#include "carousel/core/mesh.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"

namespace carousel::texture {

struct ParameterizationOptions {
  // Newton steps of ABF++ at most, 0..100; 0 = reconstruct from the 3D angles (plain LSCM).
  int max_abf_iterations = 30;
  // ABF++ stops when every constraint holds to this, radians, > 0.
  double abf_tolerance = 1e-5;
  // A chart that will not flatten validly is split at most this many times over, 0..64.
  int max_split_depth = 24;
  // A chart whose L2 stretch (its UV area equal to its surface area) exceeds this is split as
  // well, >= 1: an angle-preserving map shrinks protrusions, starving them of texels.
  double max_chart_stretch = 1.25;
  // Rectification keeps each chart's L2 stretch under this, >= 1; 1 = no rectification (the
  // plain ABF++ flattening, least angle distortion).
  double rectify_max_stretch = 1.04;
  // Unbending: a chart flattened into a bent band is also tried straightened (its boundary
  // onto a rectangle, corners at its four sharpest turns), up to this L2 stretch, >= 1; the
  // straightened bands whose stretch exceeds rectify_max_stretch are then taken, those saving
  // the most box area per unit of stretch first, while the L2 stretch of all charts together
  // stays under unbend_budget_stretch, >= 1. 1 = no unbending beyond the chart's bound.
  double max_unbent_stretch = 1.3;
  double unbend_budget_stretch = 1.04;
  // Worker threads; 0 = one per hardware thread.
  int threads = 0;
  // The description of every field above but `threads` (core/options.h): flags, widgets,
  // range checks.
  static const OptionTable<ParameterizationOptions>& Fields();
  void Validate() const;
};

struct ParameterizationResult {
  std::vector<std::array<Eigen::Vector2d, 3>> uv;  // per face, per corner, metres
  std::vector<int> chart_of_face;                  // the input's, with split charts renumbered
  int charts = 0;
  int charts_split = 0;       // charts that were split to flatten validly
  int abf_not_converged = 0;  // charts whose ABF++ stopped short of the tolerance
  int charts_unbent = 0;      // bent bands straightened
  int charts_split_for_fill =
      0;                    // charts filling little of their box, split in parts that fill more
  double l2_stretch = 1.0;  // of all charts together, each at its own surface area
  double seconds = 0.0;
};

// \pre chart_of_face: per face, 0 .. charts - 1, each chart a topological disk (ComputeCharts).
// \throw InvalidArgument (options, sizes), Cancelled.
ParameterizationResult ParameterizeCharts(const Mesh& mesh, const std::vector<int>& chart_of_face,
                                          int charts, const ParameterizationOptions& options,
                                          Progress& progress);

}  // namespace carousel::texture
