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
#include <sstream>
#include <string>
#include <vector>

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
        q.texels_per_metre, o.packing.size, q.Valid(), q.flipped_faces, q.overlapping_texels,
        q.gutter_violations, q.charts_not_disks);
    if (!g_charts_image.empty() && mode == texture::PackingMode::kObb)
      WriteImage(g_charts_image, texture::DrawCharts(mesh, std::min(o.packing.size, 2048)));
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> faces = {5000, 50000, 200000};
  std::string mesh_file;
  double noise = 0.3;
  texture::AtlasOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", arg.c_str());
        std::exit(64);
      }
      return argv[++i];
    };
    if (arg == "--faces") {
      faces.clear();
      std::stringstream list(next());
      for (std::string item; std::getline(list, item, ',');) faces.push_back(std::stoi(item));
    } else if (arg == "--mesh") {
      mesh_file = next();
    } else if (arg == "--noise") {
      noise = std::stod(next());
    } else if (arg == "--size") {
      options.packing.size = std::stoi(next());
    } else if (arg == "--seeds") {
      options.charts.seeds = std::stoi(next());
    } else if (arg == "--max-normal-deviation") {
      options.charts.max_normal_deviation_deg = std::stod(next());
    } else if (arg == "--random-seed") {
      options.charts.random_seed = std::stoull(next());
    } else if (arg == "--rectify-stretch") {
      options.parameterization.rectify_max_stretch = std::stod(next());
    } else if (arg == "--charts-image") {
      g_charts_image = next();
    } else if (arg == "--gutter") {
      options.packing.gutter_texels = std::stoi(next());
    } else {
      std::fprintf(stderr, "unknown argument %s\n", arg.c_str());
      return 64;
    }
  }
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
