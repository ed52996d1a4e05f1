// Core throughput: camera projection (called per texel by the texture stage) and reading a
// full-size DSLR JPEG (5184x3456, the paper's photos) through Carousel's checked reader.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <random>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/image_io.h"

namespace carousel {
namespace {

CameraModel DslrCamera() {
  CameraModel camera;
  camera.width = 5184;
  camera.height = 3456;
  camera.fx = camera.fy = 7700.0;  // 50 mm lens on an APS-C sensor
  camera.cx = 2591.5;
  camera.cy = 1727.5;
  camera.distortion = {-0.08, 0.05, 0.0005, -0.0003, 0.0};
  camera.cam_from_world = Rigid3d::LookAt({1.0, 0.0, 0.36}, {0.0, 0.0, 0.12});
  return camera;
}

void BenchProject(benchmark::State& state) {
  const CameraModel camera = DslrCamera();
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-0.1, 0.1);
  std::vector<Eigen::Vector3d> points(4096);
  for (auto& p : points) p = Eigen::Vector3d(u(rng), u(rng), 0.12 + u(rng));
  for (auto _ : state) {
    for (const auto& p : points) benchmark::DoNotOptimize(camera.Project(p));
  }
  state.SetItemsProcessed(state.iterations() * points.size());
}
BENCHMARK(BenchProject);

void BenchUnproject(benchmark::State& state) {
  const CameraModel camera = DslrCamera();
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> x(0, 5183), y(0, 3455);
  std::vector<Eigen::Vector2d> pixels(4096);
  for (auto& p : pixels) p = Eigen::Vector2d(x(rng), y(rng));
  for (auto _ : state) {
    for (const auto& p : pixels) benchmark::DoNotOptimize(camera.Unproject(p, 1.0));
  }
  state.SetItemsProcessed(state.iterations() * pixels.size());
}
BENCHMARK(BenchUnproject);

void BenchReadFullSizeJpeg(benchmark::State& state) {
  // A photo-like image: smooth gradients plus grain, encoded like a camera JPEG.
  cv::Mat photo(3456, 5184, CV_8UC3);
  cv::randn(photo, cv::Scalar::all(128), cv::Scalar::all(20));
  cv::GaussianBlur(photo, photo, cv::Size(0, 0), 2.0);
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() / "carousel_bench_photo.jpg";
  WriteImage(path, photo, {.jpeg_quality = 95, .sync = false});
  for (auto _ : state) benchmark::DoNotOptimize(ReadImage(path));
  state.counters["MB"] = static_cast<double>(std::filesystem::file_size(path)) / 1e6;
  std::filesystem::remove(path);
}
BENCHMARK(BenchReadFullSizeJpeg)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace carousel

BENCHMARK_MAIN();
