#include "carousel/sim/scene.h"

#include <gtest/gtest.h>
#include <tiny_gltf.h>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/testing/testing.h"

namespace carousel::sim {
namespace {

using testing::SharedDataFile;
using testing::TempDir;
using testing::WriteBytes;

TEST(SceneTest, LoadsEverySharedModelFromGltfAndObj) {
  struct Model {
    const char* gltf;
    const char* obj;
    std::size_t triangles;
  };
  for (const Model& model :
       {Model{"models/MaterialsVariantsShoe/glTF/MaterialsVariantsShoe.gltf",
              "models/MaterialsVariantsShoe/obj_derived/MaterialsVariantsShoe.obj", 22700},
        Model{"models/WaterBottle/glTF/WaterBottle.gltf",
              "models/WaterBottle/obj_derived/WaterBottle.obj", 4510},
        Model{"models/Avocado/glTF/Avocado.gltf", "models/Avocado/obj_derived/Avocado.obj", 682},
        Model{"models/Duck/glTF/Duck.gltf", "models/Duck/obj_derived/Duck.obj", 4212}}) {
    const Scene gltf = LoadScene(SharedDataFile(model.gltf));
    const Scene obj = LoadScene(SharedDataFile(model.obj));
    EXPECT_EQ(gltf.TriangleCount(), model.triangles) << model.gltf;
    EXPECT_EQ(obj.TriangleCount(), model.triangles) << model.obj;
    ASSERT_FALSE(gltf.textures.empty()) << model.gltf;
    ASSERT_FALSE(obj.textures.empty()) << model.obj;
    EXPECT_GE(gltf.textures[0]->levels().size(), 2u);
    // Same object: after placing both at the same height their boxes agree.
    Scene a = gltf, b = obj;
    PlaceOnTurntable(a, {.target_height_m = 0.2});
    PlaceOnTurntable(b, {.target_height_m = 0.2});
    EXPECT_THAT(a.Bounds().sizes(), testing::EigenNear(b.Bounds().sizes(), 2e-3)) << model.gltf;
  }
}

TEST(SceneTest, PlacementPutsTheObjectOnThePlateCentred) {
  Scene scene = LoadScene(SharedDataFile("models/Duck/glTF/Duck.gltf"));
  const Placement placement = PlaceOnTurntable(scene, {.target_height_m = 0.15});
  const Eigen::AlignedBox3d box = scene.Bounds();
  EXPECT_NEAR(box.min().z(), 0.0, 1e-12);
  EXPECT_NEAR(box.sizes().z(), 0.15, 1e-12);
  EXPECT_NEAR(box.center().x(), 0.0, 1e-12);
  EXPECT_NEAR(box.center().y(), 0.0, 1e-12);
  EXPECT_GT(placement.scale, 0.0);
  EXPECT_THROW(PlaceOnTurntable(scene, {.scale = 0.0}), InvalidArgument);
}

TEST(SceneTest, GltfIsTurnedFromYUpToZUp) {
  // The water bottle stands along glTF's +Y: after loading it stands along +Z.
  const Scene bottle = LoadScene(SharedDataFile("models/WaterBottle/glTF/WaterBottle.gltf"));
  const Eigen::Vector3d size = bottle.Bounds().sizes();
  EXPECT_GT(size.z(), 1.5 * size.x());
  EXPECT_GT(size.z(), 1.5 * size.y());
}

// The same model rendered from its glTF and from its OBJ conversion gives the same photo.
TEST(SceneTest, GltfAndObjRenderAlike) {
  Scene gltf = LoadScene(SharedDataFile("models/WaterBottle/glTF/WaterBottle.gltf"));
  Scene obj = LoadScene(SharedDataFile("models/WaterBottle/obj_derived/WaterBottle.obj"));
  PlaceOnTurntable(gltf, {.target_height_m = 0.25});
  PlaceOnTurntable(obj, {.target_height_m = 0.25});
  SimRigOptions rig;
  rig.width = 480;
  rig.height = 320;
  const CameraModel camera = CameraAtTableAngle(MakeSimRig(rig, gltf.Bounds()).front(), 0.7);
  const RenderResult a = Render(gltf, camera, 0.7, {});
  const RenderResult b = Render(obj, camera, 0.7, {});
  cv::Mat diff;
  cv::absdiff(a.image, b.image, diff);
  const double mean_diff = cv::mean(diff, a.mask)[0];
  EXPECT_GT(cv::countNonZero(a.mask), 5000);
  EXPECT_LT(mean_diff, 3.0) << "mean 8-bit difference over the object";
  cv::Mat both;
  cv::bitwise_xor(a.mask, b.mask, both);
  EXPECT_LT(cv::countNonZero(both), 0.01 * cv::countNonZero(a.mask));
}

TEST(SceneTest, LoadsBinaryGlb) {
  // Write the duck as .glb with tinygltf itself, then read it back through LoadScene.
  TempDir dir;
  tinygltf::TinyGLTF gltf;
  tinygltf::Model model;
  std::string error, warning;
  ASSERT_TRUE(gltf.LoadASCIIFromFile(&model, &error, &warning,
                                     SharedDataFile("models/Duck/glTF/Duck.gltf").string()));
  ASSERT_TRUE(
      gltf.WriteGltfSceneToFile(&model, (dir / "duck.glb").string(), true, true, false, true));
  const Scene glb = LoadScene(dir / "duck.glb");
  const Scene original = LoadScene(SharedDataFile("models/Duck/glTF/Duck.gltf"));
  EXPECT_EQ(glb.TriangleCount(), original.TriangleCount());
  EXPECT_THAT(glb.Bounds().min(), testing::EigenNear(original.Bounds().min(), 1e-6));
  ASSERT_EQ(glb.textures.size(), 1u);
  EXPECT_EQ(glb.textures[0]->width(), original.textures[0]->width());
}

TEST(SceneTest, MissingTextureIsAnIoErrorNamingIt) {
  TempDir dir;
  for (const char* file : {"Duck.gltf", "Duck0.bin"}) {
    std::filesystem::copy_file(SharedDataFile(std::string("models/Duck/glTF/") + file), dir / file);
  }
  CAROUSEL_EXPECT_THROW_WITH(LoadScene(dir / "Duck.gltf"), IoError, "DuckCM.png");
  // OBJ: the MTL names a texture that is not there.
  WriteBytes(dir / "box.obj",
             "mtllib box.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
             "usemtl skin\nf 1/1 2/2 3/3\n");
  WriteBytes(dir / "box.mtl", "newmtl skin\nKd 1 1 1\nmap_Kd skin.png\n");
  CAROUSEL_EXPECT_THROW_WITH(LoadScene(dir / "box.obj"), IoError, "skin.png");
}

TEST(SceneTest, UnsupportedGltfFeaturesAreNamed) {
  TempDir dir;
  const std::string base = testing::ReadBytes(SharedDataFile("models/Duck/glTF/Duck.gltf"));
  std::filesystem::copy_file(SharedDataFile("models/Duck/glTF/Duck0.bin"), dir / "Duck0.bin");
  std::filesystem::copy_file(SharedDataFile("models/Duck/glTF/DuckCM.png"), dir / "DuckCM.png");
  std::string draco = base;
  draco.insert(draco.find('{') + 1,
               "\"extensionsRequired\": [\"KHR_draco_mesh_compression\"], "
               "\"extensionsUsed\": [\"KHR_draco_mesh_compression\"],");
  WriteBytes(dir / "draco.gltf", draco);
  EXPECT_THROW(
      {
        try {
          LoadScene(dir / "draco.gltf");
        } catch (const FormatError& e) {
          EXPECT_NE(std::string(e.what()).find("draco.gltf"), std::string::npos) << e.what();
          EXPECT_NE(std::string(e.what()).find("KHR_draco_mesh_compression"), std::string::npos)
              << e.what();
          throw;
        }
      },
      FormatError);
  WriteBytes(dir / "broken.gltf", base.substr(0, base.size() / 2));
  CAROUSEL_EXPECT_THROW_WITH(LoadScene(dir / "broken.gltf"), FormatError, "broken.gltf");
  WriteBytes(dir / "scene.fbx", "Kaydara FBX Binary");
  CAROUSEL_EXPECT_THROW_WITH(LoadScene(dir / "scene.fbx"), FormatError, "unsupported scene format");
  CAROUSEL_EXPECT_THROW_WITH(LoadScene(dir / "absent.gltf"), IoError, "no such file");
}

TEST(SceneTest, ObjErrorsNameTheLine) {
  TempDir dir;
  WriteBytes(dir / "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
  CAROUSEL_EXPECT_THROW_WITH(LoadScene(dir / "bad.obj"), FormatError,
                             "line 4: face refers to vertex 9");
  WriteBytes(dir / "word.obj", "v 0 zero 0\n");
  CAROUSEL_EXPECT_THROW_WITH(LoadScene(dir / "word.obj"), FormatError, "line 1");
}

}  // namespace
}  // namespace carousel::sim
