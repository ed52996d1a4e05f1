// The atlas side (texture paper, sections 3 and 5): how many texels the square atlas has along
// each side. One range, kMinAtlasSize..kMaxAtlasSize texels, holds for packing (PackCharts,
// AtlasBuilder::Pack), transfer (TransferTexture) and the automatic choice, and one step
// decides the side: AtlasBuilder::DecideSizeAndPack (atlas.h), which BuildAtlas and the
// texture session call once.
//
// Automatic (size 0), with photos: the paper's rule, ChooseTextureSize below, measured on the
// atlas packed provisionally at min(4096, max_size) (the rule needs UVs); the charts are
// packed again at the chosen side when it differs. Without photos (BuildAtlas, the atlas
// alone): min(4096, max_size).
#pragma once

#include <vector>

#include "carousel/core/mesh.h"
#include "carousel/core/options.h"
#include "carousel/core/view.h"

namespace carousel::texture {

inline constexpr int kMinAtlasSize = 64;
inline constexpr int kMaxAtlasSize = 16384;
// The side packed at first when the side is automatic (at most max_size).
inline constexpr int kProvisionalAtlasSize = 4096;

struct AtlasSizeOptions {
  // Atlas side, texels, kMinAtlasSize..kMaxAtlasSize; 0 = automatic (above).
  int size = 0;
  // Largest automatic side, texels, 512..kMaxAtlasSize (the automatic side is a multiple of
  // 512).
  int max_size = 8192;
  // The automatic side gives at least this fraction of the faces as many texels as they cover
  // pixels in their front photo, (0, 1].
  double density_coverage = 0.95;
  // The description of every field above (core/options.h): flags, widgets, range checks.
  static const OptionTable<AtlasSizeOptions>& Fields();
  void Validate() const;
};

// A decided side (not 0). \throw InvalidArgument("--size must be 64..16384 texels, got N").
void CheckAtlasSize(int size);

// The atlas side at which at least `coverage` of the faces get as many texels as they cover
// pixels in their front photo (the paper's rule), rounded up to a multiple of 512 and clamped
// to [512, max_size]. `mesh` must have UVs (at any side: they are fractions of it).
// \throw InvalidArgument (no UVs, sizes).
int ChooseTextureSize(const Mesh& mesh, const std::vector<View>& views,
                      const std::vector<int>& front_view, double coverage, int max_size);

}  // namespace carousel::texture
