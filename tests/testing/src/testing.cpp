#include "carousel/testing/testing.h"

#include <fcntl.h>
#include <stdlib.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include <gtest/gtest.h>

namespace carousel::testing {

TempDir::TempDir() {
  std::string pattern = (std::filesystem::temp_directory_path() / "carousel-test-XXXXXX").string();
  if (::mkdtemp(pattern.data()) == nullptr) {
    throw std::runtime_error("cannot create a temporary folder from " + pattern);
  }
  path_ = pattern;
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::filesystem::path SharedDataDir() {
  const char* env = std::getenv("CAROUSEL_SHARED_DATA_DIR");
  const std::filesystem::path dir = env != nullptr && *env ? env : CAROUSEL_DEFAULT_SHARED_DATA_DIR;
  if (dir.empty() || !std::filesystem::is_directory(dir)) {
    ADD_FAILURE() << "shared test data not found: set CAROUSEL_SHARED_DATA_DIR (CTest sets it "
                     "to ../shared/data beside the checkout); got '"
                  << dir.string() << "'";
    throw std::runtime_error("shared test data missing");
  }
  return dir;
}

std::filesystem::path SharedDataFile(const std::string& relative) {
  const std::filesystem::path path = SharedDataDir() / relative;
  if (!std::filesystem::is_regular_file(path)) {
    ADD_FAILURE() << "shared test data file missing: " << path;
    throw std::runtime_error("shared test data file missing: " + path.string());
  }
  return path;
}

namespace {

// An exclusive flock on a file, released (and the descriptor closed) on scope exit.
class FileLock {
 public:
  explicit FileLock(const std::filesystem::path& path)
      : fd_(::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644)) {
    if (fd_ >= 0 && ::flock(fd_, LOCK_EX) == 0) return;
    const std::string reason = std::strerror(errno);
    if (fd_ >= 0) ::close(fd_);
    throw std::runtime_error("cannot lock " + path.string() + ": " + reason);
  }
  ~FileLock() {
    ::flock(fd_, LOCK_UN);
    ::close(fd_);
  }
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

 private:
  int fd_;
};

}  // namespace

std::filesystem::path SharedFixture(const std::string& key,
                                    const std::function<void(const std::filesystem::path&)>& make) {
  static std::mutex mutex;
  const std::lock_guard<std::mutex> guard(mutex);
  const char* env = std::getenv("CAROUSEL_TEST_CACHE_DIR");
  if (env == nullptr || *env == '\0') {
    // This process only: made once, removed at exit.
    static std::map<std::string, std::unique_ptr<TempDir>> own;
    auto& dir = own[key];
    if (dir == nullptr) {
      auto made = std::make_unique<TempDir>();
      make(made->path() / key);
      dir = std::move(made);
    }
    return dir->path() / key;
  }
  const std::filesystem::path root = env;
  std::filesystem::create_directories(root);
  const std::filesystem::path folder = root / key;
  const std::filesystem::path complete = root / (key + ".complete");
  const FileLock lock(root / (key + ".lock"));
  if (std::filesystem::exists(complete)) return folder;
  std::filesystem::remove_all(folder);
  try {
    make(folder);
  } catch (...) {
    std::error_code ec;
    std::filesystem::remove_all(folder, ec);
    throw;
  }
  WriteBytes(complete, key + "\n");
  return folder;
}

std::filesystem::path BinDir() {
  const char* env = std::getenv("CAROUSEL_BIN_DIR");
  const std::filesystem::path dir = env != nullptr && *env ? env : CAROUSEL_DEFAULT_BIN_DIR;
  if (!std::filesystem::is_directory(dir)) {
    ADD_FAILURE() << "the build's bin folder is missing: " << dir;
    throw std::runtime_error("bin folder missing: " + dir.string());
  }
  return dir;
}

std::string CarouselExecutable() { return (BinDir() / "carousel").string(); }

ShellResult RunShell(const std::string& command) {
  ShellResult result;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) {
    result.out = "popen failed: " + std::string(std::strerror(errno));
    return result;
  }
  char buffer[4096];
  std::size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) result.out.append(buffer, n);
  const int status = ::pclose(pipe);
  result.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

std::filesystem::path SimulatedSession(const std::string& key, const std::string& product,
                                       const std::string& arguments) {
  return SharedFixture(key,
                       [&](const std::filesystem::path& out) {
                         const ShellResult run =
                             RunShell(CarouselExecutable() + " run --sim --data '" +
                                      SharedDataDir().string() + "' --product '" + product +
                                      "' --out '" + out.string() + "' " + arguments);
                         if (run.code != 0)
                           throw std::runtime_error("carousel run failed in " + out.string() +
                                                    ":\n" + run.out);
                       }) /
         product;
}

void WriteBytes(const std::filesystem::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) throw std::runtime_error("cannot write test fixture " + path.string());
}

std::string ReadBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

CameraModel RandomCamera(std::mt19937& rng, const RandomCameraOptions& options) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_real_distribution<double> fov_deg(30.0, 60.0);
  CameraModel camera;
  camera.width = options.width;
  camera.height = options.height;
  const double fov = fov_deg(rng) * 3.14159265358979323846 / 180.0;
  camera.fx = 0.5 * options.width / std::tan(0.5 * fov);
  camera.fy = camera.fx * (1.0 + 0.002 * unit(rng));
  camera.cx = 0.5 * (options.width - 1) + 0.02 * options.width * unit(rng);
  camera.cy = 0.5 * (options.height - 1) + 0.02 * options.height * unit(rng);
  const double s = options.distortion_scale;
  camera.distortion = {s * 0.08 * unit(rng), s * 0.04 * unit(rng), s * 0.001 * unit(rng),
                       s * 0.001 * unit(rng), s * 0.01 * unit(rng)};
  Eigen::Vector3d direction(unit(rng), unit(rng), 0.8 * unit(rng));
  if (direction.norm() < 0.1) direction = Eigen::Vector3d(1, 0, 0.3);
  const double distance = 1.0 + 0.5 * unit(rng);
  const Eigen::Vector3d eye = distance * direction.normalized();
  const Eigen::Vector3d target(0.02 * unit(rng), 0.02 * unit(rng), 0.1 + 0.02 * unit(rng));
  // A slight roll keeps the pose generic.
  const Eigen::Vector3d up =
      (Eigen::Vector3d::UnitZ() + 0.1 * Eigen::Vector3d(unit(rng), unit(rng), 0)).normalized();
  camera.cam_from_world = Rigid3d::LookAt(eye, target, up);
  return camera;
}

}  // namespace carousel::testing
