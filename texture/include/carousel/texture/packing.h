// Chart packing (texture paper, section 3): flattened charts placed in one square atlas.
//
// Every chart first gets the same texel density (texels per metre of surface; the flattened
// charts are area-preserving, in metres). In OBB mode each chart is turned into its minimum-area
// oriented bounding box (rotating calipers over its convex hull, OpenCV's minAreaRect) and may
// be placed in any of its four quarter turns; in AABB mode it keeps its orientation (the
// paper's comparison). The density is the largest at which every chart fits (bisection); at a
// density the charts fit when either packer places them all:
// - Tetris-like: largest charts first, each chart's outline profile (per column of atlas
//   blocks, the lowest and highest row it covers, gutter included) dropped onto the atlas's
//   skyline at the column and turn where it comes to rest lowest, so charts interlock;
// - as boxes, MaxRects with best short side fit (Jylanki 2010, "A thousand ways to pack the
//   bin"), in 200 orders: three sorted (longest side, area, shortest side) and deterministic
//   perturbations of the first (box packing is sensitive to order; a try takes a fraction of
//   a millisecond for tens of charts, a few for hundreds). With rectified charts
//   (parameterization.h) boxes waste little.
// Then the room the packing leaves is handed out: the 40 largest charts in turn are enlarged
// in 2 % steps while the charts still fit (the packer that placed them last tried first, then
// 20 box orders), in three passes, up to max_density_spread times the common density, in at
// most as many packer runs as the bisection took. Texel density then varies between charts by
// at most that factor, which the L2 stretch (normalised over the atlas) measures. On 10 random
// marching-cubes blobs each of 5k / 50k / 200k faces (atlas_bench --blobs 10), utilization
// min 72.6 -> 76.3 %, 77.3 -> 80.6 %, 77.6 -> 78.3 % (median 76.6 -> 81.1 %, 80.1 -> 82.4 %,
// 79.0 -> 79.3 %) for L2 stretch max 1.039 -> 1.046.
// Charts are at least `gutter_texels` apart, so dilating each chart's texels by half the gutter
// (bilinear filtering, mip levels) never reaches another chart.
#pragma once

#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "carousel/core/options.h"
#include "carousel/core/progress.h"

namespace carousel::texture {

enum class PackingMode { kObb, kAabb };
// "obb" / "aabb". \throw InvalidArgument for other names.
PackingMode ParsePackingMode(const std::string& name);
const char* PackingModeName(PackingMode mode);

// The atlas side is not an option of the packer's: it is decided once (atlas_size.h) and
// passed in.
struct PackingOptions {
  PackingMode mode = PackingMode::kObb;
  // Empty texels between two charts (and between a chart and the atlas border, half of it),
  // 0..64. 8 keeps bilinear filtering clean down to the third mip level (1/4 size).
  int gutter_texels = 8;
  // A chart's texel density may exceed the common one by this factor (growing into room the
  // packing left), 1..2; 1 = every chart at the same density (the paper's rule).
  double max_density_spread = 1.2;
  // The description of every field above (core/options.h): flags, widgets, range checks.
  static const OptionTable<PackingOptions>& Fields();
  void Validate() const;
};

struct PackingResult {
  int size = 0;                                    // the atlas side packed into, texels
  std::vector<std::array<Eigen::Vector2d, 3>> uv;  // per face, per corner, in [0, 1], v up
  double texels_per_metre = 0.0;                   // the common (least) density
  std::vector<double> chart_texels_per_metre;      // per chart: its own, 1..spread x common
  double utilization = 0.0;                        // chart area / atlas area
  double seconds = 0.0;
};

// `uv`: per face, per corner, flattened positions in metres; `chart_of_face`: 0 .. charts - 1;
// `size`: the atlas side, texels, kMinAtlasSize..kMaxAtlasSize (atlas_size.h).
// \throw InvalidArgument (options, sizes), Cancelled.
PackingResult PackCharts(const std::vector<std::array<Eigen::Vector2d, 3>>& uv,
                         const std::vector<int>& chart_of_face, int charts, int size,
                         const PackingOptions& options, Progress& progress);

}  // namespace carousel::texture
