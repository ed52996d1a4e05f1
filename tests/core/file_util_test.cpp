#include "carousel/core/file_util.h"

#include <signal.h>
#include <sys/resource.h>

#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/testing/testing.h"

namespace carousel {
namespace {

using testing::ReadBytes;
using testing::TempDir;
using testing::WriteBytes;

std::size_t CountEntries(const std::filesystem::path& folder) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(folder)) ++n;
  return n;
}

TEST(FileUtilTest, AtomicWriteCreatesAndReplaces) {
  TempDir dir;
  const auto path = dir / "manifest.json";
  WriteFileAtomic(path, std::string("first"));
  EXPECT_EQ(ReadBytes(path), "first");
  WriteFileAtomic(path, std::string("second, longer"));
  EXPECT_EQ(ReadBytes(path), "second, longer");
  EXPECT_EQ(CountEntries(dir.path()), 1u) << "no temporary file may be left behind";
}

TEST(FileUtilTest, NoOverwriteLeavesTheExistingFileUntouched) {
  TempDir dir;
  const auto path = dir / "photo.jpg";
  WriteBytes(path, "captured");
  CAROUSEL_EXPECT_THROW_WITH(WriteFileAtomic(path, std::string("new"), {.overwrite = false}),
                             IoError, "photo.jpg");
  EXPECT_EQ(ReadBytes(path), "captured");
  EXPECT_EQ(CountEntries(dir.path()), 1u);
}

TEST(FileUtilTest, MissingFolderIsAnIoErrorNamingThePath) {
  TempDir dir;
  CAROUSEL_EXPECT_THROW_WITH(WriteFileAtomic(dir / "no/such/folder/x.bin", std::string("x")),
                             IoError, "does not exist");
}

// A full disk, simulated with a file-size limit: the write fails with EFBIG like ENOSPC would,
// the previous file stays intact and no temporary file remains.
TEST(FileUtilTest, FullDiskKeepsThePreviousFile) {
  TempDir dir;
  const auto path = dir / "session.json";
  WriteBytes(path, "previous manifest");
  rlimit old_limit{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  const auto old_handler = ::signal(SIGXFSZ, SIG_IGN);
  rlimit small = old_limit;
  small.rlim_cur = 4096;
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
  bool threw = false;
  try {
    WriteFileAtomic(path, std::string(100000, 'x'));
  } catch (const IoError& e) {
    threw = true;
    EXPECT_EQ(e.path(), path);
  }
  ::setrlimit(RLIMIT_FSIZE, &old_limit);
  ::signal(SIGXFSZ, old_handler);
  EXPECT_TRUE(threw);
  EXPECT_EQ(ReadBytes(path), "previous manifest");
  EXPECT_EQ(CountEntries(dir.path()), 1u);
}

TEST(FileUtilTest, ReadFileBytesErrorsNameTheFile) {
  TempDir dir;
  CAROUSEL_EXPECT_THROW_WITH(ReadFileBytes(dir / "missing.bin"), IoError, "no such file");
  CAROUSEL_EXPECT_THROW_WITH(ReadFileBytes(dir.path()), IoError, "is a folder");
  WriteBytes(dir / "data.bin", std::string("\0\1\2", 3));
  EXPECT_EQ(ReadFileBytes(dir / "data.bin").size(), 3u);
}

}  // namespace
}  // namespace carousel
