#include "carousel/sim/test_scenes.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "carousel/core/error.h"
#include "carousel/core/mesh_primitives.h"

namespace carousel::sim {

Scene SceneFromMesh(const Mesh& mesh, const Eigen::Vector3f& color, const std::string& source) {
  Mesh shaded = mesh;
  shaded.RecomputeNormals();
  Scene scene;
  scene.source = source;
  for (Mesh::VertexHandle v : shaded.vertices()) {
    const OpenMesh::Vec3d& p = shaded.point(v);
    const OpenMesh::Vec3d& n = shaded.normal(v);
    scene.positions.emplace_back(p[0], p[1], p[2]);
    scene.normals.emplace_back(n[0], n[1], n[2]);
    scene.uvs.emplace_back(0.0f, 0.0f);
  }
  for (Mesh::FaceHandle f : shaded.faces()) {
    auto fv = shaded.cfv_iter(f);
    const int a = fv->idx();
    const int b = (++fv)->idx();
    const int c = (++fv)->idx();
    scene.triangles.emplace_back(a, b, c);
    scene.triangle_material.push_back(0);
  }
  scene.materials.push_back(Material{source, color, -1, false});
  return scene;
}

Scene MakeSphereScene(double radius, const Eigen::Vector3d& centre, int subdivisions,
                      const Eigen::Vector3f& color) {
  return SceneFromMesh(MakeIcosphere(radius, subdivisions, {centre.x(), centre.y(), centre.z()}),
                       color, "procedural sphere");
}

Scene MakeRingScene(double major_radius, double minor_radius, const Eigen::Vector3f& color) {
  Mesh torus = MakeTorus(major_radius, minor_radius, 96, 48);
  for (const auto v : torus.vertices())
    torus.set_point(v, torus.point(v) + OpenMesh::Vec3d(0.0, 0.0, minor_radius));
  return SceneFromMesh(torus, color, "procedural ring");
}

Scene MakeMugScene(double height, const Eigen::Vector3f& color) {
  CAROUSEL_THROW_IF(!(height > 0), InvalidArgument, "MakeMugScene: height must be > 0");
  const double radius = 0.4 * height;
  Mesh mug = MakeCylinder(radius, height, 128, 8);
  // The handle: a torus in the x-z plane centred on the body's wall at half height; the part
  // inside the body is left out (hidden, and no surface of the product).
  const double major = 0.28 * height, minor = 0.07 * height;
  const Mesh torus = MakeTorus(major, minor, 96, 24);
  std::vector<Mesh::VertexHandle> handle(torus.n_vertices());
  auto inside = [&](const OpenMesh::Vec3d& p) {
    return p[0] * p[0] + p[1] * p[1] < (radius - 0.5 * minor) * (radius - 0.5 * minor);
  };
  auto placed = [&](Mesh::VertexHandle v) {
    // Torus about +Z -> about +Y (x stays, y -> z, z -> -y), then onto the wall.
    const OpenMesh::Vec3d& p = torus.point(v);
    return OpenMesh::Vec3d(radius + p[0], -p[2], 0.5 * height + p[1]);
  };
  for (Mesh::FaceHandle f : torus.faces()) {
    std::array<Mesh::VertexHandle, 3> corners;
    int k = 0, hidden = 0;
    for (Mesh::VertexHandle v : torus.fv_range(f)) {
      hidden += inside(placed(v)) ? 1 : 0;
      corners[k++] = v;
    }
    if (hidden == 3) continue;
    std::array<Mesh::VertexHandle, 3> added;
    for (int i = 0; i < 3; ++i) {
      Mesh::VertexHandle& h = handle[static_cast<std::size_t>(corners[i].idx())];
      if (!h.is_valid()) h = mug.add_vertex(placed(corners[i]));
      added[i] = h;
    }
    mug.add_face(added[0], added[1], added[2]);
  }
  return SceneFromMesh(mug, color, "procedural mug");
}

Scene MakeCheckerPlaneScene(double size, int squares, double height, int texels_per_square) {
  CAROUSEL_THROW_IF(!(size > 0) || squares < 2 || texels_per_square < 1, InvalidArgument,
                    "MakeCheckerPlaneScene: need size > 0, squares >= 2, texels >= 1");
  const int n = squares * texels_per_square;
  cv::Mat texture(n, n, CV_8UC3);
  for (int y = 0; y < n; ++y) {
    for (int x = 0; x < n; ++x) {
      const bool white = ((x / texels_per_square) + (y / texels_per_square)) % 2 == 0;
      texture.at<cv::Vec3b>(y, x) = white ? cv::Vec3b(235, 235, 235) : cv::Vec3b(20, 20, 20);
    }
  }
  Scene scene;
  scene.source = "procedural checker plane";
  scene.textures.push_back(std::make_shared<const Texture>(texture));
  scene.materials.push_back(Material{"checker", {1.0f, 1.0f, 1.0f}, 0, true});
  const double h = 0.5 * size;
  // Texture row 0 (v = 0) at +y: seen from above with +x right, the image reads upright.
  const Eigen::Vector3d corners[4] = {
      {-h, -h, height}, {h, -h, height}, {h, h, height}, {-h, h, height}};
  const Eigen::Vector2f uvs[4] = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
  for (int k = 0; k < 4; ++k) {
    scene.positions.push_back(corners[k]);
    scene.normals.emplace_back(0.0f, 0.0f, 1.0f);
    scene.uvs.push_back(uvs[k]);
  }
  scene.triangles.emplace_back(0, 1, 2);
  scene.triangles.emplace_back(0, 2, 3);
  scene.triangle_material = {0, 0};
  return scene;
}

Rigid3d StandCardOnTable(const Eigen::Matrix<double, 2, 3>& plane_from_pixel, const cv::Size& image,
                         double lean_deg, double lift_m) {
  CAROUSEL_THROW_IF(image.width < 2 || image.height < 2 || !(std::abs(lean_deg) < 89.0),
                    InvalidArgument, "StandCardOnTable: bad image size or lean");
  // Image right and down in plane coordinates, and the plane normal they span.
  const Eigen::Vector2d right2 = plane_from_pixel.leftCols<2>() * Eigen::Vector2d(1, 0);
  const Eigen::Vector2d down2 = plane_from_pixel.leftCols<2>() * Eigen::Vector2d(0, 1);
  Eigen::Matrix3d in_plane;
  const Eigen::Vector3d right(right2.x(), right2.y(), 0.0);
  const Eigen::Vector3d down(down2.x(), down2.y(), 0.0);
  in_plane << right.normalized(), down.normalized(), right.cross(down).normalized();
  // The same directions on the table: right along +X, down the leaning card.
  const double lean = lean_deg * M_PI / 180.0;
  const Eigen::Vector3d table_right(1, 0, 0);
  const Eigen::Vector3d table_down(0, -std::sin(lean), -std::cos(lean));
  Eigen::Matrix3d on_table;
  on_table << table_right, table_down, table_right.cross(table_down);
  Rigid3d pose(on_table * in_plane.transpose(), Eigen::Vector3d::Zero());
  // Centre on the axis, lowest corner at lift_m.
  const Eigen::Vector2d centre_px(0.5 * (image.width - 1), 0.5 * (image.height - 1));
  const Eigen::Vector2d c2 = plane_from_pixel * centre_px.homogeneous();
  const Eigen::Vector3d centre = pose * Eigen::Vector3d(c2.x(), c2.y(), 0.0);
  double lowest = 1e30;
  for (const Eigen::Vector2d& px :
       {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(image.width - 0.5, image.height - 0.5),
        Eigen::Vector2d(-0.5, image.height - 0.5), Eigen::Vector2d(image.width - 0.5, -0.5)}) {
    const Eigen::Vector2d xy = plane_from_pixel * px.homogeneous();
    lowest = std::min(lowest, (pose * Eigen::Vector3d(xy.x(), xy.y(), 0.0)).z());
  }
  pose.translation = Eigen::Vector3d(-centre.x(), -centre.y(), lift_m - lowest);
  return pose;
}

Scene MakePrintedCardScene(const cv::Mat& image,
                           const Eigen::Matrix<double, 2, 3>& plane_from_pixel,
                           const Rigid3d& table_from_plane, double thickness_m) {
  CAROUSEL_THROW_IF(image.empty() || image.depth() != CV_8U, InvalidArgument,
                    "MakePrintedCardScene: an 8-bit image is needed");
  CAROUSEL_THROW_IF(!(thickness_m > 0), InvalidArgument,
                    "MakePrintedCardScene: the card needs a thickness > 0");
  const Eigen::Matrix2d linear = plane_from_pixel.leftCols<2>();
  const double det = linear.determinant();
  CAROUSEL_THROW_IF(!(std::abs(det) > 0), InvalidArgument,
                    "MakePrintedCardScene: plane_from_pixel is singular");
  Scene scene;
  scene.source = "printed card";
  scene.textures.push_back(std::make_shared<const Texture>(image));
  scene.materials.push_back(Material{"print", {1.0f, 1.0f, 1.0f}, 0, false});
  scene.materials.push_back(Material{"card", {0.45f, 0.42f, 0.38f}, -1, false});
  // Image x right and y down span the plane; the viewer of the print is on the side where
  // they appear right-handed (-z of the plane when det > 0).
  const Eigen::Vector3d front = table_from_plane.rotation * Eigen::Vector3d(0, 0, det > 0 ? -1 : 1);
  const double w = image.cols - 0.5;
  const double h = image.rows - 0.5;
  const Eigen::Vector2d pixels[4] = {{-0.5, -0.5}, {w, -0.5}, {w, h}, {-0.5, h}};
  const Eigen::Vector2f uvs[4] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  Eigen::Vector3d corners[4];
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d xy = plane_from_pixel * pixels[k].homogeneous();
    corners[k] = table_from_plane * Eigen::Vector3d(xy.x(), xy.y(), 0.0);
  }
  const bool counter_clockwise =
      (corners[1] - corners[0]).cross(corners[2] - corners[0]).dot(front) > 0;
  const auto add_face = [&](const Eigen::Vector3d& offset, const Eigen::Vector3d& normal,
                            int material, bool ccw) {
    const int base = static_cast<int>(scene.positions.size());
    for (int k = 0; k < 4; ++k) {
      scene.positions.push_back(corners[k] + offset);
      scene.normals.push_back(normal.cast<float>());
      scene.uvs.push_back(uvs[k]);
    }
    if (ccw) {
      scene.triangles.emplace_back(base, base + 1, base + 2);
      scene.triangles.emplace_back(base, base + 2, base + 3);
    } else {
      scene.triangles.emplace_back(base, base + 2, base + 1);
      scene.triangles.emplace_back(base, base + 3, base + 2);
    }
    scene.triangle_material.push_back(material);
    scene.triangle_material.push_back(material);
  };
  add_face(Eigen::Vector3d::Zero(), front, 0, counter_clockwise);
  add_face(-thickness_m * front, -front, 1, !counter_clockwise);
  scene.Validate();
  return scene;
}

}  // namespace carousel::sim
