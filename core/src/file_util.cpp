#include "carousel/core/file_util.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>

#include "carousel/core/error.h"

namespace carousel {
namespace {

std::string ErrnoText(int error) { return std::strerror(error); }

// Closes a POSIX file descriptor on scope exit.
class FdGuard {
 public:
  explicit FdGuard(int fd) : fd_(fd) {}
  ~FdGuard() {
    if (fd_ >= 0) ::close(fd_);
  }
  FdGuard(const FdGuard&) = delete;
  FdGuard& operator=(const FdGuard&) = delete;
  int get() const { return fd_; }
  int Release() {
    const int fd = fd_;
    fd_ = -1;
    return fd;
  }

 private:
  int fd_;
};

}  // namespace

std::filesystem::path TemporarySibling(const std::filesystem::path& path) {
  static std::atomic<unsigned> counter{0};
  // Built by append: GCC 12 warns falsely (-Wrestrict) on `"." + std::string`.
  std::string name = ".";
  name.append(path.filename().string())
      .append(".tmp-")
      .append(std::to_string(::getpid()))
      .append("-")
      .append(std::to_string(counter.fetch_add(1)));
  return path.parent_path() / name;
}

void SyncFolder(const std::filesystem::path& folder) {
  const std::filesystem::path dir = folder.empty() ? std::filesystem::path(".") : folder;
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

void WriteFileAtomic(const std::filesystem::path& path, std::span<const std::uint8_t> bytes,
                     const AtomicWriteOptions& options) {
  if (path.empty()) throw IoError(path, "empty file name");
  const std::filesystem::path folder = path.parent_path();
  std::error_code ec;
  if (!folder.empty() && !std::filesystem::is_directory(folder, ec)) {
    throw IoError(path, "folder " + folder.string() + " does not exist");
  }
  if (!options.overwrite && std::filesystem::exists(path, ec)) {
    throw IoError(path, "file exists and would be overwritten");
  }
  const std::filesystem::path temporary = TemporarySibling(path);
  FdGuard fd(::open(temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644));
  if (fd.get() < 0) throw IoError(path, "cannot create file: " + ErrnoText(errno));
  auto fail = [&](const std::string& what, int error) {
    ::close(fd.Release());
    std::filesystem::remove(temporary, ec);
    throw IoError(path, what + ": " + ErrnoText(error));
  };
  std::size_t written = 0;
  while (written < bytes.size()) {
    const ssize_t n = ::write(fd.get(), bytes.data() + written, bytes.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("write failed", errno);
    }
    written += static_cast<std::size_t>(n);
  }
  if (options.sync && ::fsync(fd.get()) != 0) fail("fsync failed", errno);
  if (::close(fd.Release()) != 0) {
    const int error = errno;
    std::filesystem::remove(temporary, ec);
    throw IoError(path, "close failed: " + ErrnoText(error));
  }
  if (!options.overwrite) {
    // link() fails if the target appeared meanwhile, so nothing is ever replaced.
    if (::link(temporary.c_str(), path.c_str()) != 0) {
      const int error = errno;
      std::filesystem::remove(temporary, ec);
      throw IoError(path, error == EEXIST ? "file exists and would be overwritten"
                                          : "cannot create file: " + ErrnoText(error));
    }
    std::filesystem::remove(temporary, ec);
  } else if (::rename(temporary.c_str(), path.c_str()) != 0) {
    const int error = errno;
    std::filesystem::remove(temporary, ec);
    throw IoError(path, "cannot move file into place: " + ErrnoText(error));
  }
  if (options.sync) SyncFolder(folder);
}

void WriteFileAtomic(const std::filesystem::path& path, const std::string& text,
                     const AtomicWriteOptions& options) {
  WriteFileAtomic(path,
                  std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()),
                                                text.size()),
                  options);
}

void RequireReadableFile(const std::filesystem::path& path) {
  struct stat info {};
  if (::stat(path.c_str(), &info) != 0) {
    throw IoError(path, errno == ENOENT ? "no such file" : ErrnoText(errno));
  }
  if (S_ISDIR(info.st_mode)) throw IoError(path, "is a folder, not a file");
  if (!S_ISREG(info.st_mode)) throw IoError(path, "is not a regular file");
  if (::access(path.c_str(), R_OK) != 0) throw IoError(path, "not readable: " + ErrnoText(errno));
}

std::vector<std::uint8_t> ReadFileBytes(const std::filesystem::path& path) {
  RequireReadableFile(path);
  FdGuard fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) throw IoError(path, "cannot open: " + ErrnoText(errno));
  struct stat info {};
  if (::fstat(fd.get(), &info) != 0) throw IoError(path, "cannot stat: " + ErrnoText(errno));
  std::vector<std::uint8_t> bytes;
  bytes.reserve(static_cast<std::size_t>(info.st_size));
  std::uint8_t buffer[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd.get(), buffer, sizeof buffer);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw IoError(path, "read failed: " + ErrnoText(errno));
    }
    if (n == 0) break;
    bytes.insert(bytes.end(), buffer, buffer + n);
  }
  return bytes;
}

}  // namespace carousel
