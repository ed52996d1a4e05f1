// The filling steps of TransferTexture (texture_map.h): the texels no photo gives a colour to.
// Holes (texels on the background in every view), faces no view sees, and the gutter around
// the charts (dilated so that bilinear filtering and mip-mapping do not pull in black).
#include <opencv2/imgproc.hpp>

#include "carousel/core/raster.h"
#include "texture_map_steps.h"

namespace carousel::texture::internal {
namespace {

// The mean colour of the 8-neighbours of `q` that `take(x, y)` accepts; false when none does.
template <typename Take>
bool NeighbourMean(const cv::Mat& texture, const cv::Point& q, Take&& take, cv::Vec3b* mean) {
  cv::Vec3d sum(0, 0, 0);
  int n = 0;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int x = q.x + dx, y = q.y + dy;
      if (x < 0 || y < 0 || x >= texture.cols || y >= texture.rows || !take(x, y)) continue;
      sum += cv::Vec3d(texture.at<cv::Vec3b>(y, x));
      ++n;
    }
  if (n == 0) return false;
  *mean = cv::Vec3b(cv::saturate_cast<std::uint8_t>(sum[0] / n),
                    cv::saturate_cast<std::uint8_t>(sum[1] / n),
                    cv::saturate_cast<std::uint8_t>(sum[2] / n));
  return true;
}

// The mean colour of each face no view sees: its textured neighbours', spreading outwards
// (the faces with a front view: their texels' mean).
std::vector<cv::Vec3d> SpreadFaceColours(const std::vector<FaceData>& faces,
                                         const std::vector<int>& front_view,
                                         const TransferredTexels& texels, int* unseen) {
  const std::size_t nf = faces.size();
  std::vector<cv::Vec3d> mean(nf, cv::Vec3d(0, 0, 0));
  std::vector<unsigned char> known(nf, 0);
  std::vector<int> pending;
  for (std::size_t f = 0; f < nf; ++f) {
    if (front_view[f] < 0) {
      pending.push_back(static_cast<int>(f));
      continue;
    }
    if (texels.face_count[f] > 0) {
      mean[f] = texels.face_sum[f] / texels.face_count[f];
      known[f] = 1;
    }
  }
  *unseen = static_cast<int>(pending.size());
  for (int round = 0; !pending.empty() && round < 1000; ++round) {
    std::vector<int> still;
    std::vector<std::pair<int, cv::Vec3d>> learned;
    for (const int f : pending) {
      cv::Vec3d sum(0, 0, 0);
      int n = 0;
      for (const int g : faces[f].across)
        if (g >= 0 && known[g]) {
          sum += mean[g];
          ++n;
        }
      if (n > 0)
        learned.emplace_back(f, sum / n);
      else
        still.push_back(f);
    }
    if (learned.empty()) break;
    for (const auto& [f, c] : learned) {
      mean[f] = c;
      known[f] = 1;
    }
    pending.swap(still);
  }
  return mean;
}

}  // namespace

int InpaintHoles(const std::vector<std::vector<cv::Point>>& holes, TextureMap* map) {
  const int size = map->texture.cols;
  cv::Mat hole(size, size, CV_8UC1, cv::Scalar(0));
  std::vector<cv::Point> pending;
  for (const auto& list : holes)
    for (const cv::Point& q : list) {
      hole.at<std::uint8_t>(q.y, q.x) = 1;
      pending.push_back(q);
    }
  const int count = static_cast<int>(pending.size());
  while (!pending.empty()) {
    std::vector<std::pair<cv::Point, cv::Vec3b>> values;
    std::vector<cv::Point> still;
    for (const cv::Point& q : pending) {
      cv::Vec3b mean;
      const bool found = NeighbourMean(
          map->texture, q,
          [&](int x, int y) {
            return !hole.at<std::uint8_t>(y, x) && map->coverage.at<std::uint8_t>(y, x);
          },
          &mean);
      if (found)
        values.emplace_back(q, mean);
      else
        still.push_back(q);
    }
    if (values.empty()) {
      // Islands without a good texel around: the texture's mean colour.
      const cv::Scalar mean = cv::mean(map->texture, map->coverage & (hole == 0));
      for (const cv::Point& q : still)
        map->texture.at<cv::Vec3b>(q.y, q.x) = cv::Vec3b(cv::saturate_cast<std::uint8_t>(mean[0]),
                                                         cv::saturate_cast<std::uint8_t>(mean[1]),
                                                         cv::saturate_cast<std::uint8_t>(mean[2]));
      break;
    }
    for (const auto& [q, colour] : values) {
      map->texture.at<cv::Vec3b>(q.y, q.x) = colour;
      hole.at<std::uint8_t>(q.y, q.x) = 0;
    }
    pending.swap(still);
  }
  return count;
}

int FillUnseenFaces(const std::vector<FaceData>& faces, const std::vector<int>& front_view,
                    const TransferredTexels& texels, TextureMap* map) {
  const int size = map->texture.cols;
  int unseen = 0;
  const std::vector<cv::Vec3d> mean = SpreadFaceColours(faces, front_view, texels, &unseen);
  for (std::size_t f = 0; f < faces.size(); ++f) {
    if (front_view[f] >= 0) continue;
    const FaceData& face = faces[f];
    std::array<Eigen::Vector2d, 3> t;
    for (int i = 0; i < 3; ++i)
      t[i] = Eigen::Vector2d(face.uv[i].x() * size - 0.5, (1.0 - face.uv[i].y()) * size - 0.5);
    const cv::Vec3b colour(cv::saturate_cast<std::uint8_t>(mean[f][0]),
                           cv::saturate_cast<std::uint8_t>(mean[f][1]),
                           cv::saturate_cast<std::uint8_t>(mean[f][2]));
    int covered = 0;
    ForEachPixelCentreIn(t, size, size, [&](int x, int y) {
      map->texture.at<cv::Vec3b>(y, x) = colour;
      map->coverage.at<std::uint8_t>(y, x) = 255;
      ++covered;
    });
    map->texels_per_face[f] = covered;
  }
  return unseen;
}

void DilateGutter(int texels, TextureMap* map) {
  const int size = map->texture.cols;
  cv::Mat filled = map->coverage.clone();
  std::vector<cv::Point> ring;
  {
    cv::Mat grown;
    cv::dilate(filled, grown, cv::Mat::ones(3, 3, CV_8U));
    cv::Mat border = grown & ~filled;
    if (cv::countNonZero(border) > 0) cv::findNonZero(border, ring);
  }
  for (int r = 0; r < texels && !ring.empty(); ++r) {
    std::vector<std::pair<cv::Point, cv::Vec3b>> values;
    values.reserve(ring.size());
    for (const cv::Point& q : ring) {
      cv::Vec3b mean;
      if (NeighbourMean(
              map->texture, q, [&](int x, int y) { return filled.at<std::uint8_t>(y, x) != 0; },
              &mean))
        values.emplace_back(q, mean);
    }
    std::vector<cv::Point> next;
    for (const auto& [q, colour] : values) {
      map->texture.at<cv::Vec3b>(q.y, q.x) = colour;
      filled.at<std::uint8_t>(q.y, q.x) = 255;
    }
    for (const auto& [q, colour] : values) {
      (void)colour;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = q.x + dx, yy = q.y + dy;
          if (xx < 0 || yy < 0 || xx >= size || yy >= size) continue;
          std::uint8_t& m = filled.at<std::uint8_t>(yy, xx);
          if (m == 0) {
            m = 1;  // queued for the next ring (1: not yet coloured)
            next.emplace_back(xx, yy);
          }
        }
    }
    // Texels queued but not coloured stay uncovered for the averaging.
    for (const cv::Point& q : next) filled.at<std::uint8_t>(q.y, q.x) = 0;
    ring.swap(next);
  }
  // What is left: the texture's mean colour (the coarsest mip levels blend towards it).
  const cv::Scalar average = cv::mean(map->texture, map->coverage);
  map->texture.setTo(average, filled == 0);
}

}  // namespace carousel::texture::internal
