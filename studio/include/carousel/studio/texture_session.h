// `carousel texture SESSION`: the texture stage of a session folder (DESIGN.md):
//   model/model.obj, model.mtl, model.png   the textured mesh (OBJ v-up UVs)
//   model/model.glb                         glTF 2.0 binary with the texture embedded
//   model/report.json, model/report.png     quality report: faces by texel count (the
//                                           paper's Fig. 12), texel-to-photo-pixel density,
//                                           grouping and correction counts, time per phase
// from recon/mesh.ply, the photos and masks/. Views excluded from texturing are used to
// score the result (HeldOutScore, in the report too). session.json records the stage
// ("texture": "done") after every file is on disk. The photos, masks and mesh are only read.
#pragma once

#include <filesystem>
#include <vector>

#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/studio/session.h"
#include "carousel/texture/atlas.h"
#include "carousel/texture/export.h"
#include "carousel/texture/held_out.h"
#include "carousel/texture/texture_map.h"

namespace carousel::studio {

struct TextureSessionOptions {
  // atlas.size: the atlas side (--size, 0 = automatic, the default; --max-size;
  // --density-coverage), decided once by texture::AtlasBuilder::DecideSizeAndPack.
  texture::AtlasOptions atlas;
  texture::GroupingOptions grouping;
  // transfer.correction is not read: the grouping's (--correction) is used for both.
  texture::TransferOptions transfer;
  texture::ExportOptions output;
  // The tables of the four parts together (core/options.h); every name unique.
  static const OptionTable<TextureSessionOptions>& Fields();
  void Validate() const;
};

// The textured model rendered (unlit, from model.glb) through a held-out view's camera and
// compared with its photo over the object's mask (the session's ground-truth mask when it has
// one, else its silhouette): texture/held_out.h.
using HeldOutScore = texture::HeldOutScore;

struct TextureSessionResult {
  int views = 0;
  std::size_t faces = 0;
  int charts = 0;
  int size = 0;
  texture::GroupingResult grouping;
  int filled_faces = 0;
  int blended_texels = 0;
  int corrected_texels = 0;  // from another view than their face's (background in the front)
  int occluded_texels = 0;   // from another view than their face's (hidden in the front)
  int inpainted_texels = 0;  // background in every view: filled from the texels around
  // Fraction of faces with at least as many texels as front-photo pixels.
  double dense_fraction = 0.0;
  std::vector<int> histogram_edges;   // texels per face: bin i is [edges[i], edges[i + 1])
  std::vector<int> histogram_counts;  // faces per bin
  texture::ExportResult files;
  std::vector<HeldOutScore> held_out;  // one per excluded view
  double mean_psnr_db = 0.0, mean_ssim = 0.0;
  // What could not be done as asked (the correction skipped: views without a mask).
  std::vector<std::string> warnings;
  double seconds_grouping = 0.0, seconds_atlas = 0.0, seconds_transfer = 0.0, seconds_export = 0.0,
         seconds_evaluation = 0.0, seconds_total = 0.0;
};

// \throw IoError/FormatError naming the session file at fault (no mesh: run reconstruct
// first), InvalidArgument, Cancelled.
TextureSessionResult TextureSession(const std::filesystem::path& session_folder,
                                    const TextureSessionOptions& options, Progress& progress);
// The same on a session already read (one run reads session.json once); `session` records
// the stage and is written back.
TextureSessionResult TextureSession(const std::filesystem::path& session_folder, Session& session,
                                    const TextureSessionOptions& options, Progress& progress);

}  // namespace carousel::studio
