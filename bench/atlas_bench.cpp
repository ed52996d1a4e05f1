// Texture atlas on marching-cubes meshes (or a mesh file): charts, stretch, angle distortion,
// utilization and time per phase, in OBB and AABB packing. A timed command-line run that
// prints its figures (the targets: 50k triangles in <= 1 s and 200k in <= 4 s on 2
// cores; <= 300 charts, L2 stretch <= 1.05 and utilization >= 75 % on the 50k mesh).
//
//   atlas_bench [--faces 5000,50000,200000] [--mesh FILE] [--noise N] [--size N] [--seeds N]
//               [--gutter N] [--max-normal-deviation DEG] [--random-seed N]
//               [--rectify-stretch S] [--charts-image PNG]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "bench_flags.h"
#include "carousel/core/image_io.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/mesh_primitives.h"
#include "carousel/core/progress.h"
#include "carousel/core/timer.h"
#include "carousel/texture/atlas.h"

namespace {

using namespace carousel;  // NOLINT(google-build-using-namespace)

std::string g_charts_image;  // --charts-image: the OBB atlas of the last mesh

void Report(const std::string& name, const Mesh& input, const texture::AtlasOptions& options) {
  for (const texture::PackingMode mode :
       {texture::PackingMode::kObb, texture::PackingMode::kAabb}) {
    Mesh mesh = input;
    texture::AtlasOptions o = options;
    o.packing.mode = mode;
    Progress progress;
    Stopwatch total;
    const texture::AtlasResult r = texture::BuildAtlas(&mesh, o, progress);
    const double seconds = total.ElapsedSeconds() - r.seconds_quality;
    const texture::AtlasQuality& q = r.quality;
    std::printf(
        "%s %zu faces, %s: %.3f s (charts %.3f, flatten %.3f, pack %.3f); %d charts (%d grown, "
        "%d split); L2 stretch %.4f (worst face %.2f), angle distortion %.2f deg; utilization "
        "%.1f %%; %.0f texels/m in %d^2; valid %d (flipped %zu, overlaps %zu, gutter %zu, "
        "non-disks %d)\n",
        name.c_str(), mesh.n_faces(), texture::PackingModeName(mode), seconds, r.seconds_charts,
        r.seconds_parameterization, r.seconds_packing, q.charts, r.seeds_grown_into, r.charts_split,
        q.l2_stretch, q.max_face_stretch, q.angle_distortion_deg, 100.0 * q.utilization,
        q.texels_per_metre, r.size, q.Valid(), q.flipped_faces, q.overlapping_texels,
        q.gutter_violations, q.charts_not_disks);
    if (!g_charts_image.empty() && mode == texture::PackingMode::kObb)
      WriteImage(g_charts_image, texture::DrawCharts(mesh, std::min(r.size, 2048)));
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> faces = {5000, 50000, 200000};
  std::string mesh_file;
  double noise = 0.3;
  texture::AtlasOptions options;
  BenchFlags flags(argc, argv, "atlas_bench: the texture atlas on marching-cubes meshes, timed");
  flags.List("--faces", &faces, "marching-cubes meshes of about this many faces")
      .Option("--mesh", &mesh_file, "a mesh file instead")
      .Option("--noise", &noise, "noise of the marching-cubes blobs")
      .Option("--size", &options.size.size, "atlas size, texels")
      .Option("--seeds", &options.charts.seeds, "initial chart seeds")
      .Option("--max-normal-deviation", &options.charts.max_normal_deviation_deg,
              "chart normal spread, degrees")
      .Option("--random-seed", &options.charts.random_seed, "random seed of the seed choice")
      .Option("--rectify-stretch", &options.parameterization.rectify_max_stretch,
              "L2 stretch bound of rectification, 1 = none")
      .Option("--charts-image", &g_charts_image, "PNG of the last mesh's OBB atlas")
      .Option("--gutter", &options.packing.gutter_texels, "chart gap, texels");
  if (const std::optional<int> exit_code = flags.Parse(std::cout, std::cerr)) return *exit_code;
  try {
    if (!mesh_file.empty()) {
      Report(mesh_file, ReadMesh(mesh_file), options);
      return 0;
    }
    for (const int target : faces) {
      // MakeMarchingBlob gives about 15 r^2 faces.
      const int resolution = std::max(4, static_cast<int>(std::lround(std::sqrt(target / 15.0))));
      Report("blob", MakeMarchingBlob(resolution, noise, 7), options);
    }
  } catch (const std::exception& error) {
    std::fprintf(stderr, "atlas_bench: %s\n", error.what());
    return 1;
  }
  return 0;
}
