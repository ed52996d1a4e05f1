// Texel transfer (texture_map.h TransferTexture): where each texel's colour comes from.
#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/mesh.h"
#include "carousel/core/progress.h"
#include "carousel/core/raster.h"
#include "carousel/core/view.h"
#include "carousel/texture/atlas.h"
#include "carousel/texture/texture_map.h"
#include "test_camera.h"

namespace carousel::texture {
namespace {

using test_support::CameraLookingAtOrigin;

const cv::Vec3b square_bgr(200, 120, 40), occluder_bgr(30, 30, 220), backdrop_bgr(128, 128, 128);

// A square of `side` metres centred at (x, y, z), facing +Z, as two triangles.
void AddSquare(Mesh* mesh, double side, const Eigen::Vector3d& centre) {
  const double h = 0.5 * side, x = centre.x(), y = centre.y(), z = centre.z();
  const auto a = mesh->add_vertex({x - h, y - h, z}), b = mesh->add_vertex({x + h, y - h, z});
  const auto c = mesh->add_vertex({x + h, y + h, z}), d = mesh->add_vertex({x - h, y + h, z});
  mesh->add_face(a, b, c);
  mesh->add_face(a, c, d);
}

// The photo of `mesh` through `camera`: faces 0 and 1 (the square) in square_bgr, the others
// (the occluder) in occluder_bgr; its mask is the mesh's silhouette.
View Photograph(const Mesh& mesh, const CameraModel& camera) {
  const MeshRaster raster = RasterizeMesh(mesh, camera);
  const cv::Mat ids = raster.FaceIds();
  cv::Mat photo(camera.height, camera.width, CV_8UC3, cv::Scalar(128, 128, 128));
  for (int y = 0; y < photo.rows; ++y)
    for (int x = 0; x < photo.cols; ++x) {
      const int face = ids.at<int>(y, x);
      if (face >= 0) photo.at<cv::Vec3b>(y, x) = face < 2 ? square_bgr : occluder_bgr;
    }
  View view(camera, {});
  view.SetImage(photo);
  view.SetMask(raster.Mask());
  return view;
}

// The texel of `texture` at point `p` of face f (in its plane), nearest.
cv::Vec3b TexelAt(const Mesh& mesh, const cv::Mat& texture, int f, const Eigen::Vector3d& p) {
  std::array<Eigen::Vector3d, 3> corner;
  std::array<Eigen::Vector2d, 3> uv;
  int k = 0;
  for (const auto h : mesh.fh_range(Mesh::FaceHandle(f))) {
    const auto& q = mesh.point(mesh.to_vertex_handle(h));
    corner[k] = Eigen::Vector3d(q[0], q[1], q[2]);
    uv[k] = Eigen::Vector2d(mesh.uv(h)[0], mesh.uv(h)[1]);
    ++k;
  }
  const Eigen::Vector3d e0 = corner[1] - corner[0], e1 = corner[2] - corner[0], d = p - corner[0];
  Eigen::Matrix2d gram;
  gram << e0.dot(e0), e0.dot(e1), e0.dot(e1), e1.dot(e1);
  const Eigen::Vector2d w = gram.inverse() * Eigen::Vector2d(d.dot(e0), d.dot(e1));
  const Eigen::Vector2d at = (1.0 - w.x() - w.y()) * uv[0] + w.x() * uv[1] + w.y() * uv[2];
  const int x = static_cast<int>(std::lround(at.x() * texture.cols - 0.5));
  const int y = static_cast<int>(std::lround((1.0 - at.y()) * texture.rows - 0.5));
  return texture.at<cv::Vec3b>(y, x);
}

// A small square 2 cm above a large one hides part of face 0 from the camera straight above,
// between the 7 sample points by which the grouping finds face 0 seen whole there (so that
// view stays its front view). A second camera, 30 degrees off to the side, sees that part.
// With the per-texel depth test those texels come from the second view, in the square's
// colour; without it they show the occluder.
TEST(TransferTest, TexelsHiddenInTheFrontViewComeFromAViewThatSeesThem) {
  Mesh mesh;
  AddSquare(&mesh, 0.10, {0.0, 0.0, 0.0});               // faces 0, 1
  const Eigen::Vector3d occluder(0.026, -0.0229, 0.02);  // over face 0, off its sample points
  AddSquare(&mesh, 0.008, occluder);                     // faces 2, 3
  AtlasOptions atlas;
  atlas.size.size = 1024;
  Progress progress;
  const AtlasResult built = BuildAtlas(&mesh, atlas, progress);
  const CameraModel above = CameraLookingAtOrigin({0.0, 0.0, 0.5});
  const std::vector<View> views = {
      Photograph(mesh, above),
      Photograph(mesh, CameraLookingAtOrigin({-0.5 * std::sin(std::numbers::pi / 6), 0.0,
                                              0.5 * std::cos(std::numbers::pi / 6)}))};
  const GroupingResult grouping = GroupFaces(mesh, views, {}, progress);
  ASSERT_EQ(grouping.front_view[0], 0);  // the part hidden is between its sample points

  // Points of face 0 in the occluder's shadow from above (its centre and 2 mm around).
  const Eigen::Vector3d shadow = occluder * (0.5 / (0.5 - occluder.z()));
  std::vector<Eigen::Vector3d> hidden;
  for (const double dx : {-0.002, 0.0, 0.002})
    for (const double dy : {-0.002, 0.0, 0.002})
      hidden.emplace_back(shadow.x() + dx, shadow.y() + dy, 0.0);
  for (const Eigen::Vector3d& p : hidden) {  // the set-up: hidden from above
    const auto px = above.Project(p);
    ASSERT_TRUE(px);
    ASSERT_EQ(views[0].Image().at<cv::Vec3b>(static_cast<int>(std::lround(px->y())),
                                             static_cast<int>(std::lround(px->x()))),
              occluder_bgr);
  }
  auto distance = [](const cv::Vec3b& a, const cv::Vec3b& b) {
    return cv::norm(cv::Vec3d(a[0], a[1], a[2]) - cv::Vec3d(b[0], b[1], b[2]));
  };
  for (const int side : {1600, 0}) {
    SCOPED_TRACE(side);
    TransferOptions options;
    options.zbuffer_max_side = side;
    options.gain = false;
    const TextureMap map = TransferTexture(mesh, views, grouping, built.size, options, progress);
    for (const Eigen::Vector3d& p : hidden) {
      const cv::Vec3b texel = TexelAt(mesh, map.texture, 0, p);
      if (side > 0) {
        EXPECT_LT(distance(texel, square_bgr), 10.0) << p.transpose();
      } else {
        EXPECT_LT(distance(texel, occluder_bgr), 10.0) << p.transpose();
      }
    }
    if (side > 0) {
      EXPECT_GT(map.occluded_texels, 0);
    }
  }
}

}  // namespace
}  // namespace carousel::texture
