#include "carousel/sim/scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>

#include <tiny_gltf.h>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/text.h"

namespace carousel::sim {
namespace {

std::string Lowercase(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

// ------------------------------------------------------------------------------------------
// glTF 2.0 through tinygltf

// glTF's +Y up onto our +Z up: (x, y, z) -> (x, -z, y).
Eigen::Matrix3d YUpToZUp() {
  Eigen::Matrix3d m;
  m << 1, 0, 0, 0, 0, -1, 0, 1, 0;
  return m;
}

Eigen::Matrix4d NodeMatrix(const tinygltf::Node& node) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  if (node.matrix.size() == 16) {
    for (int c = 0; c < 4; ++c) {
      for (int r = 0; r < 4; ++r) m(r, c) = node.matrix[c * 4 + r];  // column-major
    }
    return m;
  }
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  Eigen::Matrix4d r = Eigen::Matrix4d::Identity();
  Eigen::Matrix4d s = Eigen::Matrix4d::Identity();
  if (node.translation.size() == 3) {
    t.block<3, 1>(0, 3) =
        Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2]);
  }
  if (node.rotation.size() == 4) {  // x, y, z, w
    const Eigen::Quaterniond q(node.rotation[3], node.rotation[0], node.rotation[1],
                               node.rotation[2]);
    r.block<3, 3>(0, 0) = q.normalized().toRotationMatrix();
  }
  if (node.scale.size() == 3) {
    s.diagonal().head<3>() = Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2]);
  }
  return t * r * s;
}

class GltfReader {
 public:
  GltfReader(const std::filesystem::path& path, const tinygltf::Model& model, Scene& scene)
      : path_(path), model_(model), scene_(scene) {}

  // Returns true when some primitive had no normals (the caller recomputes them).
  bool Read(const Eigen::Matrix3d& up_fix) {
    for (const std::string& extension : model_.extensionsRequired) {
      if (extension != "KHR_materials_variants") {
        Fail("unsupported glTF feature: the file requires extension " + extension);
      }
    }
    ReadMaterials();
    Eigen::Matrix4d root = Eigen::Matrix4d::Identity();
    root.block<3, 3>(0, 0) = up_fix;
    if (model_.scenes.empty()) {
      // No scene: every root node counts.
      std::vector<bool> is_child(model_.nodes.size(), false);
      for (const tinygltf::Node& node : model_.nodes) {
        for (int child : node.children) {
          if (child >= 0 && child < static_cast<int>(is_child.size())) is_child[child] = true;
        }
      }
      for (std::size_t i = 0; i < model_.nodes.size(); ++i) {
        if (!is_child[i]) VisitNode(static_cast<int>(i), root, 0);
      }
    } else {
      const int scene_index = model_.defaultScene >= 0 ? model_.defaultScene : 0;
      if (scene_index >= static_cast<int>(model_.scenes.size())) Fail("bad default scene index");
      for (int node : model_.scenes[scene_index].nodes) VisitNode(node, root, 0);
    }
    if (scene_.triangles.empty()) Fail("the scene holds no triangles");
    return needs_normals_;
  }

 private:
  [[noreturn]] void Fail(const std::string& what) const { throw FormatError(path_, what); }

  void ReadMaterials() {
    std::map<int, int> texture_of_image;
    for (const tinygltf::Material& material : model_.materials) {
      Material ours;
      ours.name = material.name;
      ours.double_sided = material.doubleSided;
      const auto& factor = material.pbrMetallicRoughness.baseColorFactor;
      if (factor.size() >= 3) {
        ours.base_color =
            Eigen::Vector3f(static_cast<float>(factor[0]), static_cast<float>(factor[1]),
                            static_cast<float>(factor[2]));
      }
      const tinygltf::TextureInfo& info = material.pbrMetallicRoughness.baseColorTexture;
      if (info.index >= 0) {
        if (info.texCoord != 0) {
          Fail("unsupported glTF feature: material '" + material.name + "' uses TEXCOORD_" +
               std::to_string(info.texCoord) + " for its base colour");
        }
        if (info.index >= static_cast<int>(model_.textures.size())) Fail("bad texture index");
        const int image = model_.textures[info.index].source;
        if (image < 0 || image >= static_cast<int>(model_.images.size())) {
          Fail("texture " + std::to_string(info.index) + " has no image");
        }
        auto found = texture_of_image.find(image);
        if (found == texture_of_image.end()) {
          found = texture_of_image.emplace(image, static_cast<int>(scene_.textures.size())).first;
          scene_.textures.push_back(std::make_shared<const Texture>(DecodeImage(image)));
        }
        ours.texture = found->second;
      }
      scene_.materials.push_back(ours);
    }
    default_material_ = static_cast<int>(scene_.materials.size());
    scene_.materials.push_back(Material{"default", {0.8f, 0.8f, 0.8f}, -1, true});
  }

  cv::Mat DecodeImage(int index) const {
    const tinygltf::Image& image = model_.images[index];
    const std::string name = image.uri.empty() ? "image " + std::to_string(index) : image.uri;
    if (image.image.empty() || image.width <= 0 || image.height <= 0) {
      Fail("texture " + name + " could not be decoded");
    }
    if (image.bits != 8) {
      Fail("unsupported glTF feature: " + std::to_string(image.bits) + "-bit texture " + name);
    }
    const int channels = image.component;
    if (channels < 1 || channels > 4 ||
        image.image.size() != static_cast<std::size_t>(image.width) * image.height * channels) {
      Fail("texture " + name + " has an unexpected pixel layout");
    }
    const cv::Mat raw(image.height, image.width, CV_8UC(channels),
                      const_cast<unsigned char*>(image.image.data()));
    cv::Mat bgr;
    switch (channels) {
      case 1:
        cv::cvtColor(raw, bgr, cv::COLOR_GRAY2BGR);
        break;
      case 2: {
        std::vector<cv::Mat> planes;
        cv::split(raw, planes);
        cv::cvtColor(planes[0], bgr, cv::COLOR_GRAY2BGR);
        break;
      }
      case 3:
        cv::cvtColor(raw, bgr, cv::COLOR_RGB2BGR);
        break;
      default:
        cv::cvtColor(raw, bgr, cv::COLOR_RGBA2BGR);
        break;
    }
    return bgr;
  }

  void VisitNode(int index, const Eigen::Matrix4d& parent, int depth) {
    if (index < 0 || index >= static_cast<int>(model_.nodes.size())) Fail("bad node index");
    if (depth > 64) Fail("node hierarchy deeper than 64 levels (a cycle?)");
    const tinygltf::Node& node = model_.nodes[index];
    const Eigen::Matrix4d world = parent * NodeMatrix(node);
    if (node.mesh >= 0) {
      if (node.mesh >= static_cast<int>(model_.meshes.size())) Fail("bad mesh index");
      for (const tinygltf::Primitive& primitive : model_.meshes[node.mesh].primitives) {
        AddPrimitive(primitive, world);
      }
    }
    for (int child : node.children) VisitNode(child, world, depth + 1);
  }

  // Reads an accessor as doubles, `components` per element, honouring stride and type.
  std::vector<double> ReadAccessor(int index, int components, const char* what) const {
    if (index < 0 || index >= static_cast<int>(model_.accessors.size())) {
      Fail(std::string("bad accessor index for ") + what);
    }
    const tinygltf::Accessor& accessor = model_.accessors[index];
    if (accessor.sparse.isSparse) {
      Fail(std::string("unsupported glTF feature: sparse accessor for ") + what);
    }
    const int count_per_element = tinygltf::GetNumComponentsInType(accessor.type);
    if (count_per_element != components) {
      Fail(std::string(what) + " accessor has " + std::to_string(count_per_element) +
           " components, expected " + std::to_string(components));
    }
    if (accessor.bufferView < 0 ||
        accessor.bufferView >= static_cast<int>(model_.bufferViews.size())) {
      Fail(std::string(what) + " accessor has no buffer view");
    }
    const tinygltf::BufferView& view = model_.bufferViews[accessor.bufferView];
    if (view.buffer < 0 || view.buffer >= static_cast<int>(model_.buffers.size())) {
      Fail("bad buffer index");
    }
    const std::vector<unsigned char>& buffer = model_.buffers[view.buffer].data;
    const int component_size = tinygltf::GetComponentSizeInBytes(accessor.componentType);
    if (component_size <= 0) Fail(std::string(what) + " accessor has an unknown component type");
    const std::size_t element_size = static_cast<std::size_t>(component_size) * components;
    const std::size_t stride = view.byteStride != 0 ? view.byteStride : element_size;
    // Bounds in an order that cannot overflow: the view inside the buffer, the accessor's
    // first element inside the view, and the number of further elements that fit.
    const auto past_end = [&] {
      Fail(std::string(what) + " accessor reaches past the end of its buffer (truncated .bin?)");
    };
    if (view.byteOffset > buffer.size() || view.byteLength > buffer.size() - view.byteOffset) {
      past_end();
    }
    if (stride < element_size || accessor.byteOffset > view.byteLength ||
        element_size > view.byteLength - accessor.byteOffset) {
      if (accessor.count > 0) past_end();
    }
    if (accessor.count > 0 &&
        accessor.count - 1 > (view.byteLength - accessor.byteOffset - element_size) / stride) {
      past_end();
    }
    const std::size_t start = view.byteOffset + accessor.byteOffset;
    std::vector<double> values(accessor.count * components);
    for (std::size_t i = 0; i < accessor.count; ++i) {
      const unsigned char* element = buffer.data() + start + i * stride;
      for (int c = 0; c < components; ++c) {
        const unsigned char* p = element + c * component_size;
        double v = 0.0;
        switch (accessor.componentType) {
          case TINYGLTF_COMPONENT_TYPE_FLOAT: {
            float f;
            std::memcpy(&f, p, 4);
            v = f;
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            v = *p;
            if (accessor.normalized) v /= 255.0;
            break;
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
            std::uint16_t s;
            std::memcpy(&s, p, 2);
            v = accessor.normalized ? s / 65535.0 : s;
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
            std::uint32_t u;
            std::memcpy(&u, p, 4);
            v = u;
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_BYTE: {
            const auto b = static_cast<std::int8_t>(*p);
            v = accessor.normalized ? std::max(b / 127.0, -1.0) : b;
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_SHORT: {
            std::int16_t s;
            std::memcpy(&s, p, 2);
            v = accessor.normalized ? std::max(s / 32767.0, -1.0) : s;
            break;
          }
          default:
            Fail(std::string(what) + " accessor has an unsupported component type");
        }
        values[i * components + c] = v;
      }
    }
    return values;
  }

  void AddPrimitive(const tinygltf::Primitive& primitive, const Eigen::Matrix4d& world) {
    const int mode = primitive.mode < 0 ? TINYGLTF_MODE_TRIANGLES : primitive.mode;
    if (mode == TINYGLTF_MODE_POINTS || mode == TINYGLTF_MODE_LINE ||
        mode == TINYGLTF_MODE_LINE_LOOP || mode == TINYGLTF_MODE_LINE_STRIP) {
      CAROUSEL_LOG_WARN(path_.string() << ": skipping a point/line primitive");
      return;
    }
    if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
        mode != TINYGLTF_MODE_TRIANGLE_FAN) {
      Fail("unsupported glTF feature: primitive mode " + std::to_string(mode));
    }
    if (primitive.extensions.count("KHR_draco_mesh_compression")) {
      Fail("unsupported glTF feature: Draco-compressed mesh");
    }
    const auto position = primitive.attributes.find("POSITION");
    if (position == primitive.attributes.end()) Fail("a primitive has no POSITION attribute");
    const std::vector<double> positions = ReadAccessor(position->second, 3, "POSITION");
    const std::size_t n = positions.size() / 3;
    std::vector<double> normals;
    if (auto it = primitive.attributes.find("NORMAL"); it != primitive.attributes.end()) {
      normals = ReadAccessor(it->second, 3, "NORMAL");
      if (normals.size() != positions.size()) Fail("NORMAL and POSITION counts differ");
    }
    std::vector<double> uvs;
    if (auto it = primitive.attributes.find("TEXCOORD_0"); it != primitive.attributes.end()) {
      uvs = ReadAccessor(it->second, 2, "TEXCOORD_0");
      if (uvs.size() / 2 != n) Fail("TEXCOORD_0 and POSITION counts differ");
    }
    std::vector<std::size_t> indices;
    if (primitive.indices >= 0) {
      for (double value : ReadAccessor(primitive.indices, 1, "indices")) {
        indices.push_back(static_cast<std::size_t>(value));
      }
    } else {
      indices.resize(n);
      for (std::size_t i = 0; i < n; ++i) indices[i] = i;
    }
    const Eigen::Matrix3d linear = world.block<3, 3>(0, 0);
    const Eigen::Vector3d offset = world.block<3, 1>(0, 3);
    const Eigen::Matrix3d normal_matrix = linear.inverse().transpose();
    const bool mirrored = linear.determinant() < 0;  // flips the winding
    const int base = static_cast<int>(scene_.positions.size());
    for (std::size_t i = 0; i < n; ++i) {
      scene_.positions.push_back(
          linear * Eigen::Vector3d(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]) +
          offset);
      Eigen::Vector3f normal = Eigen::Vector3f::Zero();
      if (!normals.empty()) {
        normal = (normal_matrix *
                  Eigen::Vector3d(normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]))
                     .normalized()
                     .cast<float>();
      }
      scene_.normals.push_back(normal);
      scene_.uvs.push_back(uvs.empty() ? Eigen::Vector2f::Zero()
                                       : Eigen::Vector2f(static_cast<float>(uvs[2 * i]),
                                                         static_cast<float>(uvs[2 * i + 1])));
    }
    if (normals.empty()) needs_normals_ = true;
    int material = primitive.material;
    if (material < 0 || material >= default_material_) material = default_material_;
    auto add = [&](std::size_t a, std::size_t b, std::size_t c) {
      if (a >= n || b >= n || c >= n) Fail("a triangle index is out of range");
      if (a == b || b == c || a == c) return;  // degenerate
      Eigen::Vector3i triangle(base + static_cast<int>(a), base + static_cast<int>(b),
                               base + static_cast<int>(c));
      if (mirrored) std::swap(triangle[1], triangle[2]);
      scene_.triangles.push_back(triangle);
      scene_.triangle_material.push_back(material);
    };
    if (mode == TINYGLTF_MODE_TRIANGLES) {
      if (indices.size() % 3 != 0) Fail("triangle index count is not a multiple of 3");
      for (std::size_t i = 0; i + 2 < indices.size(); i += 3) {
        add(indices[i], indices[i + 1], indices[i + 2]);
      }
    } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
      for (std::size_t i = 0; i + 2 < indices.size(); ++i) {
        if (i % 2 == 0) {
          add(indices[i], indices[i + 1], indices[i + 2]);
        } else {
          add(indices[i + 1], indices[i], indices[i + 2]);
        }
      }
    } else {
      for (std::size_t i = 1; i + 1 < indices.size(); ++i) {
        add(indices[0], indices[i], indices[i + 1]);
      }
    }
  }

  const std::filesystem::path& path_;
  const tinygltf::Model& model_;
  Scene& scene_;
  int default_material_ = 0;
  bool needs_normals_ = false;
};

[[noreturn]] void ThrowMissingReference(const std::filesystem::path& path,
                                        const tinygltf::Model& model, const std::string& error) {
  // A missing buffer or texture is an I/O problem of that file; say which.
  for (const tinygltf::Image& image : model.images) {
    if (!image.uri.empty() && image.uri.rfind("data:", 0) != 0 &&
        !std::filesystem::exists(path.parent_path() / image.uri)) {
      throw IoError(path.parent_path() / image.uri,
                    "texture referenced by " + path.filename().string() + " is missing");
    }
  }
  for (const tinygltf::Buffer& buffer : model.buffers) {
    if (!buffer.uri.empty() && buffer.uri.rfind("data:", 0) != 0 &&
        !std::filesystem::exists(path.parent_path() / buffer.uri)) {
      throw IoError(path.parent_path() / buffer.uri,
                    "buffer referenced by " + path.filename().string() + " is missing");
    }
  }
  throw FormatError(path, error);
}

Scene LoadGltf(const std::filesystem::path& path, bool binary, const Eigen::Matrix3d& up_fix) {
  tinygltf::TinyGLTF loader;
  tinygltf::Model model;
  std::string error, warning;
  const bool ok = binary ? loader.LoadBinaryFromFile(&model, &error, &warning, path.string())
                         : loader.LoadASCIIFromFile(&model, &error, &warning, path.string());
  if (!ok) {
    if (error.empty()) error = "tinygltf could not parse it";
    std::replace(error.begin(), error.end(), '\n', ' ');
    ThrowMissingReference(path, model, error);
  }
  if (!warning.empty()) CAROUSEL_LOG_DEBUG(path.string() << ": tinygltf: " << warning);
  Scene scene;
  scene.source = path.string();
  GltfReader reader(path, model, scene);
  if (reader.Read(up_fix)) scene.RecomputeNormals();
  return scene;
}

// ------------------------------------------------------------------------------------------
// OBJ + MTL

struct ObjMaterialFile {
  std::map<std::string, Material> materials;
  std::map<std::string, std::filesystem::path> texture_paths;
};

ObjMaterialFile ReadMtl(const std::filesystem::path& path) {
  ObjMaterialFile file;
  const std::vector<std::string> lines = ReadTextLines(path);
  Material* current = nullptr;
  std::string current_name;
  for (std::size_t number = 0; number < lines.size(); ++number) {
    const std::vector<std::string> t = SplitWords(lines[number]);
    if (t.empty() || t[0][0] == '#') continue;
    const std::string where = "line " + std::to_string(number + 1) + ": ";
    try {
      if (t[0] == "newmtl") {
        if (t.size() < 2) throw FormatError(path, where + "newmtl without a name");
        current_name = t[1];
        current = &file.materials[current_name];
        current->name = current_name;
      } else if (current == nullptr) {
        continue;
      } else if (t[0] == "Kd" && t.size() >= 4) {
        current->base_color = Eigen::Vector3f(std::stof(t[1]), std::stof(t[2]), std::stof(t[3]));
      } else if (t[0] == "map_Kd" && t.size() >= 2) {
        file.texture_paths[current_name] = path.parent_path() / t.back();  // options precede it
      }
    } catch (const std::logic_error&) {
      throw FormatError(path, where + "a number could not be read");
    }
  }
  return file;
}

class ObjReader {
 public:
  ObjReader(const std::filesystem::path& path, const Eigen::Matrix3d& up_fix)
      : path_(path), up_fix_(up_fix) {
    scene_.source = path.string();
  }

  Scene Read() {
    const std::vector<std::string> lines = ReadTextLines(path_);
    if (lines.empty()) throw FormatError(path_, "file is empty");
    for (std::size_t number = 0; number < lines.size(); ++number) {
      const std::vector<std::string> t = SplitWords(lines[number]);
      if (t.empty() || t[0][0] == '#') continue;
      where_ = "line " + std::to_string(number + 1) + ": ";
      try {
        ReadLine(t);
      } catch (const std::invalid_argument&) {
        throw FormatError(path_, where_ + "a number could not be read");
      } catch (const std::out_of_range&) {
        throw FormatError(path_, where_ + "a number is out of range");
      }
    }
    if (scene_.triangles.empty()) throw FormatError(path_, "no faces");
    const bool missing_normals =
        std::any_of(scene_.normals.begin(), scene_.normals.end(),
                    [](const Eigen::Vector3f& n) { return n.squaredNorm() == 0.0f; });
    if (missing_normals) scene_.RecomputeNormals();
    return std::move(scene_);
  }

 private:
  void ReadLine(const std::vector<std::string>& t) {
    if (t[0] == "v") {
      if (t.size() < 4) throw FormatError(path_, where_ + "vertex needs 3 coordinates");
      const Eigen::Vector3d p(std::stod(t[1]), std::stod(t[2]), std::stod(t[3]));
      if (!p.allFinite()) throw FormatError(path_, where_ + "vertex is not finite");
      v_.push_back(up_fix_ * p);
    } else if (t[0] == "vt") {
      if (t.size() < 3) throw FormatError(path_, where_ + "texture coordinate needs u and v");
      vt_.emplace_back(std::stof(t[1]), 1.0f - std::stof(t[2]));  // to image convention
    } else if (t[0] == "vn") {
      if (t.size() < 4) throw FormatError(path_, where_ + "normal needs 3 components");
      vn_.push_back((up_fix_ * Eigen::Vector3d(std::stod(t[1]), std::stod(t[2]), std::stod(t[3])))
                        .normalized()
                        .cast<float>());
    } else if (t[0] == "mtllib" && t.size() >= 2) {
      const std::filesystem::path mtl_path = path_.parent_path() / t[1];
      if (!std::filesystem::exists(mtl_path)) {
        throw IoError(mtl_path, "material library of " + path_.filename().string() + " is missing");
      }
      mtl_ = ReadMtl(mtl_path);
    } else if (t[0] == "usemtl" && t.size() >= 2) {
      current_material_ = MaterialFor(t[1]);
    } else if (t[0] == "f") {
      ReadFace(t);
    }
  }

  int MaterialFor(const std::string& name) {
    if (auto it = material_index_.find(name); it != material_index_.end()) return it->second;
    Material material;
    material.name = name;
    if (auto it = mtl_.materials.find(name); it != mtl_.materials.end()) material = it->second;
    if (auto tp = mtl_.texture_paths.find(name); tp != mtl_.texture_paths.end()) {
      auto [it, inserted] = texture_index_.try_emplace(tp->second, 0);
      if (inserted) {
        if (!std::filesystem::exists(tp->second)) {
          throw IoError(tp->second, "texture of material '" + name + "' (" +
                                        path_.filename().string() + ") is missing");
        }
        it->second = static_cast<int>(scene_.textures.size());
        scene_.textures.push_back(std::make_shared<const Texture>(ReadImage(tp->second)));
      }
      material.texture = it->second;
    }
    const int index = static_cast<int>(scene_.materials.size());
    scene_.materials.push_back(material);
    material_index_[name] = index;
    return index;
  }

  int Resolve(int index, std::size_t count, const char* kind) const {
    const long resolved = index < 0 ? static_cast<long>(count) + index : index - 1L;
    if (index == 0 || resolved < 0 || resolved >= static_cast<long>(count)) {
      throw FormatError(path_, where_ + "face refers to " + kind + " " + std::to_string(index) +
                                   " but " + std::to_string(count) + " are defined");
    }
    return static_cast<int>(resolved);
  }

  void ReadFace(const std::vector<std::string>& t) {
    if (t.size() < 4) throw FormatError(path_, where_ + "face needs at least 3 vertices");
    if (current_material_ < 0) current_material_ = MaterialFor("default");
    std::vector<int> corners;
    for (std::size_t k = 1; k < t.size(); ++k) {
      // v, v/vt, v//vn or v/vt/vn; 0 = absent.
      std::array<int, 3> ref = {0, 0, 0};
      std::size_t field = 0, start = 0;
      const std::string& token = t[k];
      for (std::size_t i = 0; i <= token.size(); ++i) {
        if (i == token.size() || token[i] == '/') {
          if (i > start && field < 3) ref[field] = std::stoi(token.substr(start, i - start));
          ++field;
          start = i + 1;
        }
      }
      ref[0] = Resolve(ref[0], v_.size(), "vertex");
      ref[1] = ref[1] == 0 ? -1 : Resolve(ref[1], vt_.size(), "texture coordinate");
      ref[2] = ref[2] == 0 ? -1 : Resolve(ref[2], vn_.size(), "normal");
      auto [it, inserted] =
          corner_vertex_.try_emplace(ref, static_cast<int>(scene_.positions.size()));
      if (inserted) {
        scene_.positions.push_back(v_[ref[0]]);
        scene_.uvs.push_back(ref[1] >= 0 ? vt_[ref[1]] : Eigen::Vector2f::Zero());
        scene_.normals.push_back(ref[2] >= 0 ? vn_[ref[2]] : Eigen::Vector3f::Zero());
      }
      corners.push_back(it->second);
    }
    for (std::size_t k = 1; k + 1 < corners.size(); ++k) {
      if (corners[0] == corners[k] || corners[k] == corners[k + 1]) continue;
      scene_.triangles.emplace_back(corners[0], corners[k], corners[k + 1]);
      scene_.triangle_material.push_back(current_material_);
    }
  }

  const std::filesystem::path& path_;
  Eigen::Matrix3d up_fix_;
  Scene scene_;
  std::string where_;
  std::vector<Eigen::Vector3d> v_;
  std::vector<Eigen::Vector2f> vt_;
  std::vector<Eigen::Vector3f> vn_;
  ObjMaterialFile mtl_;
  std::map<std::string, int> material_index_;
  std::map<std::filesystem::path, int> texture_index_;
  int current_material_ = -1;
  // Vertices are unique per (v, vt, vn) triple, like glTF's.
  std::map<std::array<int, 3>, int> corner_vertex_;
};

}  // namespace

Texture::Texture(const cv::Mat& image) {
  CAROUSEL_THROW_IF(image.empty() || image.depth() != CV_8U, InvalidArgument,
                    "Texture: needs a non-empty 8-bit image");
  cv::Mat level;
  if (image.channels() == 3) {
    level = image.clone();
  } else if (image.channels() == 1) {
    cv::cvtColor(image, level, cv::COLOR_GRAY2BGR);
  } else if (image.channels() == 4) {
    cv::cvtColor(image, level, cv::COLOR_BGRA2BGR);
  } else {
    throw InvalidArgument("Texture: needs 1, 3 or 4 channels");
  }
  levels_.push_back(level);
  while (level.cols > 1 || level.rows > 1) {
    cv::Mat next;
    cv::resize(level, next, cv::Size(std::max(1, level.cols / 2), std::max(1, level.rows / 2)), 0,
               0, cv::INTER_AREA);
    levels_.push_back(next);
    level = next;
  }
}

Eigen::AlignedBox3d Scene::Bounds() const {
  Eigen::AlignedBox3d box;
  for (const Eigen::Vector3d& p : positions) box.extend(p);
  return box;
}

void Scene::Transform(const Rigid3d& transform, double scale) {
  for (Eigen::Vector3d& p : positions) p = transform * (scale * p);
  const Eigen::Matrix3f rotation = transform.rotation.cast<float>();
  for (Eigen::Vector3f& n : normals) n = rotation * n;
}

void Scene::RecomputeNormals() {
  normals.assign(positions.size(), Eigen::Vector3f::Zero());
  for (const Eigen::Vector3i& t : triangles) {
    const Eigen::Vector3d n =
        (positions[t[1]] - positions[t[0]]).cross(positions[t[2]] - positions[t[0]]);
    for (int k = 0; k < 3; ++k) normals[t[k]] += n.cast<float>();
  }
  for (Eigen::Vector3f& n : normals) {
    const float length = n.norm();
    n = length > 0 ? Eigen::Vector3f(n / length) : Eigen::Vector3f::UnitZ();
  }
}

Mesh Scene::ToMesh() const {
  Mesh mesh;
  std::map<std::array<double, 3>, Mesh::VertexHandle> welded;
  std::vector<Mesh::VertexHandle> handle(positions.size());
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const Eigen::Vector3d& p = positions[i];
    auto [it, inserted] = welded.try_emplace({p.x(), p.y(), p.z()});
    if (inserted) it->second = mesh.add_vertex({p.x(), p.y(), p.z()});
    handle[i] = it->second;
  }
  for (const Eigen::Vector3i& t : triangles) {
    const Mesh::VertexHandle a = handle[t[0]], b = handle[t[1]], c = handle[t[2]];
    if (a == b || b == c || a == c) continue;
    if (!mesh.add_face(a, b, c).is_valid()) {
      // Non-manifold in the welded mesh: keep the triangle with its own vertices.
      const Mesh::VertexHandle a2 = mesh.add_vertex(mesh.point(a));
      const Mesh::VertexHandle b2 = mesh.add_vertex(mesh.point(b));
      const Mesh::VertexHandle c2 = mesh.add_vertex(mesh.point(c));
      mesh.add_face(a2, b2, c2);
    }
  }
  mesh.RecomputeNormals();
  return mesh;
}

void Scene::Validate() const {
  const std::size_t n = positions.size();
  CAROUSEL_THROW_IF(normals.size() != n || uvs.size() != n, InvalidArgument,
                    "Scene " << source << ": per-vertex arrays differ in size");
  CAROUSEL_THROW_IF(triangle_material.size() != triangles.size(), InvalidArgument,
                    "Scene " << source << ": triangle_material size differs from triangles");
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      CAROUSEL_THROW_IF(triangles[i][k] < 0 || triangles[i][k] >= static_cast<int>(n),
                        InvalidArgument,
                        "Scene " << source << ": triangle " << i << " index out of range");
    }
    CAROUSEL_THROW_IF(
        triangle_material[i] < 0 || triangle_material[i] >= static_cast<int>(materials.size()),
        InvalidArgument, "Scene " << source << ": bad material of triangle " << i);
  }
  for (const Material& material : materials) {
    CAROUSEL_THROW_IF(
        material.texture >= static_cast<int>(textures.size()), InvalidArgument,
        "Scene " << source << ": material " << material.name << " has a bad texture index");
  }
  for (std::size_t i = 0; i < n; ++i) {
    CAROUSEL_THROW_IF(!positions[i].allFinite() || !normals[i].allFinite() || !uvs[i].allFinite(),
                      InvalidArgument,
                      "Scene " << source << ": vertex " << i << " has a non-finite position, "
                               << "normal or texture coordinate");
  }
  for (const Material& material : materials) {
    CAROUSEL_THROW_IF(
        !material.base_color.allFinite(), InvalidArgument,
        "Scene " << source << ": material " << material.name << " has a non-finite colour");
  }
}

Scene LoadScene(const std::filesystem::path& path, const SceneLoadOptions& options) {
  RequireReadableFile(path);
  const Eigen::Matrix3d up_fix =
      options.up_axis == SceneLoadOptions::UpAxis::kY ? YUpToZUp() : Eigen::Matrix3d::Identity();
  const std::string extension = Lowercase(path.extension().string());
  Scene scene;
  if (extension == ".gltf") {
    scene = LoadGltf(path, false, up_fix);
  } else if (extension == ".glb") {
    scene = LoadGltf(path, true, up_fix);
  } else if (extension == ".obj") {
    scene = ObjReader(path, up_fix).Read();
  } else {
    throw FormatError(
        path, "unsupported scene format '" + extension + "' (expected .gltf, .glb or .obj)");
  }
  scene.Validate();
  return scene;
}

void PlacementOptions::Validate() const {
  CAROUSEL_THROW_IF(!std::isfinite(target_height_m), InvalidArgument,
                    "PlacementOptions.target_height_m must be finite");
  CAROUSEL_THROW_IF(!(scale > 0 && std::isfinite(scale)), InvalidArgument,
                    "PlacementOptions.scale must be > 0, got " << scale);
  CAROUSEL_THROW_IF(!std::isfinite(yaw_rad), InvalidArgument,
                    "PlacementOptions.yaw_rad must be finite");
}

Placement PlaceOnTurntable(Scene& scene, const PlacementOptions& options) {
  options.Validate();
  CAROUSEL_THROW_IF(scene.positions.empty(), InvalidArgument,
                    "PlaceOnTurntable: scene " << scene.source << " is empty");
  Placement placement;
  const Rigid3d yaw = Rigid3d::RotationZ(options.yaw_rad);
  scene.Transform(yaw);
  const Eigen::AlignedBox3d before = scene.Bounds();
  const double height = before.sizes().z();
  if (options.target_height_m > 0) {
    CAROUSEL_THROW_IF(height <= 0, InvalidArgument,
                      "PlaceOnTurntable: scene " << scene.source << " has no height");
    placement.scale = options.target_height_m / height;
  } else {
    placement.scale = options.scale;
  }
  const Eigen::Vector3d centre = before.center() * placement.scale;
  const Eigen::Vector3d offset(-centre.x(), -centre.y(), -before.min().z() * placement.scale);
  scene.Transform(Rigid3d(Eigen::Matrix3d::Identity(), offset), placement.scale);
  placement.transform = Rigid3d(yaw.rotation, offset);
  return placement;
}

MaterialOverride ParseMaterialOverride(const std::string& name) {
  if (name == "none") return MaterialOverride::kNone;
  if (name == "white") return MaterialOverride::kWhite;
  if (name == "black") return MaterialOverride::kBlack;
  if (name == "glossy") return MaterialOverride::kGlossy;
  if (name == "see-through") return MaterialOverride::kSeeThrough;
  throw InvalidArgument("unknown material '" + name +
                        "' (expected none, white, black, glossy or see-through)");
}

const char* MaterialOverrideName(MaterialOverride material) {
  switch (material) {
    case MaterialOverride::kWhite:
      return "white";
    case MaterialOverride::kBlack:
      return "black";
    case MaterialOverride::kGlossy:
      return "glossy";
    case MaterialOverride::kSeeThrough:
      return "see-through";
    case MaterialOverride::kNone:
      break;
  }
  return "none";
}

void Scene::OverrideMaterials(MaterialOverride material) {
  for (Material& m : materials) {
    switch (material) {
      case MaterialOverride::kWhite:
        m.base_color = Eigen::Vector3f::Constant(0.9f);
        m.texture = -1;
        break;
      case MaterialOverride::kBlack:
        m.base_color = Eigen::Vector3f::Constant(0.03f);
        m.texture = -1;
        break;
      case MaterialOverride::kGlossy:
        m.specular = 0.8f;
        m.shininess = 80.0f;
        break;
      case MaterialOverride::kSeeThrough:
        m.base_color = Eigen::Vector3f(0.88f, 0.95f, 0.9f);
        m.texture = -1;
        m.transmission = 0.85f;
        m.specular = 0.8f;
        m.shininess = 120.0f;
        break;
      case MaterialOverride::kNone:
        break;
    }
  }
}

}  // namespace carousel::sim
