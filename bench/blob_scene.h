// texture_bench --blob: the texture stage on a scene nothing was tuned on (issue 26). A noisy
// marching-cubes blob (MakeRandomBlob, ~50k faces, 0.25 m across) with a procedural albedo
// (value noise in 3D: colour regions of a few centimetres, bands 5 mm apart, fractal detail
// from 6 mm down to 0.05 mm),
// photographed unlit by 12 cameras of 800x600 on an icosahedron around it, each photo with
// sensor noise and its own exposure gain (uniform within +-10 %), and no masks: a dataset
// imported with its mesh given. The mesh is textured as `carousel texture` does (front views,
// automatic size, transfer with gains and seam blending) and scored against the truth: at
// 400k points spread uniformly over the surface (by area), the texture sampled bilinearly at
// the point's UV against the true albedo there, after one least-squares gain per channel (the
// photos' common level is arbitrary): "gain-compensated PSNR vs the true albedo".
//
// The loss is accounted for step by step, each a full texturing run on the same mesh:
//   ideal      the true albedo written into our atlas at the automatic size (what the atlas's
//              resolution allows),
//   bound      noise-free, gain-free photos (what the photos allow),
//   noise      noisy photos, equal gains,
//   real       noisy photos with gains (the case; the target >= 26.7 dB in <= 4 s),
//   and the real case with one step changed: gains not estimated, no seam blending, every
//   face its most frontal view (view choice), the atlas at 2048^2 (automatic size).
#pragma once

#include <cstdint>

namespace carousel::bench {

struct BlobSceneOptions {
  int faces = 50000;  // of the blob, about
  int seeds = 1;      // blobs 1..seeds (shape, albedo, noise and gains)
  int width = 800;
  int height = 600;
  double gain_spread = 0.1;  // per-view exposure within 1 +- this
  double noise_sigma = 2.0;  // sensor noise, 8-bit levels
};

// Prints one line per run and seed and the min / median per run; returns 0, or 1 on error
// (printed).
int RunBlobScene(const BlobSceneOptions& options);

}  // namespace carousel::bench
