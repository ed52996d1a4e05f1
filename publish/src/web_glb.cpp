#include "carousel/publish/web_glb.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>

#include <meshoptimizer.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/texture/atlas_size.h"

namespace carousel::publish {
namespace {

using Json = nlohmann::ordered_json;
using Bytes = std::vector<unsigned char>;

constexpr std::uint32_t kGlbMagic = 0x46546C67;   // "glTF"
constexpr std::uint32_t kJsonChunk = 0x4E4F534A;  // "JSON"
constexpr std::uint32_t kBinChunk = 0x004E4942;   // "BIN\0"
constexpr const char* kMeshopt = "EXT_meshopt_compression";
constexpr const char* kUnlit = "KHR_materials_unlit";

void Align4(Bytes* bytes, unsigned char fill = 0) {
  while (bytes->size() % 4 != 0) bytes->push_back(fill);
}

void AppendU32(Bytes* bytes, std::uint32_t value) {
  for (int k = 0; k < 4; ++k) bytes->push_back(static_cast<unsigned char>(value >> (8 * k)));
}

std::uint32_t LoadU32(const unsigned char* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}

template <typename T>
void AppendRaw(Bytes* bytes, const std::vector<T>& data) {
  const auto* p = reinterpret_cast<const unsigned char*>(data.data());
  bytes->insert(bytes->end(), p, p + data.size() * sizeof(T));
}

Bytes AssembleGlb(const Json& json, const Bytes& bin) {
  std::string text = json.dump();
  while (text.size() % 4 != 0) text.push_back(' ');
  Bytes padded_bin = bin;
  Align4(&padded_bin);
  const std::size_t total = 12 + 8 + text.size() + (padded_bin.empty() ? 0 : 8 + padded_bin.size());
  CAROUSEL_THROW_IF(total > std::numeric_limits<std::uint32_t>::max(), InvalidArgument,
                    "web GLB: larger than 4 GiB");
  Bytes out;
  out.reserve(total);
  AppendU32(&out, kGlbMagic);
  AppendU32(&out, 2);
  AppendU32(&out, static_cast<std::uint32_t>(total));
  AppendU32(&out, static_cast<std::uint32_t>(text.size()));
  AppendU32(&out, kJsonChunk);
  out.insert(out.end(), text.begin(), text.end());
  if (!padded_bin.empty()) {
    AppendU32(&out, static_cast<std::uint32_t>(padded_bin.size()));
    AppendU32(&out, kBinChunk);
    out.insert(out.end(), padded_bin.begin(), padded_bin.end());
  }
  return out;
}

// One stream of the geometry: its raw bytes and how the glTF bufferView describes it.
struct Stream {
  Bytes raw;
  std::size_t count = 0;   // elements
  std::size_t stride = 0;  // bytes per element
  bool indices = false;
  int target = 0;
};

Bytes Compress(const Stream& s) {
  Bytes out;
  if (s.indices) {
    // meshopt's index codec takes 32-bit indices whatever the stored width.
    std::vector<std::uint32_t> wide(s.count);
    for (std::size_t i = 0; i < s.count; ++i) {
      if (s.stride == 2) {
        std::uint16_t v = 0;
        std::memcpy(&v, s.raw.data() + 2 * i, 2);
        wide[i] = v;
      } else {
        std::memcpy(&wide[i], s.raw.data() + 4 * i, 4);
      }
    }
    std::size_t vertices = 0;
    for (const std::uint32_t v : wide) vertices = std::max<std::size_t>(vertices, v + 1);
    out.resize(meshopt_encodeIndexBufferBound(s.count, vertices));
    out.resize(meshopt_encodeIndexBuffer(out.data(), out.size(), wide.data(), s.count));
  } else {
    out.resize(meshopt_encodeVertexBufferBound(s.count, s.stride));
    out.resize(meshopt_encodeVertexBuffer(out.data(), out.size(), s.raw.data(), s.count, s.stride));
  }
  CAROUSEL_CHECK(!out.empty(), "meshopt encoding produced nothing");
  return out;
}

cv::Mat WebTexture(const cv::Mat& texture, int side) {
  if (texture.cols == side && texture.rows == side) return texture;
  cv::Mat out;
  const bool shrinks = side < texture.cols || side < texture.rows;
  cv::resize(texture, out, cv::Size(side, side), 0, 0, shrinks ? cv::INTER_AREA : cv::INTER_CUBIC);
  return out;
}

}  // namespace

const OptionTable<WebGlbOptions>& WebGlbOptions::Fields() {
  using O = WebGlbOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::max_texture_size, {.name = "web-texture-size",
                                 .help = "largest texture side of the web GLB (a power of two)",
                                 .unit = "texels",
                                 .min = 64,
                                 .max = 16384});
    t.Add(&O::jpeg_quality, {.name = "web-jpeg-quality",
                             .help = "JPEG quality of the web GLB's texture",
                             .min = 1,
                             .max = 100});
    t.Add(&O::unlit, {.name = "web-unlit",
                      .help = "the web GLB's material unlit (the photos' own light); off: PBR",
                      .negative_name = "web-lit"});
    t.Add(&O::compress, {.name = "web-meshopt",
                         .help = "compress the web GLB's geometry (EXT_meshopt_compression)",
                         .advanced = true});
    return t;
  }();
  return table;
}

void WebGlbOptions::Validate() const {
  Fields().Check(*this);
  CAROUSEL_THROW_IF((max_texture_size & (max_texture_size - 1)) != 0, InvalidArgument,
                    "--web-texture-size must be a power of two, got " << max_texture_size);
}

int WebTextureSize(int atlas_side, int max_texture_size) {
  int side = 64;
  while (side < atlas_side && side < max_texture_size) side *= 2;
  return std::min(side, max_texture_size);
}

std::vector<unsigned char> EncodeWebGlb(const texture::TexturedModel& model,
                                        const WebGlbOptions& options, WebGlbResult* result) {
  options.Validate();
  model.Validate();
  CAROUSEL_THROW_IF(model.triangles.empty(), InvalidArgument, "web GLB: the model has no faces");
  CAROUSEL_THROW_IF(model.texture.empty(), InvalidArgument, "web GLB: the model has no texture");
  WebGlbResult r;
  const std::size_t vertex_count = model.positions.size();
  // Triangles in vertex-cache order, then vertices in the order the triangles first use them.
  std::vector<std::uint32_t> indices;
  indices.reserve(3 * model.triangles.size());
  for (const Eigen::Vector3i& t : model.triangles)
    for (int k = 0; k < 3; ++k) indices.push_back(static_cast<std::uint32_t>(t[k]));
  meshopt_optimizeVertexCache(indices.data(), indices.data(), indices.size(), vertex_count);
  std::vector<unsigned int> remap(vertex_count);
  const std::size_t used =
      meshopt_optimizeVertexFetchRemap(remap.data(), indices.data(), indices.size(), vertex_count);
  std::vector<float> positions(3 * used), uvs(2 * used);
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (remap[v] == ~0u) continue;  // no triangle uses it
    const Eigen::Vector3d& p = model.positions[v];
    float* out = &positions[3 * remap[v]];
    out[0] = static_cast<float>(p.x());
    out[1] = static_cast<float>(p.z());  // glTF +Y up
    out[2] = static_cast<float>(-p.y());
    uvs[2 * remap[v]] = model.uvs[v].x();
    uvs[2 * remap[v] + 1] = model.uvs[v].y();
  }
  for (std::uint32_t& i : indices) i = remap[i];
  std::vector<double> lo(3, std::numeric_limits<double>::max()),
      hi(3, std::numeric_limits<double>::lowest());
  for (std::size_t i = 0; i < positions.size(); ++i) {
    lo[i % 3] = std::min(lo[i % 3], static_cast<double>(positions[i]));
    hi[i % 3] = std::max(hi[i % 3], static_cast<double>(positions[i]));
  }
  r.vertices = used;
  r.triangles = model.triangles.size();

  std::vector<Stream> streams(3);
  AppendRaw(&streams[0].raw, positions);
  streams[0].count = used;
  streams[0].stride = 12;
  streams[0].target = 34962;  // ARRAY_BUFFER
  AppendRaw(&streams[1].raw, uvs);
  streams[1].count = used;
  streams[1].stride = 8;
  streams[1].target = 34962;
  const bool short_indices = used <= 65535;
  if (short_indices) {
    std::vector<std::uint16_t> narrow(indices.begin(), indices.end());
    AppendRaw(&streams[2].raw, narrow);
  } else {
    AppendRaw(&streams[2].raw, indices);
  }
  streams[2].count = indices.size();
  streams[2].stride = short_indices ? 2 : 4;
  streams[2].indices = true;
  streams[2].target = 34963;  // ELEMENT_ARRAY_BUFFER

  // The texture.
  r.texture_size =
      WebTextureSize(std::max(model.texture.cols, model.texture.rows), options.max_texture_size);
  Bytes jpeg;
  if (!cv::imencode(".jpg", WebTexture(model.texture, r.texture_size), jpeg,
                    {cv::IMWRITE_JPEG_QUALITY, options.jpeg_quality, cv::IMWRITE_JPEG_OPTIMIZE, 1}))
    throw InvalidArgument("web GLB: JPEG encoding of the texture failed");
  r.texture_bytes = jpeg.size();

  Json json;
  json["asset"] = {{"version", "2.0"}, {"generator", "Carousel publish"}};
  Json used_extensions = Json::array();
  if (options.compress) used_extensions.push_back(kMeshopt);
  if (options.unlit) used_extensions.push_back(kUnlit);
  if (!used_extensions.empty()) json["extensionsUsed"] = used_extensions;
  if (options.compress) json["extensionsRequired"] = Json::array({kMeshopt});

  Bytes bin;
  Json views = Json::array();
  std::size_t fallback_bytes = 0;
  for (const Stream& s : streams) {
    Json view;
    r.geometry_raw_bytes += s.raw.size();
    if (options.compress) {
      const Bytes packed = Compress(s);
      Align4(&bin);
      Json ext = {{"buffer", 0},
                  {"byteOffset", bin.size()},
                  {"byteLength", packed.size()},
                  {"byteStride", s.stride},
                  {"count", s.count},
                  {"mode", s.indices ? "TRIANGLES" : "ATTRIBUTES"}};
      bin.insert(bin.end(), packed.begin(), packed.end());
      r.geometry_bytes += packed.size();
      fallback_bytes = (fallback_bytes + 3) / 4 * 4;
      view = {{"buffer", 1}, {"byteOffset", fallback_bytes}, {"byteLength", s.raw.size()}};
      fallback_bytes += s.raw.size();
      if (!s.indices) view["byteStride"] = s.stride;
      view["target"] = s.target;
      view["extensions"] = {{kMeshopt, ext}};
    } else {
      Align4(&bin);
      view = {{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", s.raw.size()}};
      if (!s.indices) view["byteStride"] = s.stride;
      view["target"] = s.target;
      bin.insert(bin.end(), s.raw.begin(), s.raw.end());
      r.geometry_bytes += s.raw.size();
    }
    views.push_back(view);
  }
  Align4(&bin);
  views.push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", jpeg.size()}});
  bin.insert(bin.end(), jpeg.begin(), jpeg.end());
  Align4(&bin);
  json["bufferViews"] = views;
  Json buffers = Json::array({{{"byteLength", bin.size()}}});
  if (options.compress)
    buffers.push_back(
        {{"byteLength", fallback_bytes}, {"extensions", {{kMeshopt, {{"fallback", true}}}}}});
  json["buffers"] = buffers;
  json["accessors"] =
      Json::array({{{"bufferView", 0},
                    {"componentType", 5126},
                    {"count", used},
                    {"type", "VEC3"},
                    {"min", lo},
                    {"max", hi}},
                   {{"bufferView", 1}, {"componentType", 5126}, {"count", used}, {"type", "VEC2"}},
                   {{"bufferView", 2},
                    {"componentType", short_indices ? 5123 : 5125},
                    {"count", indices.size()},
                    {"type", "SCALAR"}}});
  json["images"] = Json::array({{{"bufferView", 3}, {"mimeType", "image/jpeg"}}});
  const bool repeat = model.wrap == texture::TexturedModel::Wrap::kRepeat;
  const int wrap = repeat ? 10497 : 33071;
  json["samplers"] =
      Json::array({{{"magFilter", 9729}, {"minFilter", 9987}, {"wrapS", wrap}, {"wrapT", wrap}}});
  json["textures"] = Json::array({{{"sampler", 0}, {"source", 0}}});
  Json material = {
      {"name", "model"},
      {"pbrMetallicRoughness",
       {{"baseColorTexture", {{"index", 0}}}, {"metallicFactor", 0.0}, {"roughnessFactor", 1.0}}}};
  if (options.unlit) material["extensions"] = {{kUnlit, Json::object()}};
  json["materials"] = Json::array({material});
  json["meshes"] = Json::array(
      {{{"name", "model"},
        {"primitives", Json::array({{{"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}}},
                                     {"indices", 2},
                                     {"material", 0},
                                     {"mode", 4}}})}}});
  json["nodes"] = Json::array({{{"name", "model"}, {"mesh", 0}}});
  json["scenes"] = Json::array({{{"nodes", Json::array({0})}}});
  json["scene"] = 0;
  Bytes glb = AssembleGlb(json, bin);
  r.bytes = glb.size();
  if (result != nullptr) *result = r;
  return glb;
}

WebGlbResult WriteWebGlb(const texture::TexturedModel& model, const std::filesystem::path& path,
                         const WebGlbOptions& options) {
  WebGlbResult result;
  const Bytes glb = EncodeWebGlb(model, options, &result);
  WriteFileAtomic(path, std::span<const std::uint8_t>(glb.data(), glb.size()));
  return result;
}

texture::TexturedModel ReadWebGlb(const std::filesystem::path& path) {
  const std::vector<std::uint8_t> file = ReadFileBytes(path);
  if (file.size() < 20 || LoadU32(file.data()) != kGlbMagic)
    throw FormatError(path, "not a GLB (no glTF binary header)");
  if (LoadU32(file.data() + 4) != 2) throw FormatError(path, "not a glTF 2 binary");
  const std::size_t json_length = LoadU32(file.data() + 12);
  if (LoadU32(file.data() + 16) != kJsonChunk || 20 + json_length > file.size())
    throw FormatError(path, "the first chunk is not a complete JSON chunk");
  Json json;
  try {
    json = Json::parse(file.begin() + 20, file.begin() + 20 + static_cast<long>(json_length));
  } catch (const nlohmann::json::exception& e) {
    throw FormatError(path, std::string("malformed JSON chunk: ") + e.what());
  }
  Bytes bin;
  const std::size_t bin_at = 20 + (json_length + 3) / 4 * 4;
  if (bin_at + 8 <= file.size() && LoadU32(file.data() + bin_at + 4) == kBinChunk) {
    const std::size_t length = LoadU32(file.data() + bin_at);
    if (bin_at + 8 + length > file.size()) throw FormatError(path, "the BIN chunk is truncated");
    bin.assign(file.begin() + static_cast<long>(bin_at + 8),
               file.begin() + static_cast<long>(bin_at + 8 + length));
  }
  const auto is_meshopt = [](const Json& j) {
    return j.value("extensions", Json::object()).contains(kMeshopt);
  };
  bool compressed = false;
  try {
    for (Json& view : json.at("bufferViews")) {
      if (!is_meshopt(view)) continue;
      compressed = true;
      const Json& ext = view["extensions"][kMeshopt];
      const std::size_t offset = ext.value("byteOffset", std::size_t{0});
      const std::size_t length = ext.at("byteLength").get<std::size_t>();
      const std::size_t stride = ext.at("byteStride").get<std::size_t>();
      const std::size_t count = ext.at("count").get<std::size_t>();
      const std::string mode = ext.at("mode").get<std::string>();
      if (ext.at("buffer").get<int>() != 0)
        throw FormatError(path, "compressed data outside the GLB's own buffer");
      if (ext.value("filter", std::string("NONE")) != "NONE")
        throw FormatError(path, "unsupported meshopt filter " + ext["filter"].get<std::string>());
      if (offset + length > bin.size())
        throw FormatError(path, "compressed stream outside the BIN chunk");
      if (count == 0 || stride == 0 || count > (std::size_t{1} << 31) / stride)
        throw FormatError(path, "implausible compressed stream size");
      Bytes decoded(count * stride);
      int status = -1;
      if (mode == "ATTRIBUTES") {
        status =
            meshopt_decodeVertexBuffer(decoded.data(), count, stride, bin.data() + offset, length);
      } else if (mode == "TRIANGLES") {
        if (stride != 2 && stride != 4) throw FormatError(path, "index stride must be 2 or 4");
        status =
            meshopt_decodeIndexBuffer(decoded.data(), count, stride, bin.data() + offset, length);
      } else {
        throw FormatError(path, "unsupported meshopt mode " + mode);
      }
      if (status != 0) throw FormatError(path, "a meshopt stream does not decode (damaged file)");
      Align4(&bin);
      view["buffer"] = 0;
      view["byteOffset"] = bin.size();
      view["byteLength"] = decoded.size();
      view.erase("extensions");
      bin.insert(bin.end(), decoded.begin(), decoded.end());
    }
    if (compressed) {
      Align4(&bin);
      Json& buffers = json.at("buffers");
      buffers[0]["byteLength"] = bin.size();
      for (std::size_t b = 1; b < buffers.size(); ++b)
        if (!is_meshopt(buffers[b]))
          throw FormatError(path, "a buffer besides the BIN chunk and the meshopt fallback");
      buffers.erase(buffers.begin() + 1, buffers.end());
      for (const char* key : {"extensionsUsed", "extensionsRequired"}) {
        if (!json.contains(key)) continue;
        Json kept = Json::array();
        for (const Json& e : json[key])
          if (e != kMeshopt) kept.push_back(e);
        json[key] = kept;
        if (kept.empty()) json.erase(key);
      }
    }
  } catch (const nlohmann::json::exception& e) {
    throw FormatError(path, std::string("bufferViews: ") + e.what());
  }
  // KHR_materials_unlit changes only how a viewer lights the model; the reader ignores it.
  if (json.contains("extensionsRequired"))
    for (const Json& e : json["extensionsRequired"])
      if (e != kUnlit)
        throw FormatError(path, "unsupported: the file requires extension " + e.dump());
  return texture::ReadTexturedModelFromGlb(AssembleGlb(json, bin), path);
}

}  // namespace carousel::publish
