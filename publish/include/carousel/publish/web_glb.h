// The web GLB: what a shop's page downloads. The archive copy (model.glb, texture/export.h)
// stays lossless; this one is made for size:
//   - the texture as JPEG at a mipmap-friendly power-of-two side (the atlas side rounded up to
//     one, at most `max_texture_size`, area-averaged when it shrinks);
//   - the triangles reordered for the GPU's vertex cache and the vertices for fetch order
//     (meshoptimizer's optimizeVertexCache / optimizeVertexFetch);
//   - every vertex and index stream compressed with meshoptimizer's codecs in glTF's
//     EXT_meshopt_compression (required; the uncompressed buffer is a fallback placeholder
//     with no data, as the extension allows), which three.js and <model-viewer> decode;
//   - positions baked into glTF's +Y-up frame (turntable (x, y, z) -> glTF (x, z, -y)), no
//     node transform;
//   - the material unlit (KHR_materials_unlit) by default: a photo texture already holds the
//     studio's light, so a viewer shows its colours as they were photographed.
// ReadWebGlb decodes it again (for scoring and tests) into texture's TexturedModel.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "carousel/core/options.h"
#include "carousel/texture/textured_model.h"

namespace carousel::publish {

struct WebGlbOptions {
  int max_texture_size = 2048;  // texels per side, a power of two in 64..16384
  int jpeg_quality = 85;        // 1..100
  bool unlit = true;            // KHR_materials_unlit; false: a rough, non-metallic PBR material
  bool compress = true;         // EXT_meshopt_compression (false: plain buffers, same order)
  static const OptionTable<WebGlbOptions>& Fields();
  // \throw InvalidArgument naming the field.
  void Validate() const;
};

struct WebGlbResult {
  std::size_t bytes = 0;               // the whole file
  std::size_t texture_bytes = 0;       // the JPEG inside
  std::size_t geometry_bytes = 0;      // the (compressed) vertex and index streams
  std::size_t geometry_raw_bytes = 0;  // the same uncompressed
  int texture_size = 0;                // texels per side
  std::size_t vertices = 0, triangles = 0;
};

// The texture side the web GLB gets for an atlas of `atlas_side` texels.
int WebTextureSize(int atlas_side, int max_texture_size);

// The file's bytes. \throw InvalidArgument (model, options).
std::vector<unsigned char> EncodeWebGlb(const texture::TexturedModel& model,
                                        const WebGlbOptions& options,
                                        WebGlbResult* result = nullptr);

// Writes `path` atomically. \throw InvalidArgument, IoError naming the file.
WebGlbResult WriteWebGlb(const texture::TexturedModel& model, const std::filesystem::path& path,
                         const WebGlbOptions& options);

// Reads a GLB, decoding EXT_meshopt_compression streams (filters NONE; the ones this module
// writes) and then reading it as texture::ReadTexturedModel does; also reads plain GLBs.
// \throw IoError (missing file), FormatError naming the file and what is wrong.
texture::TexturedModel ReadWebGlb(const std::filesystem::path& path);

}  // namespace carousel::publish
