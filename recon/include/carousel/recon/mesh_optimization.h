// Mesh optimization: from the visual hull's dense, stair-stepped surface to a web-sized mesh
// (the paper's optimized mesh of about 4,500 faces).
//
//   1. Taubin lambda|mu smoothing (uniform Laplacian): removes the hull's staircase and the
//      ridges where silhouette cones meet (the paper's "virtual features") without the
//      shrinkage of plain Laplacian smoothing.
//   2. Quadric decimation (Garland-Heckbert, OpenMesh's decimater) to an intermediate size.
//   3. Isotropic remeshing (Botsch-Kobbelt 2004: split long edges, collapse short ones,
//      flip towards valence 6, tangential relaxation) at the edge length that gives about
//      `remesh_face_factor` x the target: well-shaped triangles for the final step.
//   4. Quadric decimation to exactly `target_faces`, guarded against normal flips and
//      needle triangles; where a collapse folded a thin part through another (faces that
//      intersect), the decimation is redone with the vertices there locked.
// Every step keeps the mesh closed and manifold; the result is outward oriented. Finally a
// uniform offset along the normals (a fraction of a millimetre) restores the hull's volume
// (or options.target_volume_m3).
// Units: the mesh's own (metres).
#pragma once

#include <cstddef>

#include "carousel/core/mesh.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"

namespace carousel::recon {

struct MeshOptimizationOptions {
  // Faces of the result (the paper's web model: 4,500), >= 100. Met within 1 %.
  int target_faces = 4500;
  // Taubin lambda|mu pairs on the hull; 0 = no smoothing. 0..200.
  int smoothing_iterations = 8;
  double taubin_lambda = 0.5;  // 0 < lambda < 1
  double taubin_mu = -0.53;    // mu < -lambda: the pass-band stays, high frequencies go
  // Isotropic remeshing before the final decimation.
  bool remesh = true;
  int remesh_iterations = 5;        // 1..20
  double remesh_face_factor = 2.0;  // remesh to about this x target_faces, >= 1
  // Decimation guards: largest change of a face normal by one collapse, degrees (0..180],
  // and largest triangle aspect ratio (longest edge / its height) a collapse may create, > 1.
  double max_normal_deviation_deg = 60.0;
  double max_aspect_ratio = 10.0;
  // Volume the result is offset to, m^3; 0 = the input's volume. (The visual hull's, when the
  // input is its coarser proxy.)
  double target_volume_m3 = 0.0;
  // The description of every field above (core/options.h): flags, widgets, range checks.
  static const OptionTable<MeshOptimizationOptions>& Fields();
  void Validate() const;
};

struct MeshOptimizationResult {
  Mesh mesh;
  std::size_t input_faces = 0;
  double input_volume_m3 = 0.0;
  double volume_m3 = 0.0;
  // Pairs of faces that intersect (0 unless the repair gave up; a warning is logged), and the
  // decimation rounds redone to remove intersections.
  std::size_t self_intersections = 0;
  int repair_rounds = 0;
  double seconds_smooth = 0.0;
  double seconds_decimate = 0.0;
  double seconds_remesh = 0.0;
};

// \pre `hull` is closed and manifold (the visual hull is).
// \throw InvalidArgument (options; an open, non-manifold or empty input, naming what is
//        wrong), Cancelled.
MeshOptimizationResult OptimizeMesh(const Mesh& hull, const MeshOptimizationOptions& options,
                                    Progress& progress);

// The steps, for staged use and tests. Each keeps the mesh closed and manifold.
void TaubinSmooth(Mesh* mesh, int iterations, double lambda, double mu);
// Quadric decimation to at most `target_faces`; returns the faces left.
std::size_t DecimateQuadric(Mesh* mesh, std::size_t target_faces, double max_normal_deviation_deg,
                            double max_aspect_ratio);
void RemeshIsotropic(Mesh* mesh, double edge_length, int iterations);

}  // namespace carousel::recon
