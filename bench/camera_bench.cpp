// Cameras through real libgphoto2 over PTP/IP, timed: N emulated cameras (the PTP/IP camera
// emulator, one per camera, each serving a photo of the simulated rig of the requested size)
// capture in parallel, every shot is downloaded, and the figures are printed: trigger-to-photo
// time, download time and throughput per shot, and the trigger skew between the cameras
// (when InitiateCapture reached each camera). A timed command-line run that prints its figures.
//
//   camera_bench [--cameras 3] [--shots 10] [--width 5184] [--height 3456] [--random-mb 0]
// --random-mb serves that many random bytes instead of the render (a busy real-world JPEG of a
// 18 MP camera is 6-10 MB; the simulated studio compresses far better).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <future>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "bench_flags.h"
#include "carousel/core/error.h"
#include "carousel/rig/gphoto_camera.h"
#include "carousel/sim/ptpip_camera.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/sim/test_scenes.h"

using namespace carousel;  // NOLINT(google-build-using-namespace)
using Clock = std::chrono::steady_clock;

namespace {

double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

struct Stats {
  std::vector<double> values;
  void Add(double v) { values.push_back(v); }
  double Median() {
    std::sort(values.begin(), values.end());
    return values.empty() ? 0 : values[values.size() / 2];
  }
  double Max() const {
    return values.empty() ? 0 : *std::max_element(values.begin(), values.end());
  }
};

int Run(int argc, char** argv) {
  int cameras = 3, shots = 10, width = 5184, height = 3456;
  double random_mb = 0;
  BenchFlags flags(argc, argv,
                   "camera_bench: parallel capture and download through libgphoto2, timed");
  flags.Option("--cameras", &cameras)
      .Option("--shots", &shots, "shots per camera")
      .Option("--width", &width)
      .Option("--height", &height)
      .Option("--random-mb", &random_mb, "serve random bytes of this size instead");
  if (const std::optional<int> exit_code = flags.Parse(std::cout, std::cerr)) return *exit_code;

  // libgphoto2 keeps ~/.gphoto/settings: a scratch HOME keeps the user's untouched.
  const std::filesystem::path work =
      std::filesystem::temp_directory_path() / "carousel_camera_bench";
  std::filesystem::remove_all(work);
  std::filesystem::create_directories(work / "home");
  ::setenv("HOME", (work / "home").c_str(), 1);

  // One photo per camera, rendered once at full size and served for every shot.
  auto scene = std::make_shared<sim::Scene>(sim::MakeSphereScene(0.1, {0, 0, 0.1}, 4));
  auto table = std::make_shared<sim::SimTurntable>(sim::SimTurntableOptions{.time_scale = 0.0});
  sim::SimRigOptions rig;
  rig.width = width;
  rig.height = height;
  rig.elevations_deg.assign(static_cast<std::size_t>(cameras), 20.0);
  for (int c = 0; c < cameras; ++c) rig.elevations_deg[c] = 10.0 + 20.0 * c;
  const auto models = sim::MakeSimRig(rig, scene->Bounds());
  std::vector<std::unique_ptr<sim::PtpIpCamera>> emulators;
  std::vector<std::unique_ptr<rig::GPhotoCamera>> bodies;
  std::size_t photo_bytes = 0;
  const auto render_start = Clock::now();
  for (int c = 0; c < cameras; ++c) {
    sim::SimCameraOptions options;
    options.render.noise_sigma = 1.5;
    sim::SimCamera renderer(scene, models[c], table, options);
    std::vector<std::uint8_t> bytes = renderer.Shoot();
    if (random_mb > 0) {
      bytes.resize(static_cast<std::size_t>(random_mb * 1e6));
      std::uint32_t x = 12345u + static_cast<std::uint32_t>(c);
      for (std::uint8_t& b : bytes)
        b = static_cast<std::uint8_t>((x = x * 1664525u + 1013904223u) >> 24);
    }
    auto jpeg = std::make_shared<const std::vector<std::uint8_t>>(std::move(bytes));
    photo_bytes = jpeg->size();
    emulators.push_back(std::make_unique<sim::PtpIpCamera>(
        [jpeg](const std::map<std::string, std::string>&) { return *jpeg; },
        sim::PtpIpCameraOptions{.serial = "BENCH" + std::to_string(c)}));
    rig::GPhotoCameraOptions camera_options;
    camera_options.port = emulators.back()->gphoto_port();
    bodies.push_back(std::make_unique<rig::GPhotoCamera>(camera_options));
  }
  std::printf("%d cameras, %d shots each, %dx%d JPEG of %.2f MB (rendered in %.1f s)\n", cameras,
              shots, width, height, photo_bytes / 1e6, Ms(Clock::now() - render_start) / 1000);

  Stats capture_ms, download_ms, round_ms, skew_ms;
  const auto total_start = Clock::now();
  for (int s = 0; s < shots; ++s) {
    const auto round_start = Clock::now();
    std::vector<std::future<std::pair<double, double>>> futures;
    futures.reserve(static_cast<std::size_t>(cameras));
    for (int c = 0; c < cameras; ++c) {
      futures.push_back(std::async(std::launch::async, [&, c, s] {
        const auto t0 = Clock::now();
        const rig::CapturedPhoto photo = bodies[c]->Capture(std::chrono::seconds(30));
        const auto t1 = Clock::now();
        std::string name = "c";  // built by append: GCC 12 warns falsely on "c" + string
        name.append(std::to_string(c)).append("_").append(std::to_string(s)).append(".jpg");
        bodies[c]->Download(photo, work / name, true, std::chrono::seconds(60));
        return std::make_pair(Ms(t1 - t0), Ms(Clock::now() - t1));
      }));
    }
    for (auto& f : futures) {
      const auto [capture, download] = f.get();
      capture_ms.Add(capture);
      download_ms.Add(download);
    }
    round_ms.Add(Ms(Clock::now() - round_start));
    std::vector<Clock::time_point> arrivals;
    arrivals.reserve(emulators.size());
    for (const auto& e : emulators) arrivals.push_back(e->Photos().back().triggered_at);
    const auto [lo, hi] = std::minmax_element(arrivals.begin(), arrivals.end());
    skew_ms.Add(Ms(*hi - *lo));
  }
  const double total_s = Ms(Clock::now() - total_start) / 1000;
  const double download_median = download_ms.Median();
  std::printf("trigger to photo on camera: median %.1f ms, max %.1f ms\n", capture_ms.Median(),
              capture_ms.Max());
  std::printf("download per photo:         median %.1f ms, max %.1f ms (%.0f MB/s per camera)\n",
              download_median, download_ms.Max(), photo_bytes / 1e3 / download_median);
  std::printf("round (all cameras):        median %.1f ms, max %.1f ms\n", round_ms.Median(),
              round_ms.Max());
  std::printf("trigger skew:               median %.2f ms, max %.2f ms\n", skew_ms.Median(),
              skew_ms.Max());
  std::printf("total: %d photos in %.2f s (%.2f s per shot per camera, %.0f MB/s overall)\n",
              cameras * shots, total_s, total_s / shots,
              cameras * shots * photo_bytes / 1e6 / total_s);
  std::filesystem::remove_all(work);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "camera_bench: %s\n", e.what());
    return 1;
  }
}
