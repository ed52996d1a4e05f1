// Texture grouping (texture_map.h GroupFaces): which views see which faces.
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/mesh.h"
#include "carousel/core/progress.h"
#include "carousel/core/view.h"
#include "carousel/texture/texture_map.h"
#include "test_camera.h"

namespace carousel::texture {
namespace {

// A square of `side` metres at height `z`, facing +Z, as two triangles.
void AddSquare(Mesh* mesh, double side, double z) {
  const double h = 0.5 * side;
  const auto a = mesh->add_vertex({-h, -h, z}), b = mesh->add_vertex({h, -h, z});
  const auto c = mesh->add_vertex({h, h, z}), d = mesh->add_vertex({-h, h, z});
  mesh->add_face(a, b, c);
  mesh->add_face(a, c, d);
}

// A camera `distance` metres above the origin looking straight down, 1600 x 1200.
View CameraAbove(double distance) {
  const CameraModel camera = test_support::CameraLookingAtOrigin({0.0, 0.0, distance});
  View view(camera, {});
  view.SetImage(cv::Mat(camera.height, camera.width, CV_8UC3, cv::Scalar(128, 128, 128)));
  return view;
}

// A layer 2 mm under another (a label's edge on a bottle, a shoe's upper tucked under its
// sole, a sheet modelled with some thickness) faces the camera too, but is hidden: only the
// layer on top is seen. The z-buffer's tolerance follows its pixel's footprint on the face,
// not a fixed 3 mm plus 0.4 % of the distance (5 mm here), which saw through it.
TEST(GroupingTest, ALayerAFewMillimetresUnderAnotherIsHidden) {
  Mesh mesh;
  AddSquare(&mesh, 0.10, 0.0);     // faces 0, 1: on top
  AddSquare(&mesh, 0.06, -0.002);  // faces 2, 3: under it
  GroupingOptions options;
  options.correction = false;
  Progress progress;
  const GroupingResult result = GroupFaces(mesh, {CameraAbove(0.5)}, options, progress);
  ASSERT_EQ(result.seen.size(), 4u);
  EXPECT_EQ(result.seen[0], 1);
  EXPECT_EQ(result.seen[1], 1);
  EXPECT_EQ(result.seen[2], 0);
  EXPECT_EQ(result.seen[3], 0);
  EXPECT_EQ(result.unseen_faces, 2);
}

}  // namespace
}  // namespace carousel::texture
