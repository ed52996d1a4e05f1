// libgphoto2's process-wide state: the driver tables, keeping the drivers loaded, the fd-0
// guard, and camera detection.
#include <dlfcn.h>
#include <fcntl.h>
#include <link.h>
#include <unistd.h>

#include <gphoto2/gphoto2-version.h>

#include <cerrno>
#include <cstdlib>
#include <sstream>

#include "gphoto_internal.h"

namespace carousel::rig {
namespace gphoto_internal {

std::mutex& LibraryMutex() {
  static std::mutex mutex;
  return mutex;
}

CameraAbilitiesList* Abilities() {
  static CameraAbilitiesList* list = [] {
    CameraAbilitiesList* l = nullptr;
    gp_abilities_list_new(&l);
    GPContext* context = gp_context_new();
    const int r = gp_abilities_list_load(l, context);
    gp_context_unref(context);
    if (r < GP_OK) {
      throw DeviceError("libgphoto2",
                        std::string("cannot load the camera drivers: ") + gp_result_as_string(r));
    }
    return l;
  }();
  return list;
}

GPPortInfoList* Ports() {
  static GPPortInfoList* list = [] {
    GPPortInfoList* l = nullptr;
    gp_port_info_list_new(&l);
    const int r = gp_port_info_list_load(l);
    if (r < GP_OK) {
      throw DeviceError("libgphoto2", std::string("cannot load the port drivers: ") +
                                          gp_port_result_as_string(r));
    }
    return l;
  }();
  return list;
}

// libgphoto2 2.5.30 closes file descriptor 0 when a PTP/IP camera exits (seen with strace:
// close(cmd), close(event), close(0)). Were fd 0 free, the next open() or socket() anywhere in
// the process would get it and the next camera exit would close that file or socket under its
// owner. So fd 0 is kept occupied by /dev/null after every exit.
void KeepFdZeroOccupied() {
  if (::fcntl(0, F_GETFD) != -1 || errno != EBADF) return;
  const int fd = ::open("/dev/null", O_RDONLY);  // the lowest free descriptor: 0
  if (fd > 0) ::close(fd);                       // 0 was taken meanwhile: leave it
}

// Keeps every libgphoto2 camera and port driver loaded for the life of the process: libgphoto2
// dlopens a driver on gp_camera_init and dlcloses it on exit, so each reconnect would load and
// unload it again (and a leak report could not name its frames). RTLD_NOLOAD only takes another
// reference on what is already mapped; RTLD_NODELETE makes it permanent.
void PinLoadedDrivers() {
  dl_iterate_phdr(
      [](dl_phdr_info* info, std::size_t, void*) {
        const std::string path = info->dlpi_name ? info->dlpi_name : "";
        if (path.find("/libgphoto2/") != std::string::npos ||
            path.find("/libgphoto2_port/") != std::string::npos) {
          ::dlopen(path.c_str(), RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
        }
        return 0;
      },
      nullptr);
}

void ExitCamera(::Camera* camera, GPContext* context) {
  KeepFdZeroOccupied();
  gp_camera_exit(camera, context);
  gp_camera_unref(camera);
  KeepFdZeroOccupied();
}

std::string Describe(int result) {
  std::ostringstream out;
  out << gp_result_as_string(result) << " (" << result << ")";
  return out.str();
}

// Loads every libgphoto2 port driver for good before detection, which opens and closes them
// (so that a leak report can name the frames of a driver that leaks while detecting). The
// drivers are where libgphoto2_port looks: $IOLIBS, else its install folder.
void LoadPortDriversForGood() {
  const char* env = std::getenv("IOLIBS");
  const std::filesystem::path folder =
      env != nullptr && *env != '\0' ? std::filesystem::path(env)
                                     : std::filesystem::path(CAROUSEL_GPHOTO2_PORT_DRIVER_DIR);
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
    if (entry.path().extension() == ".so") {
      ::dlopen(entry.path().c_str(), RTLD_NOW | RTLD_NODELETE);
    }
  }
}

}  // namespace gphoto_internal

std::string GPhotoVersion() {
  const char** version = gp_library_version(GP_VERSION_SHORT);
  return std::string("libgphoto2 ") + (version && version[0] ? version[0] : "?");
}

std::vector<DetectedCamera> DetectGPhotoCameras() {
  std::lock_guard<std::mutex> lock(gphoto_internal::LibraryMutex());
  gphoto_internal::KeepFdZeroOccupied();
  gphoto_internal::LoadPortDriversForGood();
  CameraList* list = nullptr;
  gp_list_new(&list);
  GPContext* context = gp_context_new();
  const int r = gp_camera_autodetect(list, context);
  std::vector<DetectedCamera> cameras;
  for (int i = 0; r >= GP_OK && i < gp_list_count(list); ++i) {
    const char* name = nullptr;
    const char* value = nullptr;
    gp_list_get_name(list, i, &name);
    gp_list_get_value(list, i, &value);
    cameras.push_back({name ? name : "", value ? value : ""});
  }
  gp_list_free(list);
  gp_context_unref(context);
  if (r < GP_OK) {
    throw DeviceError("libgphoto2", "camera detection failed: " + gphoto_internal::Describe(r));
  }
  return cameras;
}

}  // namespace carousel::rig
