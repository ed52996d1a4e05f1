// carousel_testing: helpers shared by every test binary (STYLE.md, practice 10): temporary
// folders, the shared test data, random cameras and tolerance matchers. Module-specific
// matchers (RigCalibrationNear, MeshNear, UvLayoutValid) join here as modules are built.
#pragma once

#include <filesystem>
#include <functional>
#include <random>
#include <string>

#include <gmock/gmock.h>
#include <Eigen/Core>

#include "carousel/core/camera_model.h"

namespace carousel::testing {

// A fresh folder under the system temporary directory, removed with everything in it when the
// object goes out of scope.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

// shared/data (third-party models, photos, Middlebury): $CAROUSEL_SHARED_DATA_DIR, or the
// build's CAROUSEL_SHARED_DATA_DIR (../shared/data beside the checkout). Fails the calling test
// (fatal) when the folder is missing: such tests never pass by being skipped.
std::filesystem::path SharedDataDir();
// SharedDataDir() / relative, after asserting that the file exists.
std::filesystem::path SharedDataFile(const std::string& relative);

// A folder made once per CTest run and shared by every test process that asks for it by key
// (a simulated session, say, that several tests start from). The first to ask runs make(folder)
// while holding a lock; the others wait and get the same folder. Tests must treat it as read
// only (copy it to change it). CTest points $CAROUSEL_TEST_CACHE_DIR at a folder it empties at
// the start of each run, so nothing outlives the run; without it (a test binary run by hand)
// each process makes its own in a temporary folder. A make() that throws leaves nothing behind.
std::filesystem::path SharedFixture(const std::string& key,
                                    const std::function<void(const std::filesystem::path&)>& make);

// The folder holding the `carousel` executable of this build ($CAROUSEL_BIN_DIR overrides).
std::filesystem::path BinDir();
// BinDir() / "carousel", as a string to start a shell command with.
std::string CarouselExecutable();

// What a shell command printed (stdout and stderr merged, in order) and its exit status
// (-1 when it did not exit normally or could not be started).
struct ShellResult {
  int code = -1;
  std::string out;
};
// Runs `command` through /bin/sh, as a user would type it: the installed program in a child
// process, its output captured.
ShellResult RunShell(const std::string& command);

// A session of the simulated rig made once per CTest run by `carousel run --sim --data <shared
// data> --product <product> --out <folder> <arguments>` (SharedFixture under `key`, so every test
// asking with the same key gets the same folder): the session folder, read only.
// \throw IoError with the command's output when the run fails.
std::filesystem::path SimulatedSession(const std::string& key, const std::string& product,
                                       const std::string& arguments);

// Writes `bytes` to `path` (test fixtures: garbage, truncated copies).
void WriteBytes(const std::filesystem::path& path, const std::string& bytes);
std::string ReadBytes(const std::filesystem::path& path);

struct RandomCameraOptions {
  int width = 1296;
  int height = 864;
  double distortion_scale = 1.0;  // 0: no distortion; 1: typical DSLR lens; 3: strong
};
// A random camera of a product studio: looking at the origin from 0.5..1.5 m, focal length for
// a 30..60 deg field of view, principal point near the centre, realistic distortion.
CameraModel RandomCamera(std::mt19937& rng, const RandomCameraOptions& options = {});

// Largest absolute coefficient difference.
template <typename A, typename B>
double MaxAbsDiff(const Eigen::MatrixBase<A>& a, const Eigen::MatrixBase<B>& b) {
  return (a - b).cwiseAbs().maxCoeff();
}

// Matches an Eigen vector/matrix within `tolerance` (max absolute coefficient difference).
MATCHER_P2(EigenNear, expected, tolerance,
           "is within " + ::testing::PrintToString(tolerance) + " of the expected value") {
  if (arg.rows() != expected.rows() || arg.cols() != expected.cols()) return false;
  const double diff = (arg - expected).cwiseAbs().maxCoeff();
  *result_listener << "max difference " << diff;
  return diff <= tolerance;
}

// Matches an exception whose what() contains `needle` (for "the message names the file").
MATCHER_P(MessageContains, needle, "message contains \"" + std::string(needle) + "\"") {
  const std::string message = arg.what();
  *result_listener << "message is \"" << message << "\"";
  return message.find(needle) != std::string::npos;
}

}  // namespace carousel::testing

// EXPECT_THROW_WITH(statement, ErrorType, needle): throws exactly ErrorType (or a subclass) and
// its message contains `needle`.
#define CAROUSEL_EXPECT_THROW_WITH(statement, ErrorType, needle) \
  EXPECT_THAT([&] { statement; }, ::testing::ThrowsMessage<ErrorType>(::testing::HasSubstr(needle)))
