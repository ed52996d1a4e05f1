// Moving photos: the shutter release with bounded retries on Device Busy, our own event loop
// against a deadline, the atomic download with retries after a reconnect, and live view.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include <opencv2/imgcodecs.hpp>

#include "carousel/core/file_util.h"
#include "carousel/core/logging.h"
#include "gphoto_internal.h"

namespace carousel::rig {
namespace {

using gphoto_internal::Describe;

// Owns a CameraFile.
struct FileHandle {
  CameraFile* file = nullptr;
  FileHandle(const FileHandle&) = delete;
  FileHandle& operator=(const FileHandle&) = delete;
  FileHandle() = default;
  ~FileHandle() {
    if (file) gp_file_unref(file);
  }
};

}  // namespace

void GPhotoCamera::Impl::DrainEvents() {
  for (int i = 0; i < 50; ++i) {
    CameraEventType type = GP_EVENT_TIMEOUT;
    void* data = nullptr;
    const int r = gp_camera_wait_for_event(camera_, 1, &type, &data, context_);
    std::free(data);
    if (r < GP_OK || type == GP_EVENT_TIMEOUT) return;
  }
}

CapturedPhoto GPhotoCamera::Impl::DoCapture(Clock::time_point deadline) {
  EnsureOpen(deadline);
  DrainEvents();
  milliseconds backoff = options_.busy_backoff;
  Clock::time_point triggered;
  for (int attempt = 0;; ++attempt) {
    triggered = Clock::now();
    const int r = gp_camera_trigger_capture(camera_, context_);
    if (r >= GP_OK) break;
    if (r == GP_ERROR_CAMERA_BUSY && attempt < options_.busy_retries &&
        Clock::now() + backoff < deadline) {
      Count(&GPhotoCounters::busy_retries);
      CAROUSEL_LOG_DEBUG(Where() << ": busy, retrying the trigger in " << backoff.count() << " ms");
      std::this_thread::sleep_for(backoff);
      backoff *= 2;
      continue;
    }
    if (r == GP_ERROR_CAMERA_BUSY) {
      throw DeviceError(Where(), "the camera stayed busy (PTP Device Busy) through " +
                                     std::to_string(attempt + 1) + " trigger attempts");
    }
    needs_reconnect_ = true;
    throw DeviceError(Where(), "the shutter could not be released: " + Describe(r));
  }
  return WaitForNewPhoto(triggered, deadline);
}

CapturedPhoto GPhotoCamera::Impl::WaitForNewPhoto(Clock::time_point triggered,
                                                  Clock::time_point deadline) {
  bool complete = false;
  while (Clock::now() < deadline) {
    CameraEventType type = GP_EVENT_TIMEOUT;
    void* data = nullptr;
    const int r = gp_camera_wait_for_event(camera_, 100, &type, &data, context_);
    if (r < GP_OK) {
      std::free(data);
      needs_reconnect_ = true;
      throw DeviceError(Where(), "lost while waiting for the photo: " + Describe(r));
    }
    if (type == GP_EVENT_FILE_ADDED && data) {
      const auto* path = static_cast<const CameraFilePath*>(data);
      const std::string folder = path->folder;
      const std::string name = path->name;
      std::free(data);
      CapturedPhoto photo;
      photo.camera_path = (folder == "/" ? "" : folder) + "/" + name;
      photo.triggered_at = triggered;
      CameraFileInfo info;
      if (gp_camera_file_get_info(camera_, folder.c_str(), name.c_str(), &info, context_) >=
              GP_OK &&
          (info.file.fields & GP_FILE_INFO_SIZE)) {
        photo.size_bytes = info.file.size;
      }
      Count(&GPhotoCounters::captures);
      return photo;
    }
    if (type == GP_EVENT_CAPTURE_COMPLETE) complete = true;
    std::free(data);
    // Over PTP/IP wait_for_event returns at once (rig-notes 1.6.4): pace the loop.
    if (type == GP_EVENT_TIMEOUT) std::this_thread::sleep_for(milliseconds(5));
  }
  throw DeviceError(Where(), complete
                                 ? "the camera finished the capture but reported no new photo"
                                 : "no new photo reported before the deadline (the shutter may "
                                   "not have fired)");
}

void GPhotoCamera::Impl::DoDownload(const CapturedPhoto& photo,
                                    const std::filesystem::path& destination,
                                    bool delete_from_camera, Clock::time_point deadline) {
  const std::size_t slash = photo.camera_path.find_last_of('/');
  CAROUSEL_THROW_IF(slash == std::string::npos || slash + 1 == photo.camera_path.size(),
                    InvalidArgument, "not a camera file path: '" << photo.camera_path << "'");
  const std::string folder = slash == 0 ? "/" : photo.camera_path.substr(0, slash);
  const std::string name = photo.camera_path.substr(slash + 1);
  std::error_code ec;
  if (std::filesystem::exists(destination, ec)) {
    throw IoError(destination, "already exists; a downloaded photo is never overwritten");
  }
  for (int attempt = 1;; ++attempt) {
    EnsureOpen(deadline);
    const std::filesystem::path temporary = TemporarySibling(destination);
    const int fd = ::open(temporary.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) throw IoError(temporary, std::strerror(errno));
    int r = GP_OK;
    {
      FileHandle file;
      // libgphoto2 writes through its own descriptor and closes it with the file.
      const int gp_fd = ::dup(fd);
      r = gp_file_new_from_fd(&file.file, gp_fd);
      if (r < GP_OK) ::close(gp_fd);
      if (r >= GP_OK) {
        r = gp_camera_file_get(camera_, folder.c_str(), name.c_str(), GP_FILE_TYPE_NORMAL,
                               file.file, context_);
      }
    }
    struct stat st {};
    const bool stat_ok = ::fstat(fd, &st) == 0;
    const bool complete =
        r >= GP_OK && stat_ok &&
        (photo.size_bytes == 0 || static_cast<std::uint64_t>(st.st_size) == photo.size_bytes);
    const bool synced = complete && ::fsync(fd) == 0;
    ::close(fd);
    if (synced) {
      // A caller that gave up waiting has been told the download failed: the photo must not
      // appear under its name afterwards.
      if (!CommitRunningJob()) {
        ::unlink(temporary.c_str());
        throw DeviceError(Where(), "download of " + photo.camera_path +
                                       " finished after its deadline; discarded");
      }
      // link() never replaces a file that appeared meanwhile.
      const bool linked = ::link(temporary.c_str(), destination.c_str()) == 0;
      const int link_errno = errno;
      ::unlink(temporary.c_str());
      if (!linked) throw IoError(destination, std::strerror(link_errno));
      SyncFolder(destination.parent_path());
      break;
    }
    ::unlink(temporary.c_str());
    std::string reason = r < GP_OK ? Describe(r)
                                   : "got " + std::to_string(st.st_size) + " of " +
                                         std::to_string(photo.size_bytes) + " bytes";
    if (r >= GP_OK && complete && !synced) {
      throw IoError(destination, "cannot flush the photo to disk");
    }
    needs_reconnect_ = true;
    if (r == GP_ERROR_FILE_NOT_FOUND || attempt >= options_.download_attempts ||
        Clock::now() + milliseconds(200) >= deadline) {
      throw DeviceError(Where(), "download of " + photo.camera_path + " failed: " + reason +
                                     " (attempt " + std::to_string(attempt) + ")");
    }
    Count(&GPhotoCounters::download_retries);
    CAROUSEL_LOG_WARN(Where() << ": download of " << photo.camera_path << " failed (" << reason
                              << "); reconnecting and retrying");
  }
  if (delete_from_camera) {
    const int r = gp_camera_file_delete(camera_, folder.c_str(), name.c_str(), context_);
    if (r < GP_OK) {
      CAROUSEL_LOG_WARN(Where() << ": " << photo.camera_path
                                << " is downloaded but could not be deleted from the camera: "
                                << Describe(r));
    }
  }
}

cv::Mat GPhotoCamera::Impl::DoPreview(Clock::time_point deadline) {
  EnsureOpen(deadline);
  FileHandle file;
  gp_file_new(&file.file);
  const int r = gp_camera_capture_preview(camera_, file.file, context_);
  if (r == GP_ERROR_NOT_SUPPORTED) {
    throw DeviceError(Where(), "the camera offers no live view through libgphoto2");
  }
  if (r < GP_OK) throw DeviceError(Where(), "live view failed: " + Describe(r));
  const char* data = nullptr;
  unsigned long size = 0;
  gp_file_get_data_and_size(file.file, &data, &size);
  const cv::Mat encoded(1, static_cast<int>(size), CV_8UC1,
                        const_cast<char*>(data));  // NOLINT(cppcoreguidelines-pro-type-const-cast)
  cv::Mat frame = cv::imdecode(encoded, cv::IMREAD_COLOR);
  if (frame.empty()) throw DeviceError(Where(), "the live-view frame could not be decoded");
  return frame;
}

}  // namespace carousel::rig
