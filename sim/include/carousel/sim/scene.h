// Scene: a textured triangle mesh for the simulated rig, loaded from glTF 2.0 (.gltf, .glb)
// or OBJ+MTL and placed on the turntable plate.
//
// Frames: after PlaceOnTurntable() the scene is in the turntable frame (metres, +Z up along
// the rotation axis, origin at the centre of the plate's top surface; DESIGN.md). glTF is
// +Y up: loading converts it to +Z up (x stays, y -> z, z -> -y) unless told otherwise.
// Texture coordinates are stored in image convention: u right, v down, (0,0) = the texture's
// top-left corner (glTF's convention; OBJ's v-up coordinates are flipped on load).
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "carousel/core/mesh.h"
#include "carousel/core/rigid3.h"

namespace carousel::sim {

// An 8-bit BGR texture with its mip pyramid (level 0 = full size).
class Texture {
 public:
  Texture() = default;
  // \throw InvalidArgument unless `image` is 8-bit with 1, 3 or 4 channels.
  explicit Texture(const cv::Mat& image);
  const std::vector<cv::Mat>& levels() const { return levels_; }
  int width() const { return levels_.empty() ? 0 : levels_[0].cols; }
  int height() const { return levels_.empty() ? 0 : levels_[0].rows; }

 private:
  std::vector<cv::Mat> levels_;  // CV_8UC3 each
};

struct Material {
  std::string name;
  Eigen::Vector3f base_color{1.0f, 1.0f, 1.0f};  // multiplies the texture; linear, 0..1
  int texture = -1;                              // index into Scene::textures, -1 = none
  bool double_sided = true;
  // Highlights (Blinn-Phong, white): strength (linear, 0 = matte) and exponent.
  float specular = 0.0f;
  float shininess = 50.0f;
  // See-through (glass, clear plastic): the fraction of the light behind the surface that
  // passes through it, tinted by base_color, at normal incidence (less at grazing angles,
  // where a Fresnel reflection takes over); 0 = opaque.
  float transmission = 0.0f;
};

// What a studio finds hard, on any scene: every material made white, black, glossy (its own
// colours and a strong highlight) or see-through (clear, faintly tinted glass with highlights).
enum class MaterialOverride { kNone, kWhite, kBlack, kGlossy, kSeeThrough };
// "none", "white", "black", "glossy", "see-through". \throw InvalidArgument naming the others.
MaterialOverride ParseMaterialOverride(const std::string& name);
const char* MaterialOverrideName(MaterialOverride material);

struct Scene {
  // Per vertex (all the same length).
  std::vector<Eigen::Vector3d> positions;  // metres
  std::vector<Eigen::Vector3f> normals;    // unit, may be recomputed
  std::vector<Eigen::Vector2f> uvs;        // image convention; (0,0) when the mesh has none
  // Per triangle.
  std::vector<Eigen::Vector3i> triangles;  // counter-clockwise seen from outside
  std::vector<int> triangle_material;      // index into materials
  std::vector<Material> materials;
  std::vector<std::shared_ptr<const Texture>> textures;
  std::string source;  // file it came from, or a procedural name

  std::size_t TriangleCount() const { return triangles.size(); }
  Eigen::AlignedBox3d Bounds() const;
  // Applies `transform` (x -> scale * (R x) + t) to positions and rotates normals.
  void Transform(const Rigid3d& transform, double scale = 1.0);
  // Recomputes smooth vertex normals from the faces (area-weighted).
  void RecomputeNormals();
  // The geometry as a Mesh, with vertices at equal positions welded (glTF splits vertices at
  // UV seams), e.g. the ground-truth surface. Faces OpenMesh cannot add (non-manifold after
  // welding) keep their own vertices, so no face is lost.
  Mesh ToMesh() const;
  // \throw InvalidArgument if arrays disagree in size, an index is out of range or a
  // coordinate is not finite.
  void Validate() const;
  // Every material white (albedo 0.9, no texture), black (0.03), glossy (its colours, a
  // strong, sharp highlight) or see-through (transmission 0.85, a faint green tint, the
  // glossy highlight); kNone changes nothing.
  void OverrideMaterials(MaterialOverride material);
};

struct SceneLoadOptions {
  // Axis that points up in the file: glTF's is +Y (the specification); OBJ files from glTF
  // are +Y too. Loading rotates it onto +Z.
  enum class UpAxis { kY, kZ } up_axis = UpAxis::kY;
};

// Loads .gltf, .glb or .obj (with its .mtl and textures), all nodes of the default scene with
// their transforms. \throw IoError (missing file, missing texture or buffer) or FormatError
// (malformed file, an unsupported glTF feature such as a required extension, sparse
// accessors or a non-triangle primitive), naming the file and the problem.
Scene LoadScene(const std::filesystem::path& path, const SceneLoadOptions& options = {});

struct PlacementOptions {
  // Final height of the object along +Z, metres; <= 0 keeps the file's size (times `scale`).
  double target_height_m = 0.0;
  // Uniform scale applied when target_height_m <= 0 (> 0).
  double scale = 1.0;
  // Rotation about +Z applied before placing, radians (which side faces table angle 0).
  double yaw_rad = 0.0;
  void Validate() const;
};

// What PlaceOnTurntable did: positions_after = transform * (scale * positions_before).
struct Placement {
  double scale = 1.0;
  Rigid3d transform;  // rotation and translation applied after scaling
};
// Scales the scene, centres its bounding box on the turntable axis and sets it on the plate
// (lowest point at z = 0). \throw InvalidArgument for bad options or an empty scene.
Placement PlaceOnTurntable(Scene& scene, const PlacementOptions& options);

}  // namespace carousel::sim
