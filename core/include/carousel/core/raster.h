// Triangle rasterisation at pixel centres, shared by the silhouette of a mesh in a photo
// (recon) and the texel coverage of an atlas (texture).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include <Eigen/Core>

namespace carousel {

// Calls visit(x, y) for every pixel (x, y) of a width x height grid whose centre, at integer
// coordinates (x, y), lies in the triangle or on its edges. Either orientation.
template <typename Visit>
void ForEachPixelCentreIn(std::array<Eigen::Vector2d, 3> t, int width, int height, Visit&& visit) {
  auto edge = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b, double x, double y) {
    return (b.x() - a.x()) * (y - a.y()) - (b.y() - a.y()) * (x - a.x());
  };
  // Counter-clockwise in these coordinates: every edge function >= 0 inside.
  if (edge(t[0], t[1], t[2].x(), t[2].y()) < 0.0) std::swap(t[1], t[2]);
  const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({t[0].x(), t[1].x(), t[2].x()}))));
  const int x1 =
      std::min(width - 1, static_cast<int>(std::floor(std::max({t[0].x(), t[1].x(), t[2].x()}))));
  const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({t[0].y(), t[1].y(), t[2].y()}))));
  const int y1 =
      std::min(height - 1, static_cast<int>(std::floor(std::max({t[0].y(), t[1].y(), t[2].y()}))));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x)
      if (edge(t[0], t[1], x, y) >= 0.0 && edge(t[1], t[2], x, y) >= 0.0 &&
          edge(t[2], t[0], x, y) >= 0.0)
        visit(x, y);
}

}  // namespace carousel
