// Quadric edge-collapse decimation (Garland & Heckbert 1997) on a plain indexed mesh, for the
// first, large reduction of the visual hull (millions of faces). OpenMesh's decimater needs
// about 45 us per collapse on this Debian build (its collapse check dominates); this one needs
// about 1 us, so the hull can be sampled finely. Closed manifold meshes stay closed and
// manifold (link condition); collapses that turn a face by more than the allowed angle or
// make a needle triangle are refused.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "carousel/core/mesh.h"

namespace carousel::recon::internal {

struct IndexedMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> faces;
};

IndexedMesh ToIndexed(const Mesh& mesh);
Mesh FromIndexed(const IndexedMesh& mesh);

// Collapses edges in order of quadric error until at most `target_faces` remain (or no legal
// collapse is left). Vertices move to the quadric's optimum.
void DecimateIndexed(IndexedMesh* mesh, std::size_t target_faces, double max_normal_deviation_deg,
                     double max_aspect_ratio);

}  // namespace carousel::recon::internal
