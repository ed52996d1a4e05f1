#include "carousel/texture/atlas_size.h"

#include <algorithm>
#include <cmath>

#include "carousel/core/error.h"
#include "texture_map_steps.h"

namespace carousel::texture {
namespace {

// The atlas side's description: the one range, and 0 = automatic.
OptionInfo SizeInfo() {
  return {.name = "size",
          .help = "atlas side",
          .unit = "texels",
          .min = kMinAtlasSize,
          .max = kMaxAtlasSize,
          .special = 0,
          .special_meaning = "automatic"};
}

}  // namespace

const OptionTable<AtlasSizeOptions>& AtlasSizeOptions::Fields() {
  using O = AtlasSizeOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    OptionInfo size = SizeInfo();
    size.help =
        "atlas side; automatic: as many texels per face as front-photo pixels (without photos: "
        "4096), at most --max-size";
    t.Add(&O::size, size);
    t.Add(&O::max_size, {.name = "max-size",
                         .help = "largest automatic atlas side",
                         .unit = "texels",
                         .min = 512,
                         .max = kMaxAtlasSize});
    t.Add(&O::density_coverage,
          {.name = "density-coverage",
           .help = "the automatic side gives this fraction of the faces a texel per photo pixel",
           .min = 0,
           .max = 1,
           .min_exclusive = true,
           .advanced = true});
    return t;
  }();
  return table;
}

void AtlasSizeOptions::Validate() const { Fields().Check(*this); }

void CheckAtlasSize(int size) {
  OptionInfo info = SizeInfo();
  info.special.reset();  // a decided side is never "automatic"
  CheckOptionValue(info, size);
}

int ChooseTextureSize(const Mesh& mesh, const std::vector<View>& views,
                      const std::vector<int>& front_view, double coverage, int max_size) {
  CAROUSEL_THROW_IF(!mesh.has_uvs(), InvalidArgument,
                    "texture: the mesh has no UVs (build its atlas first)");
  CAROUSEL_THROW_IF(!(coverage > 0.0 && coverage <= 1.0) || max_size < 512, InvalidArgument,
                    "ChooseTextureSize: coverage in (0, 1], max_size >= 512");
  CAROUSEL_THROW_IF(front_view.size() != mesh.n_faces(), InvalidArgument,
                    "ChooseTextureSize: one front view per face expected");
  const std::vector<internal::FaceData> faces = internal::ReadFaces(mesh);
  std::vector<double> needed;
  for (std::size_t f = 0; f < faces.size(); ++f) {
    const int v = front_view[f];
    if (v < 0 || v >= static_cast<int>(views.size())) continue;
    const double pixels = internal::ProjectedArea(faces[f], views[v].camera());
    const double uv = internal::UvArea(faces[f]);
    if (pixels > 0.0 && uv > 0.0) needed.push_back(std::sqrt(pixels / uv));
  }
  if (needed.empty()) return 512;
  const std::size_t at = std::min(
      needed.size() - 1, static_cast<std::size_t>(std::ceil(coverage * needed.size())) - 1);
  std::nth_element(needed.begin(), needed.begin() + static_cast<std::ptrdiff_t>(at), needed.end());
  const double side = needed[at];
  const int rounded = static_cast<int>(std::ceil(side / 512.0)) * 512;
  return std::clamp(rounded, 512, max_size);
}

}  // namespace carousel::texture
