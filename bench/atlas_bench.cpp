// Texture atlas on marching-cubes meshes (or a mesh file): charts, stretch, angle distortion,
// utilization and time per phase, in OBB and AABB packing. A timed command-line run that
// prints its figures (the targets: 50k triangles in <= 1 s and 200k in <= 4 s on 2
// cores; <= 300 charts, L2 stretch <= 1.05 and utilization >= 75 % on the 50k mesh).
//
//   atlas_bench [--faces 5000,50000,200000] [--mesh FILE] [--noise N] [--size N] [--seeds N]
//               [--gutter N] [--max-normal-deviation DEG] [--random-seed N]
//               [--rectify-stretch S] [--charts-image PNG] [--blobs N] [--repeat N] [--layouts N]
//
// --blobs N: N random blobs per size (MakeRandomBlob, seeds 1..N: shapes nothing was tuned
// on), OBB packing only, one line each and the minimum / median of utilization, L2 stretch and
// time per size (issue 26: >= 80 % with L2 <= 1.05 and no flips or overlaps; 50k in <= 0.7 s).
// --repeat N: each mesh is built N times and its median time reported (the phase times are the
// last run's).
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
int g_repeat = 1;            // --repeat: runs per mesh, the median time reported

struct Figures {
  double utilization = 0.0, l2 = 0.0, seconds = 0.0;
  bool valid = false;
};

Figures Report(const std::string& name, const Mesh& input, const texture::AtlasOptions& options,
               bool obb_only = false) {
  Figures figures;
  for (const texture::PackingMode mode :
       {texture::PackingMode::kObb, texture::PackingMode::kAabb}) {
    if (obb_only && mode != texture::PackingMode::kObb) continue;
    Mesh mesh;
    texture::AtlasOptions o = options;
    o.packing.mode = mode;
    // The atlas is deterministic: repeats differ in time only (a busy machine's noise).
    std::vector<double> times;
    texture::AtlasResult r;
    for (int run = 0; run < std::max(1, g_repeat); ++run) {
      mesh = input;
      Progress progress;
      Stopwatch total;
      r = texture::BuildAtlas(&mesh, o, progress);
      times.push_back(total.ElapsedSeconds() - r.seconds_quality);
    }
    std::sort(times.begin(), times.end());
    const double seconds = times[times.size() / 2];
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
    if (mode == texture::PackingMode::kObb)
      figures = {q.utilization, q.l2_stretch, seconds, q.Valid()};
  }
  return figures;
}

double Median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> faces = {5000, 50000, 200000};
  std::string mesh_file;
  double noise = 0.3;
  int blobs = 0;
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
      .Option("--layouts", &options.charts.layouts, "chart layouts tried on small meshes")
      .Option("--rectify-stretch", &options.parameterization.rectify_max_stretch,
              "L2 stretch bound of rectification, 1 = none")
      .Option("--charts-image", &g_charts_image, "PNG of the last mesh's OBB atlas")
      .Option("--gutter", &options.packing.gutter_texels, "chart gap, texels")
      .Option("--blobs", &blobs, "random blobs per size (seeds 1..N), 0 = the fixed blob")
      .Option("--repeat", &g_repeat, "runs per mesh; the median time is reported");
  if (const std::optional<int> exit_code = flags.Parse(std::cout, std::cerr)) return *exit_code;
  try {
    if (!mesh_file.empty()) {
      Report(mesh_file, ReadMesh(mesh_file), options);
      return 0;
    }
    for (const int target : faces) {
      // MakeMarchingBlob gives about 15 r^2 faces.
      const int resolution = std::max(4, static_cast<int>(std::lround(std::sqrt(target / 15.0))));
      if (blobs <= 0) {
        Report("blob", MakeMarchingBlob(resolution, noise, 7), options);
        continue;
      }
      std::vector<double> utilization, l2, seconds;
      int invalid = 0;
      for (int seed = 1; seed <= blobs; ++seed) {
        const Figures f = Report("random blob " + std::to_string(seed),
                                 MakeRandomBlob(resolution, noise, seed), options, true);
        utilization.push_back(100.0 * f.utilization);
        l2.push_back(f.l2);
        seconds.push_back(f.seconds);
        invalid += f.valid ? 0 : 1;
      }
      std::printf(
          "%d random blobs of ~%d faces: utilization min %.1f %% median %.1f %%; L2 max %.4f "
          "median %.4f; time max %.3f s median %.3f s; %d invalid\n",
          blobs, target, *std::min_element(utilization.begin(), utilization.end()),
          Median(utilization), *std::max_element(l2.begin(), l2.end()), Median(l2),
          *std::max_element(seconds.begin(), seconds.end()), Median(seconds), invalid);
    }
  } catch (const std::exception& error) {
    std::fprintf(stderr, "atlas_bench: %s\n", error.what());
    return 1;
  }
  return 0;
}
