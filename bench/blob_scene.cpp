#include "blob_scene.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "albedo_score.h"
#include "carousel/core/camera_model.h"
#include "carousel/core/mesh.h"
#include "carousel/core/mesh_primitives.h"
#include "carousel/core/progress.h"
#include "carousel/core/raster.h"
#include "carousel/core/timer.h"
#include "carousel/core/view.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/scene.h"
#include "carousel/texture/atlas.h"
#include "carousel/texture/export.h"
#include "carousel/texture/texture_map.h"

namespace carousel::bench {
namespace {

constexpr double kBlobSize = 0.25;        // metres across
constexpr double kCameraDistance = 0.55;  // metres from the blob's centre
constexpr double kFocalPerWidth = 1.1;    // focal length / image width
constexpr int kBakeSize = 4096;           // the true albedo's texture for the renderer
constexpr double kContrast = 2.0;         // of the albedo's fractal detail

// A hash of a lattice point to [0, 1).
double Hash01(std::int64_t x, std::int64_t y, std::int64_t z, std::uint64_t seed) {
  std::uint64_t h = (seed + 1) * 0x9E3779B97F4A7C15ULL;
  for (const std::int64_t k : {x, y, z}) {
    h ^= static_cast<std::uint64_t>(k) + 0x9E3779B97F4A7C15ULL + (h << 6) + (h >> 2);
    h = (h ^ (h >> 30)) * 0xBF58476D1CE4E5B9ULL;
    h = (h ^ (h >> 27)) * 0x94D049BB133111EBULL;
    h ^= h >> 31;
  }
  return static_cast<double>(h >> 11) * 0x1.0p-53;
}

// Value noise: lattice values in [0, 1) interpolated with a smoothstep.
double ValueNoise(const Eigen::Vector3d& q, std::uint64_t seed) {
  const Eigen::Vector3d floor = q.array().floor();
  const Eigen::Vector3d t = q - floor;
  auto smooth = [](double a) { return a * a * (3.0 - 2.0 * a); };
  const double s[3] = {smooth(t.x()), smooth(t.y()), smooth(t.z())};
  const auto x0 = static_cast<std::int64_t>(floor.x());
  const auto y0 = static_cast<std::int64_t>(floor.y());
  const auto z0 = static_cast<std::int64_t>(floor.z());
  double value = 0.0;
  for (int corner = 0; corner < 8; ++corner) {
    const int dx = corner & 1, dy = (corner >> 1) & 1, dz = (corner >> 2) & 1;
    const double w = (dx ? s[0] : 1.0 - s[0]) * (dy ? s[1] : 1.0 - s[1]) * (dz ? s[2] : 1.0 - s[2]);
    value += w * Hash01(x0 + dx, y0 + dy, z0 + dz, seed);
  }
  return value;
}

cv::Vec3d Mix(const cv::Vec3d& a, const cv::Vec3d& b, double t) { return a * (1.0 - t) + b * t; }

// Fractal noise: kOctaves of value noise from `scale` down, each half the size and
// kPersistence the amplitude of the one before (about 3 dB of detail per halving of the
// scale, as in a fabric or a print), in [0, 1).
constexpr int kOctaves = 8;
constexpr double kPersistence = 0.7;
double Fractal(const Eigen::Vector3d& p, double scale, std::uint64_t seed) {
  double sum = 0.0, norm = 0.0, amplitude = 1.0;
  for (int octave = 0; octave < kOctaves; ++octave) {
    sum += amplitude * ValueNoise(p / scale, seed * 16 + static_cast<std::uint64_t>(octave));
    norm += amplitude;
    amplitude *= kPersistence;
    scale *= 0.5;
  }
  return sum / norm;
}

// The true albedo at p (metres), sRGB BGR 0..255: colour regions of a few centimetres, warped
// bands 5 mm apart and fractal detail from 6 mm down to 0.05 mm (finer than the photos'
// pixels and the atlas's texels: the loss of each is measurable).
cv::Vec3d Albedo(const Eigen::Vector3d& p, std::uint64_t seed) {
  const double region = ValueNoise(p / 0.04, seed * 16 + 8);
  const double warp = ValueNoise(p / 0.012, seed * 16 + 9);
  const double detail = Fractal(p, 0.006, seed);
  const double band = 0.5 + 0.5 * std::sin(2.0 * std::numbers::pi * (p.z() / 0.005 + 3.0 * warp));
  const cv::Vec3d warm = Mix(cv::Vec3d(50, 80, 190), cv::Vec3d(40, 170, 210), region);
  const cv::Vec3d cool = Mix(cv::Vec3d(190, 120, 40), cv::Vec3d(110, 190, 90), region);
  const cv::Vec3d colour =
      Mix(warm, cool, band) * (1.0 + kContrast * (2.0 * detail - 1.0)) + cv::Vec3d(10, 10, 10);
  cv::Vec3d clamped;
  for (int k = 0; k < 3; ++k) clamped[k] = std::clamp(colour[k], 16.0, 230.0);
  return clamped;
}

// Push-pull: every texel without colour (weight 0) takes the mean of its coloured
// surroundings at the finest scale that has some. `colour` premultiplied by `weight` in, plain
// out (weights all 1).
void PushPull(cv::Mat* colour, cv::Mat* weight) {
  if (colour->rows > 1 && colour->cols > 1) {
    cv::Mat coarse_colour, coarse_weight;
    cv::resize(*colour, coarse_colour, {}, 0.5, 0.5, cv::INTER_AREA);
    cv::resize(*weight, coarse_weight, {}, 0.5, 0.5, cv::INTER_AREA);
    PushPull(&coarse_colour, &coarse_weight);
    cv::Mat up;
    cv::resize(coarse_colour, up, colour->size(), 0, 0, cv::INTER_LINEAR);
    for (int y = 0; y < colour->rows; ++y)
      for (int x = 0; x < colour->cols; ++x) {
        float& w = weight->at<float>(y, x);
        cv::Vec3f& c = colour->at<cv::Vec3f>(y, x);
        c = w > 0.0f ? c / w : up.at<cv::Vec3f>(y, x);
        w = 1.0f;
      }
    return;
  }
  const float w = weight->at<float>(0, 0);
  colour->at<cv::Vec3f>(0, 0) =
      w > 0.0f ? colour->at<cv::Vec3f>(0, 0) / w : cv::Vec3f(128, 128, 128);
  weight->at<float>(0, 0) = 1.0f;
}

// The true albedo written into the mesh's atlas (texel centres), the gutter filled.
cv::Mat BakeAlbedo(const Mesh& mesh, int size, std::uint64_t seed) {
  cv::Mat colour(size, size, CV_32FC3, cv::Scalar(0, 0, 0));
  cv::Mat weight(size, size, CV_32FC1, cv::Scalar(0));
  for (const auto f : mesh.faces()) {
    std::array<Eigen::Vector3d, 3> p;
    std::array<Eigen::Vector2d, 3> uv;
    FaceCorners(mesh, f, &p, &uv);
    std::array<Eigen::Vector2d, 3> t;
    for (int k = 0; k < 3; ++k)
      t[k] = Eigen::Vector2d(uv[k].x() * size - 0.5, (1.0 - uv[k].y()) * size - 0.5);
    ForEachPixelCentreWithBarycentrics(
        t, size, size, [&](int x, int y, const std::array<double, 3>& b) {
          const cv::Vec3d a = Albedo(b[0] * p[0] + b[1] * p[1] + b[2] * p[2], seed);
          colour.at<cv::Vec3f>(y, x) = cv::Vec3f(a);
          weight.at<float>(y, x) = 1.0f;
        });
  }
  PushPull(&colour, &weight);
  cv::Mat out;
  colour.convertTo(out, CV_8UC3);
  return out;
}

// The blob with its true albedo as the simulator's scene (three vertices per face).
sim::Scene AlbedoScene(const Mesh& mesh, std::uint64_t seed) {
  sim::Scene scene;
  scene.source = "procedural blob " + std::to_string(seed);
  for (const auto f : mesh.faces()) {
    std::array<Eigen::Vector3d, 3> p;
    std::array<Eigen::Vector2d, 3> uv;
    FaceCorners(mesh, f, &p, &uv);
    const Eigen::Vector3f normal = (p[1] - p[0]).cross(p[2] - p[0]).normalized().cast<float>();
    const int first = static_cast<int>(scene.positions.size());
    for (int k = 0; k < 3; ++k) {
      scene.positions.push_back(p[k]);
      scene.normals.push_back(normal);
      scene.uvs.emplace_back(static_cast<float>(uv[k].x()), static_cast<float>(1.0 - uv[k].y()));
    }
    scene.triangles.emplace_back(first, first + 1, first + 2);
    scene.triangle_material.push_back(0);
  }
  sim::Material material;
  material.name = "albedo";
  material.texture = 0;
  scene.materials.push_back(material);
  scene.textures.push_back(std::make_shared<const sim::Texture>(BakeAlbedo(mesh, kBakeSize, seed)));
  scene.Validate();
  return scene;
}

CameraModel Camera(const Eigen::Vector3d& direction, int width, int height) {
  CameraModel camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = kFocalPerWidth * width;
  camera.cx = 0.5 * (width - 1);
  camera.cy = 0.5 * (height - 1);
  const Eigen::Vector3d d = direction.normalized();
  const Eigen::Vector3d up =
      std::abs(d.z()) > 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitZ();
  camera.cam_from_world = Rigid3d::LookAt(d * kCameraDistance, Eigen::Vector3d::Zero(), up);
  return camera;
}

// The 12 cameras (an icosahedron's corners).
std::vector<CameraModel> PhotoCameras(int width, int height) {
  const double phi = 0.5 * (1.0 + std::sqrt(5.0));
  std::vector<CameraModel> cameras;
  for (const double a : {-1.0, 1.0})
    for (const double b : {-phi, phi}) {
      cameras.push_back(Camera({0.0, a, b}, width, height));
      cameras.push_back(Camera({a, b, 0.0}, width, height));
      cameras.push_back(Camera({b, 0.0, a}, width, height));
    }
  return cameras;
}

sim::RenderOptions Unlit(double noise_sigma, double exposure, std::uint64_t seed) {
  sim::RenderOptions options;
  options.lit = false;
  options.plate_radius_m = 0.0;
  options.noise_sigma = noise_sigma;
  options.exposure = exposure;
  options.seed = seed;
  return options;
}

// Photos through `cameras`: noise and per-view exposure gains as asked; no masks.
std::vector<View> Photograph(const sim::Scene& scene, const std::vector<CameraModel>& cameras,
                             double noise_sigma, double gain_spread, std::uint64_t seed) {
  std::vector<View> views;
  for (std::size_t v = 0; v < cameras.size(); ++v) {
    const double gain =
        1.0 + gain_spread * (2.0 * Hash01(static_cast<std::int64_t>(v), 0, 7, seed) - 1.0);
    const sim::RenderResult r =
        sim::Render(scene, cameras[v], 0.0, Unlit(noise_sigma, gain, seed * 100 + v));
    View view(cameras[v], {});
    view.SetImage(r.image);
    view.set_name("blob view " + std::to_string(v));
    views.push_back(std::move(view));
  }
  return views;
}

// Gain-compensated PSNR of the texture against the true albedo at points spread uniformly over
// the surface (by area; seeded): the texture sampled bilinearly at each point's UV, one
// least-squares gain per channel (the photos' common level is arbitrary).
double ScorePsnr(const Mesh& mesh, const cv::Mat& texture, std::uint64_t seed) {
  constexpr int kPoints = 400000;
  std::vector<std::array<Eigen::Vector3d, 3>> p(mesh.n_faces());
  std::vector<std::array<Eigen::Vector2d, 3>> uv(mesh.n_faces());
  std::vector<double> cumulative;
  double total = 0.0;
  for (const auto f : mesh.faces()) {
    FaceCorners(mesh, f, &p[f.idx()], &uv[f.idx()]);
    const auto& q = p[f.idx()];
    total += 0.5 * (q[1] - q[0]).cross(q[2] - q[0]).norm();
    cumulative.push_back(total);
  }
  GainCompensatedPsnr psnr;
  for (int i = 0; i < kPoints; ++i) {
    const double pick = Hash01(i, 1, 0, seed) * total;
    const auto f = static_cast<std::size_t>(std::min<std::ptrdiff_t>(
        std::lower_bound(cumulative.begin(), cumulative.end(), pick) - cumulative.begin(),
        static_cast<std::ptrdiff_t>(cumulative.size()) - 1));
    // Uniform in the triangle.
    const double r1 = std::sqrt(Hash01(i, 2, 0, seed));
    const double r2 = Hash01(i, 3, 0, seed);
    const double b[3] = {1.0 - r1, r1 * (1.0 - r2), r1 * r2};
    const Eigen::Vector3d point = b[0] * p[f][0] + b[1] * p[f][1] + b[2] * p[f][2];
    const Eigen::Vector2d t = b[0] * uv[f][0] + b[1] * uv[f][1] + b[2] * uv[f][2];
    psnr.Add(SampleAtlas(texture, t), Albedo(point, seed));
  }
  return psnr.Db();
}

// One texturing run's settings.
struct Variant {
  std::string name;
  int photos = 2;  // 0 clean, 1 noise, 2 noise and gains
  bool gain = true, blend = true, frontal = false;
  int size = 0;  // 0 = automatic
};

struct Run {
  Mesh mesh;
  cv::Mat texture;
  int size = 0;
  double seconds = 0.0, seconds_export = 0.0;
  int patches = 0;
};

// Textures `blob` from `views` as `carousel texture` does without masks, and writes the model.
Run TextureBlob(const Mesh& blob, const std::vector<View>& views, const Variant& variant,
                const std::filesystem::path& folder) {
  Progress progress;
  Stopwatch watch;
  Run run;
  run.mesh = blob;
  texture::GroupingOptions grouping;
  grouping.correction = false;
  if (variant.frontal) grouping.seam_cost = 0.0;
  const texture::GroupingResult groups = texture::GroupFaces(run.mesh, views, grouping, progress);
  run.patches = groups.patches;
  texture::AtlasBuilder builder(run.mesh);
  const texture::AtlasOptions atlas;
  builder.Layout(atlas, progress);
  texture::AtlasSizeOptions size = atlas.size;
  size.size = variant.size;
  run.size =
      builder.DecideSizeAndPack(atlas.packing, size, views, groups.front_view, &run.mesh, progress)
          .size;
  texture::TransferOptions transfer;
  transfer.correction = false;
  transfer.gain = variant.gain;
  transfer.blend = variant.blend;
  run.texture =
      texture::TransferTexture(run.mesh, views, groups, run.size, transfer, progress).texture;
  run.seconds = watch.ElapsedSeconds();
  watch = Stopwatch();
  texture::ExportOptions output;
  output.glb = false;
  texture::ExportTexturedModel(run.mesh, run.texture, folder, output);
  run.seconds_export = watch.ElapsedSeconds();
  return run;
}

double Median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

}  // namespace

int RunBlobScene(const BlobSceneOptions& options) {
  const std::vector<Variant> variants = {
      {.name = "bound (clean photos)", .photos = 0},
      {.name = "noise", .photos = 1},
      {.name = "real (noise, gains)"},
      {.name = "real, gains not estimated", .gain = false},
      {.name = "real, no seam blending", .blend = false},
      {.name = "real, most frontal views", .frontal = true},
      {.name = "real at 2048^2", .size = 2048},
  };
  const std::filesystem::path folder =
      std::filesystem::temp_directory_path() / "carousel_blob_scene";
  std::map<std::string, std::vector<double>> psnr, seconds;
  try {
    for (int seed = 1; seed <= options.seeds; ++seed) {
      const auto s = static_cast<std::uint64_t>(seed);
      const int resolution =
          std::max(4, static_cast<int>(std::lround(std::sqrt(options.faces / 15.0))));
      Mesh blob = MakeRandomBlob(resolution, 0.3, s);
      Eigen::AlignedBox3d bounds;
      for (const auto v : blob.vertices()) {
        const auto& q = blob.point(v);
        bounds.extend(Eigen::Vector3d(q[0], q[1], q[2]));
      }
      const double scale = kBlobSize / bounds.sizes().maxCoeff();
      for (const auto v : blob.vertices()) {
        auto& q = blob.point(v);
        const Eigen::Vector3d p = (Eigen::Vector3d(q[0], q[1], q[2]) - bounds.center()) * scale;
        q = Mesh::Point(p.x(), p.y(), p.z());
      }
      // The scene's UVs: our own atlas of the blob (any parameterization would do).
      Mesh parameterized = blob;
      texture::AtlasOptions bake;
      bake.size.size = kBakeSize;
      Progress progress;
      texture::BuildAtlas(&parameterized, bake, progress);
      const sim::Scene scene = AlbedoScene(parameterized, s);
      const std::vector<CameraModel> cameras = PhotoCameras(options.width, options.height);
      const std::vector<std::vector<View>> photos = {
          Photograph(scene, cameras, 0.0, 0.0, s),
          Photograph(scene, cameras, options.noise_sigma, 0.0, s),
          Photograph(scene, cameras, options.noise_sigma, options.gain_spread, s)};
      std::printf("blob %d: %zu faces, %zu photos of %dx%d (noise %.1f, gains +-%.0f %%)\n", seed,
                  blob.n_faces(), cameras.size(), options.width, options.height,
                  options.noise_sigma, 100.0 * options.gain_spread);
      Run real;
      for (const Variant& variant : variants) {
        Run run = TextureBlob(blob, photos[variant.photos], variant, folder);
        const double db = ScorePsnr(run.mesh, run.texture, s);
        std::printf("  %-28s %.2f dB at %d^2; %.2f s (+ %.2f s writing OBJ/PNG); %d patches\n",
                    variant.name.c_str(), db, run.size, run.seconds, run.seconds_export,
                    run.patches);
        psnr[variant.name].push_back(db);
        seconds[variant.name].push_back(run.seconds + run.seconds_export);
        if (variant.name == "real (noise, gains)") real = std::move(run);
      }
      // What the atlas's resolution allows: the true albedo written into the real run's atlas.
      const double ideal_2048 = ScorePsnr(real.mesh, BakeAlbedo(real.mesh, 2048, s), s);
      const double ideal = ScorePsnr(real.mesh, BakeAlbedo(real.mesh, real.size, s), s);
      std::printf("  %-28s %.2f dB at %d^2 (%.2f dB at 2048^2)\n", "ideal (true albedo baked)",
                  ideal, real.size, ideal_2048);
      psnr["ideal (true albedo baked)"].push_back(ideal);
    }
  } catch (const std::exception& error) {
    std::fprintf(stderr, "texture_bench --blob: %s\n", error.what());
    return 1;
  }
  std::printf("%d blob(s): PSNR min / median, time (with writing) max / median\n", options.seeds);
  for (const auto& [name, values] : psnr) {
    std::printf("  %-28s %.2f / %.2f dB", name.c_str(),
                *std::min_element(values.begin(), values.end()), Median(values));
    if (seconds.count(name))
      std::printf("; %.2f / %.2f s", *std::max_element(seconds[name].begin(), seconds[name].end()),
                  Median(seconds[name]));
    std::printf("\n");
  }
  return 0;
}

}  // namespace carousel::bench
