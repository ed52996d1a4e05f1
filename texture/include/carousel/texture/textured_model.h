// TexturedModel: a textured triangle mesh as a viewer draws it (one UV per vertex, one base
// colour texture), read back from the GLB that ExportTexturedModel wrote or made from the
// in-memory mesh and texture. The held-out scoring renders it (held_out.h).
//
// Frames and units: positions in the turntable frame (metres, +Z up; DESIGN.md). glTF is +Y
// up: reading turns it back onto +Z (x, y, z) -> (x, -z, y) after the file's node transforms,
// which undoes the export's node rotation. UVs in the texture image's convention: u right,
// v down, (0,0) = the top-left corner of the texture (glTF's; Mesh UVs are v up and are
// flipped here, as the export flips them).
#pragma once

#include <filesystem>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "carousel/core/mesh.h"

namespace carousel::texture {

struct TexturedModel {
  // How texture coordinates outside [0, 1] address the texture (the glTF sampler's wrap).
  enum class Wrap { kClampToEdge, kRepeat };

  std::vector<Eigen::Vector3d> positions;  // per vertex, metres
  std::vector<Eigen::Vector2f> uvs;        // per vertex, image convention (v down)
  std::vector<Eigen::Vector3i> triangles;  // vertex indices, counter-clockwise from outside
  cv::Mat texture;                         // CV_8UC3, BGR, sRGB-encoded
  Wrap wrap = Wrap::kClampToEdge;

  // \throw InvalidArgument if the arrays disagree in size, an index is out of range, a value
  // is not finite or the texture is not 8-bit BGR.
  void Validate() const;
};

// The model from a mesh with UVs and its texture (CV_8UC3 BGR): three vertices per face, so
// that triangle i is face i. \throw InvalidArgument (no UVs, not a triangle mesh, texture).
TexturedModel TexturedModelFromMesh(const Mesh& mesh, const cv::Mat& texture);

// Reads a .glb (or .gltf) with what ExportTexturedModel writes: the default scene's nodes with
// their transforms, triangle primitives with POSITION and TEXCOORD_0 (float, or normalised
// unsigned integers), one base colour texture shared by every primitive (embedded PNG or
// JPEG), baseColorFactor white, wrap clamp-to-edge or repeat.
// \throw IoError (missing or unreadable file) or FormatError naming the file and, for a file of
// another shape, the unsupported feature.
TexturedModel ReadTexturedModel(const std::filesystem::path& path);

// The same from a GLB in memory (what publish/ decodes a compressed file into); `name` is the
// file the bytes came from, for messages. \throw FormatError naming it.
TexturedModel ReadTexturedModelFromGlb(const std::vector<unsigned char>& glb,
                                       const std::filesystem::path& name);

}  // namespace carousel::texture
