// The texture atlas (texture paper, sections 1-3): charts (charts.h), flattening
// (parameterization.h) and packing (packing.h) at the side decided once (atlas_size.h) in one
// call, or staged with AtlasBuilder; writes Mesh::chart_id per face and per-halfedge UVs in
// [0, 1] (v up, OBJ convention). MeasureAtlas computes the figures of merit and the validity
// checks the tests assert.
#pragma once

#include <cstddef>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/core/mesh.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/core/view.h"
#include "carousel/texture/atlas_size.h"
#include "carousel/texture/charts.h"
#include "carousel/texture/packing.h"
#include "carousel/texture/parameterization.h"

namespace carousel::texture {

struct AtlasOptions {
  ChartOptions charts;
  ParameterizationOptions parameterization;
  PackingOptions packing;
  AtlasSizeOptions size;  // the atlas side (AtlasBuilder::DecideSizeAndPack)
  // The tables of the four parts together (core/options.h); every name unique.
  static const OptionTable<AtlasOptions>& Fields();
  void Validate() const;
};

struct AtlasQuality {
  int charts = 0;
  // Area-weighted L2 texture stretch (Sander, Snyder, Gortler, Hoppe 2001), normalised so
  // that 1 is an isometry up to the common scale; the worst face's, too.
  double l2_stretch = 0.0;
  double max_face_stretch = 0.0;
  // Area-weighted mean |UV angle - surface angle| over all corners, degrees.
  double angle_distortion_deg = 0.0;
  double utilization = 0.0;       // chart area / atlas area
  double texels_per_metre = 0.0;  // the common density (0 if not known)
  // Validity: faces without UVs (non-finite) or with a flipped or zero-area UV triangle, UVs
  // outside [0, 1], texels claimed by two charts (their pixel-centre coverage), texels whose
  // gutter neighbourhood (half the gutter around each chart) meets another chart's, and
  // charts that are not disks (one boundary loop each).
  std::size_t faces_without_uvs = 0;
  std::size_t flipped_faces = 0;
  std::size_t uvs_outside = 0;
  std::size_t overlapping_texels = 0;
  std::size_t gutter_violations = 0;
  int charts_not_disks = 0;
  bool Valid() const {
    return faces_without_uvs == 0 && flipped_faces == 0 && uvs_outside == 0 &&
           overlapping_texels == 0 && gutter_violations == 0 && charts_not_disks == 0;
  }
};

// \pre the mesh carries chart ids and UVs (BuildAtlas). The texel checks rasterise the atlas
// at `atlas_size` with the given gutter.
// \throw InvalidArgument (no UVs, sizes).
AtlasQuality MeasureAtlas(const Mesh& mesh, int atlas_size, int gutter_texels);

struct AtlasResult {
  int size = 0;  // the atlas side decided, texels
  AtlasQuality quality;
  int seeds_grown_into = 0;  // charts after growth, before splits
  int charts_split = 0;      // charts split because they did not flatten one-to-one
  int chart_iterations = 0;
  int layouts = 1;              // chart layouts tried (AtlasBuilder::Layout)
  double seconds_charts = 0.0;  // all layouts'
  double seconds_parameterization = 0.0;
  double seconds_packing = 0.0;
  double seconds_quality = 0.0;
};

// Staged use: each step re-runnable with other options (e.g. packing in both modes).
class AtlasBuilder {
 public:
  // \throw InvalidArgument: an empty mesh, non-finite coordinates (naming the vertex).
  explicit AtlasBuilder(const Mesh& mesh);
  const ChartsResult& ComputeCharts(const ChartOptions& options, Progress& progress);
  const ParameterizationResult& Parameterize(const ParameterizationOptions& options,
                                             Progress& progress);
  // Charts and flattening from `options`: on a mesh of at most options.charts.layout_faces
  // faces options.charts.layouts times, from consecutive random seeds, keeping the layout whose
  // packing at the first side DecideSizeAndPack packs at uses the most of the atlas (the first
  // on a tie). Returns the layouts tried; charts() and flattening() are the kept one's.
  int Layout(const AtlasOptions& options, Progress& progress);
  const ChartsResult& charts() const;
  const ParameterizationResult& flattening() const;
  // Packs at side `size`, kMinAtlasSize..kMaxAtlasSize.
  const PackingResult& Pack(const PackingOptions& options, int size, Progress& progress);
  // Writes chart ids and UVs into `mesh` (the same connectivity as the builder's).
  void Apply(Mesh* mesh) const;
  // The one place the atlas side is decided: packs at the side `size` gives and writes the
  // atlas into `mesh` (Apply); the result's `size` is the side. A set side is used as it is.
  // Automatic, with `views` and each face's front view among them (GroupFaces): packed
  // provisionally at min(kProvisionalAtlasSize, max_size) and written into `mesh`, the side
  // chosen on that atlas by ChooseTextureSize, packed again at it when it differs. Automatic
  // without views (`views` empty): min(kProvisionalAtlasSize, max_size).
  // \throw as Pack, Apply, ChooseTextureSize; InvalidArgument (size options).
  const PackingResult& DecideSizeAndPack(const PackingOptions& packing,
                                         const AtlasSizeOptions& size,
                                         const std::vector<View>& views,
                                         const std::vector<int>& front_view, Mesh* mesh,
                                         Progress& progress);

 private:
  const Mesh& mesh_;
  std::optional<ChartsResult> charts_;
  std::optional<ParameterizationResult> flat_;
  std::optional<PackingResult> packed_;
};

// Charts, flattening and packing of `mesh` at the side options.size gives (without photos: a
// set side, or min(kProvisionalAtlasSize, max_size)), written into it; quality measured.
// \throw as AtlasBuilder, the stages and MeasureAtlas; Cancelled.
AtlasResult BuildAtlas(Mesh* mesh, const AtlasOptions& options, Progress& progress);

// The atlas's charts drawn in distinct colours on black (BGR, size x size), for inspection.
cv::Mat DrawCharts(const Mesh& mesh, int size);

}  // namespace carousel::texture
