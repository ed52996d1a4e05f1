// Export of a textured model (texture paper's output): OBJ + MTL + PNG texture (OBJ's v-up
// UVs; positions Y-up by default, as Blender and MeshLab read OBJ: turntable (x, y, z) is
// written as (x, z, -y); `obj_up = kZ` writes the turntable frame as it is), and a glTF 2.0 binary
// (GLB, through Debian's tinygltf) with the texture embedded as PNG or JPEG, v flipped to glTF's
// top-left origin. Vertices are split where a chart seam gives one position two UVs (glTF needs one
// UV per vertex). Every file is written atomically; nothing is written outside `folder`.
#pragma once

#include <filesystem>
#include <string>

#include <opencv2/core.hpp>

#include "carousel/core/mesh.h"
#include "carousel/core/options.h"

namespace carousel::texture {

struct ExportOptions {
  enum class Up { kY, kZ };
  std::string name = "model";  // file stem: model.obj, model.mtl, model.png, model.glb
  bool glb = true;
  bool jpeg_in_glb = false;  // the GLB's texture as JPEG (smaller) instead of PNG
  int jpeg_quality = 92;     // 1..100
  int png_compression = 3;   // 0..9
  Up obj_up = Up::kY;        // the OBJ's up axis (the GLB is always glTF's +Y up)
  // The description of every field above (core/options.h): flags, widgets, range checks.
  static const OptionTable<ExportOptions>& Fields();
  void Validate() const;
};

struct ExportResult {
  std::filesystem::path obj, mtl, texture, glb;
  std::size_t glb_bytes = 0;
  double seconds_png = 0.0;  // encoding and writing the texture
  double seconds_obj = 0.0;
  double seconds_glb = 0.0;
};

// `mesh` with UVs; `texture` 8-bit BGR. Creates `folder` if needed.
// \throw InvalidArgument (no UVs, empty texture, options), IoError naming the file.
ExportResult ExportTexturedModel(const Mesh& mesh, const cv::Mat& texture,
                                 const std::filesystem::path& folder, const ExportOptions& options);

}  // namespace carousel::texture
