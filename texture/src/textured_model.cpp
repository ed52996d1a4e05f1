#include "carousel/texture/textured_model.h"

#include <algorithm>
#include <cstring>
#include <limits>

#include <tiny_gltf.h>
#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"

namespace carousel::texture {
namespace {

// A node's local transform (matrix, or translation * rotation * scale).
Eigen::Matrix4d LocalTransform(const tinygltf::Node& node) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  if (node.matrix.size() == 16) {
    for (int i = 0; i < 16; ++i) m(i % 4, i / 4) = node.matrix[i];  // column-major
    return m;
  }
  Eigen::Affine3d t = Eigen::Affine3d::Identity();
  if (node.translation.size() == 3)
    t.translate(Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2]));
  if (node.rotation.size() == 4)  // x, y, z, w
    t.rotate(
        Eigen::Quaterniond(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2])
            .normalized());
  if (node.scale.size() == 3) t.scale(Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2]));
  return t.matrix();
}

class GlbReader {
 public:
  GlbReader(const std::filesystem::path& path, const tinygltf::Model& gltf)
      : path_(path), gltf_(gltf) {}

  TexturedModel Read() {
    // glTF's +Y up onto our +Z up: (x, y, z) -> (x, -z, y).
    Eigen::Matrix4d root = Eigen::Matrix4d::Identity();
    root.block<3, 3>(0, 0) << 1, 0, 0, 0, 0, -1, 0, 1, 0;
    if (gltf_.scenes.empty()) Fail("the file has no scene");
    const int scene = gltf_.defaultScene >= 0 ? gltf_.defaultScene : 0;
    if (scene >= static_cast<int>(gltf_.scenes.size())) Fail("bad default scene index");
    for (const int node : gltf_.scenes[scene].nodes) Visit(node, root, 0);
    if (model_.triangles.empty()) Fail("the scene holds no triangles");
    if (image_ < 0) Fail("unsupported: no base colour texture");
    model_.texture = DecodeImage(gltf_.images[image_]);
    return std::move(model_);
  }

 private:
  [[noreturn]] void Fail(const std::string& what) const { throw FormatError(path_, what); }

  void Visit(int index, const Eigen::Matrix4d& parent, int depth) {
    if (index < 0 || index >= static_cast<int>(gltf_.nodes.size())) Fail("bad node index");
    if (depth > 64) Fail("node hierarchy deeper than 64 levels (a cycle?)");
    const tinygltf::Node& node = gltf_.nodes[index];
    const Eigen::Matrix4d world = parent * LocalTransform(node);
    if (node.mesh >= 0) {
      if (node.mesh >= static_cast<int>(gltf_.meshes.size())) Fail("bad mesh index");
      for (const tinygltf::Primitive& primitive : gltf_.meshes[node.mesh].primitives)
        AddPrimitive(primitive, world);
    }
    for (const int child : node.children) Visit(child, world, depth + 1);
  }

  // The texture of a material (its image index), checking that it is the only one used.
  void UseMaterial(int material_index) {
    if (material_index < 0 || material_index >= static_cast<int>(gltf_.materials.size()))
      Fail("unsupported: a primitive without a material");
    const tinygltf::Material& material = gltf_.materials[material_index];
    const auto& factor = material.pbrMetallicRoughness.baseColorFactor;
    for (std::size_t c = 0; c < std::min<std::size_t>(3, factor.size()); ++c)
      if (factor[c] != 1.0) Fail("unsupported: a baseColorFactor other than white");
    const tinygltf::TextureInfo& info = material.pbrMetallicRoughness.baseColorTexture;
    if (info.index < 0 || info.index >= static_cast<int>(gltf_.textures.size()))
      Fail("unsupported: material '" + material.name + "' has no base colour texture");
    if (info.texCoord != 0) Fail("unsupported: a base colour texture on TEXCOORD_1 or later");
    const tinygltf::Texture& texture = gltf_.textures[info.index];
    if (texture.source < 0 || texture.source >= static_cast<int>(gltf_.images.size()))
      Fail("texture " + std::to_string(info.index) + " has no image");
    if (image_ >= 0 && image_ != texture.source)
      Fail("unsupported: more than one base colour texture");
    image_ = texture.source;
    int wrap_s = TINYGLTF_TEXTURE_WRAP_REPEAT, wrap_t = TINYGLTF_TEXTURE_WRAP_REPEAT;
    if (texture.sampler >= 0) {
      if (texture.sampler >= static_cast<int>(gltf_.samplers.size())) Fail("bad sampler index");
      wrap_s = gltf_.samplers[texture.sampler].wrapS;
      wrap_t = gltf_.samplers[texture.sampler].wrapT;
    }
    if (wrap_s != wrap_t ||
        (wrap_s != TINYGLTF_TEXTURE_WRAP_REPEAT && wrap_s != TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE))
      Fail("unsupported: texture wrap other than clamp-to-edge or repeat on both axes");
    model_.wrap = wrap_s == TINYGLTF_TEXTURE_WRAP_REPEAT ? TexturedModel::Wrap::kRepeat
                                                         : TexturedModel::Wrap::kClampToEdge;
  }

  // An accessor's elements as doubles, `components` per element.
  std::vector<double> ReadAccessor(int index, int components, const std::string& what) const {
    if (index < 0 || index >= static_cast<int>(gltf_.accessors.size()))
      Fail("bad accessor index for " + what);
    const tinygltf::Accessor& accessor = gltf_.accessors[index];
    if (accessor.sparse.isSparse) Fail("unsupported: sparse accessor for " + what);
    if (tinygltf::GetNumComponentsInType(accessor.type) != components)
      Fail(what + " has " + std::to_string(tinygltf::GetNumComponentsInType(accessor.type)) +
           " components, expected " + std::to_string(components));
    if (accessor.bufferView < 0 ||
        accessor.bufferView >= static_cast<int>(gltf_.bufferViews.size()))
      Fail(what + " has no buffer view");
    const tinygltf::BufferView& view = gltf_.bufferViews[accessor.bufferView];
    if (view.buffer < 0 || view.buffer >= static_cast<int>(gltf_.buffers.size()))
      Fail("bad buffer index for " + what);
    const std::vector<unsigned char>& buffer = gltf_.buffers[view.buffer].data;
    const int size = tinygltf::GetComponentSizeInBytes(accessor.componentType);
    if (size <= 0) Fail(what + " has an unknown component type");
    const std::size_t element = static_cast<std::size_t>(size) * components;
    const std::size_t stride = view.byteStride != 0 ? view.byteStride : element;
    // The view inside the buffer, then every element inside the view (no overflow).
    if (view.byteOffset > buffer.size() || view.byteLength > buffer.size() - view.byteOffset ||
        stride < element ||
        (accessor.count > 0 &&
         (accessor.byteOffset > view.byteLength ||
          element > view.byteLength - accessor.byteOffset ||
          accessor.count - 1 > (view.byteLength - accessor.byteOffset - element) / stride)))
      Fail(what + " reaches past the end of its buffer");
    const unsigned char* start = buffer.data() + view.byteOffset + accessor.byteOffset;
    std::vector<double> values(accessor.count * components);
    for (std::size_t i = 0; i < accessor.count; ++i)
      for (int c = 0; c < components; ++c) {
        const unsigned char* p = start + i * stride + static_cast<std::size_t>(c) * size;
        double v = 0.0;
        switch (accessor.componentType) {
          case TINYGLTF_COMPONENT_TYPE_FLOAT: {
            float f;
            std::memcpy(&f, p, sizeof f);
            v = f;
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            v = accessor.normalized ? *p / 255.0 : *p;
            break;
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
            std::uint16_t s;
            std::memcpy(&s, p, sizeof s);
            v = accessor.normalized ? s / 65535.0 : s;
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
            std::uint32_t u;
            std::memcpy(&u, p, sizeof u);
            v = u;
            break;
          }
          default:
            Fail("unsupported: component type " + std::to_string(accessor.componentType) + " for " +
                 what);
        }
        values[i * components + c] = v;
      }
    return values;
  }

  void AddPrimitive(const tinygltf::Primitive& primitive, const Eigen::Matrix4d& world) {
    const int mode = primitive.mode < 0 ? TINYGLTF_MODE_TRIANGLES : primitive.mode;
    if (mode != TINYGLTF_MODE_TRIANGLES)
      Fail("unsupported: primitive mode " + std::to_string(mode) + " (triangles only)");
    if (!primitive.extensions.empty()) Fail("unsupported: a primitive with extensions");
    UseMaterial(primitive.material);
    const auto position = primitive.attributes.find("POSITION");
    const auto uv = primitive.attributes.find("TEXCOORD_0");
    if (position == primitive.attributes.end()) Fail("a primitive has no POSITION");
    if (uv == primitive.attributes.end()) Fail("a primitive has no TEXCOORD_0");
    const std::vector<double> positions = ReadAccessor(position->second, 3, "POSITION");
    const std::vector<double> uvs = ReadAccessor(uv->second, 2, "TEXCOORD_0");
    const std::size_t n = positions.size() / 3;
    if (uvs.size() / 2 != n) Fail("TEXCOORD_0 and POSITION counts differ");
    std::vector<double> indices;
    if (primitive.indices >= 0) {
      indices = ReadAccessor(primitive.indices, 1, "indices");
    } else {
      indices.resize(n);
      for (std::size_t i = 0; i < n; ++i) indices[i] = static_cast<double>(i);
    }
    if (indices.size() % 3 != 0) Fail("the triangle index count is not a multiple of 3");
    const Eigen::Matrix3d linear = world.block<3, 3>(0, 0);
    const Eigen::Vector3d offset = world.block<3, 1>(0, 3);
    const bool mirrored = linear.determinant() < 0;  // flips the winding
    const auto base = static_cast<int>(model_.positions.size());
    for (std::size_t i = 0; i < n; ++i) {
      model_.positions.push_back(
          linear * Eigen::Vector3d(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]) +
          offset);
      model_.uvs.emplace_back(static_cast<float>(uvs[2 * i]), static_cast<float>(uvs[2 * i + 1]));
    }
    for (std::size_t i = 0; i < indices.size(); i += 3) {
      Eigen::Vector3i t;
      for (int k = 0; k < 3; ++k) {
        if (indices[i + k] >= static_cast<double>(n)) Fail("a triangle index is out of range");
        t[k] = base + static_cast<int>(indices[i + k]);
      }
      if (mirrored) std::swap(t[1], t[2]);
      model_.triangles.push_back(t);
    }
  }

  cv::Mat DecodeImage(const tinygltf::Image& image) const {
    if (image.image.empty() || image.width <= 0 || image.height <= 0)
      Fail("the texture could not be decoded");
    if (image.bits != 8) Fail("unsupported: a " + std::to_string(image.bits) + "-bit texture");
    const int channels = image.component;
    if (channels < 1 || channels > 4 ||
        image.image.size() != static_cast<std::size_t>(image.width) * image.height * channels)
      Fail("the texture has an unexpected pixel layout");
    const cv::Mat raw(image.height, image.width, CV_8UC(channels),
                      const_cast<unsigned char*>(image.image.data()));
    cv::Mat bgr;
    if (channels == 1 || channels == 2) {
      cv::Mat grey;
      cv::extractChannel(raw, grey, 0);
      cv::cvtColor(grey, bgr, cv::COLOR_GRAY2BGR);
    } else {
      cv::cvtColor(raw, bgr, channels == 3 ? cv::COLOR_RGB2BGR : cv::COLOR_RGBA2BGR);
    }
    return bgr;
  }

  const std::filesystem::path& path_;
  const tinygltf::Model& gltf_;
  TexturedModel model_;
  int image_ = -1;
};

}  // namespace

void TexturedModel::Validate() const {
  CAROUSEL_THROW_IF(
      uvs.size() != positions.size(), InvalidArgument,
      "TexturedModel: " << positions.size() << " positions but " << uvs.size() << " UVs");
  for (const Eigen::Vector3d& p : positions)
    CAROUSEL_THROW_IF(!p.allFinite(), InvalidArgument, "TexturedModel: a position is not finite");
  for (const Eigen::Vector2f& uv : uvs)
    CAROUSEL_THROW_IF(!uv.allFinite(), InvalidArgument, "TexturedModel: a UV is not finite");
  const auto n = static_cast<int>(positions.size());
  for (const Eigen::Vector3i& t : triangles)
    CAROUSEL_THROW_IF((t.array() < 0).any() || (t.array() >= n).any(), InvalidArgument,
                      "TexturedModel: a triangle index is out of range");
  CAROUSEL_THROW_IF(texture.empty() || texture.type() != CV_8UC3, InvalidArgument,
                    "TexturedModel: the texture must be 8-bit BGR");
}

TexturedModel TexturedModelFromMesh(const Mesh& mesh, const cv::Mat& texture) {
  CAROUSEL_THROW_IF(!mesh.has_uvs(), InvalidArgument, "TexturedModelFromMesh: the mesh has no UVs");
  CAROUSEL_THROW_IF(texture.empty() || texture.type() != CV_8UC3, InvalidArgument,
                    "TexturedModelFromMesh: the texture must be 8-bit BGR");
  TexturedModel model;
  model.texture = texture;
  model.triangles.reserve(mesh.n_faces());
  for (const auto f : mesh.faces()) {
    Eigen::Vector3i t;
    int k = 0;
    for (const auto h : mesh.fh_range(f)) {
      CAROUSEL_THROW_IF(k == 3, InvalidArgument,
                        "TexturedModelFromMesh: face " << f.idx() << " is not a triangle");
      const auto& p = mesh.point(mesh.to_vertex_handle(h));
      const auto uv = mesh.uv(h);
      t[k++] = static_cast<int>(model.positions.size());
      model.positions.emplace_back(p[0], p[1], p[2]);
      model.uvs.emplace_back(static_cast<float>(uv[0]), static_cast<float>(1.0 - uv[1]));
    }
    CAROUSEL_THROW_IF(k != 3, InvalidArgument,
                      "TexturedModelFromMesh: face " << f.idx() << " is not a triangle");
    model.triangles.push_back(t);
  }
  return model;
}

namespace {

TexturedModel CheckedModel(const std::filesystem::path& path, bool ok, const std::string& error_in,
                           const tinygltf::Model& gltf) {
  if (!ok) {
    std::string error = error_in;
    std::replace(error.begin(), error.end(), '\n', ' ');
    throw FormatError(path, error.empty() ? "not a glTF file tinygltf can read" : error);
  }
  if (!gltf.extensionsRequired.empty())
    throw FormatError(path,
                      "unsupported: the file requires extension " + gltf.extensionsRequired[0]);
  TexturedModel model = GlbReader(path, gltf).Read();
  for (const Eigen::Vector3d& p : model.positions)
    if (!p.allFinite()) throw FormatError(path, "a position is not finite");
  for (const Eigen::Vector2f& uv : model.uvs)
    if (!uv.allFinite()) throw FormatError(path, "a texture coordinate is not finite");
  return model;
}

}  // namespace

TexturedModel ReadTexturedModel(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw IoError(path, "no such file");
  tinygltf::TinyGLTF loader;
  tinygltf::Model gltf;
  std::string error, warning;
  const bool binary = path.extension() != ".gltf";
  const bool ok = binary ? loader.LoadBinaryFromFile(&gltf, &error, &warning, path.string())
                         : loader.LoadASCIIFromFile(&gltf, &error, &warning, path.string());
  return CheckedModel(path, ok, error, gltf);
}

TexturedModel ReadTexturedModelFromGlb(const std::vector<unsigned char>& glb,
                                       const std::filesystem::path& name) {
  if (glb.size() > std::numeric_limits<unsigned int>::max())
    throw FormatError(name, "larger than 4 GiB");
  tinygltf::TinyGLTF loader;
  tinygltf::Model gltf;
  std::string error, warning;
  const bool ok = loader.LoadBinaryFromMemory(&gltf, &error, &warning, glb.data(),
                                              static_cast<unsigned int>(glb.size()), "");
  return CheckedModel(name, ok, error, gltf);
}

}  // namespace carousel::texture
