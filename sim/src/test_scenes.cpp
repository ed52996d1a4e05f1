#include "carousel/sim/test_scenes.h"

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

}  // namespace carousel::sim
