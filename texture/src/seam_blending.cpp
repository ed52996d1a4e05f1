// Seam blending of TransferTexture (texture_map.h), the paper's Eq. 8: near an edge between
// faces of different front images, a texel's colour is blended with the neighbour's image,
//   C = (C_f + C_n (1 - d)) / (2 - d),   d = D_c / D_f,
// d being the texel's distance from the edge relative to the opposite corner's (its
// barycentric coordinate of that corner): half and half on the edge, the face's own image at
// the opposite corner.
#include <algorithm>

#include "texture_map_steps.h"

namespace carousel::texture::internal {

std::array<int, 3> SeamViews(const std::vector<FaceData>& faces, int f, int view,
                             const GroupingResult& grouping) {
  const std::vector<int>& front = grouping.front_view;
  std::array<int, 3> seam{-1, -1, -1};
  for (int k = 0; k < 3; ++k) {
    const int g = faces[f].across[k];
    if (g >= 0 && front[g] >= 0 && front[g] != view &&
        grouping.usable[static_cast<std::size_t>(f) * grouping.views + front[g]])
      seam[k] = front[g];
  }
  return seam;
}

bool BlendAcrossSeam(const ViewSampler& sampler, const std::array<int, 3>& seam,
                     const std::array<double, 3>& b, const Eigen::Vector3d& p, bool correction,
                     cv::Vec3d* colour) {
  // The nearest seam edge: edge (k, k + 1) is opposite corner k + 2.
  int nearest = -1;
  double d = 1.0;
  for (int k = 0; k < 3; ++k)
    if (seam[k] >= 0 && b[(k + 2) % 3] < d) {
      d = std::max(0.0, b[(k + 2) % 3]);
      nearest = k;
    }
  if (nearest < 0) return false;
  cv::Vec3d other;
  if ((correction && !sampler.OnObject(seam[nearest], p)) ||
      !sampler.Sample(seam[nearest], p, &other))
    return false;
  *colour = (*colour + other * (1.0 - d)) / (2.0 - d);
  return true;
}

}  // namespace carousel::texture::internal
