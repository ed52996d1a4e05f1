#include "carousel/rig/gphoto_camera.h"

#include <dlfcn.h>
#include <fcntl.h>
#include <link.h>
#include <sys/stat.h>
#include <unistd.h>

#include <gphoto2/gphoto2-version.h>
#include <gphoto2/gphoto2.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <functional>
#include <future>
#include <mutex>
#include <sstream>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/logging.h"

namespace carousel::rig {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

// libgphoto2's process-wide tables (camera drivers, port drivers) load once; loading and
// gp_camera_init go through ltdl, which is not thread-safe, so both are serialised.
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

// gp_camera_exit + unref, then the fd-0 guard (the caller holds LibraryMutex()).
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

// The libgphoto2 widget names a rig setting goes by, by camera family.
const std::vector<std::string>& WidgetNames(const std::string& setting) {
  static const std::map<std::string, std::vector<std::string>> names = {
      {kSettingIso, {"iso", "exposureindex"}},
      {kSettingAperture, {"aperture", "f-number"}},
      {kSettingShutterSpeed, {"shutterspeed", "shutterspeed2", "exposuretime"}},
      {kSettingWhiteBalance, {"whitebalance"}},
      {kSettingImageFormat, {"imageformat", "imagequality", "compression"}},
      {kSettingCaptureTarget, {"capturetarget"}},
  };
  static const std::vector<std::string> none;
  const auto it = names.find(setting);
  return it == names.end() ? none : it->second;
}

// A widget's value as text; false when the widget holds none (sections, buttons).
bool WidgetValue(CameraWidget* widget, std::string* value) {
  CameraWidgetType type;
  gp_widget_get_type(widget, &type);
  switch (type) {
    case GP_WIDGET_TEXT:
    case GP_WIDGET_RADIO:
    case GP_WIDGET_MENU: {
      const char* text = nullptr;
      if (gp_widget_get_value(widget, &text) < GP_OK || !text) return false;
      *value = text;
      return true;
    }
    case GP_WIDGET_RANGE: {
      float number = 0;
      if (gp_widget_get_value(widget, &number) < GP_OK) return false;
      std::ostringstream out;
      out << number;
      *value = out.str();
      return true;
    }
    case GP_WIDGET_TOGGLE: {
      int on = 0;
      if (gp_widget_get_value(widget, &on) < GP_OK) return false;
      *value = std::to_string(on);
      return true;
    }
    case GP_WIDGET_DATE: {
      int t = 0;
      if (gp_widget_get_value(widget, &t) < GP_OK) return false;
      *value = std::to_string(t);
      return true;
    }
    default:
      return false;
  }
}

std::vector<std::string> WidgetChoices(CameraWidget* widget) {
  std::vector<std::string> choices;
  const int n = gp_widget_count_choices(widget);
  for (int i = 0; i < n; ++i) {
    const char* choice = nullptr;
    if (gp_widget_get_choice(widget, i, &choice) == GP_OK && choice) choices.emplace_back(choice);
  }
  return choices;
}

void CollectWidgets(CameraWidget* widget, const std::string& prefix,
                    std::map<std::string, std::string>* values,
                    std::map<std::string, std::vector<std::string>>* choices) {
  const char* name = nullptr;
  gp_widget_get_name(widget, &name);
  const std::string path = prefix + "/" + (name ? name : "");
  std::string value;
  if (WidgetValue(widget, &value)) {
    (*values)[path] = value;
    CameraWidgetType type;
    gp_widget_get_type(widget, &type);
    if (choices && (type == GP_WIDGET_RADIO || type == GP_WIDGET_MENU)) {
      (*choices)[path] = WidgetChoices(widget);
    }
  }
  const int n = gp_widget_count_children(widget);
  for (int i = 0; i < n; ++i) {
    CameraWidget* child = nullptr;
    if (gp_widget_get_child(widget, i, &child) == GP_OK) {
      CollectWidgets(child, path, values, choices);
    }
  }
}

// "Key: value" from libgphoto2's summary text.
std::string SummaryField(const std::string& summary, const std::string& key) {
  std::istringstream in(summary);
  std::string line;
  while (std::getline(in, line)) {
    const std::size_t start = line.find_first_not_of(" \t");
    if (start == std::string::npos) continue;
    if (line.compare(start, key.size() + 1, key + ":") == 0) {
      std::string value = line.substr(start + key.size() + 1);
      value.erase(0, value.find_first_not_of(" \t"));
      while (!value.empty() && (value.back() == ' ' || value.back() == '\r')) value.pop_back();
      return value;
    }
  }
  return {};
}

// The number a setting label stands for: "f/5.6" and "5.6" -> 5.6, "1/125" and "0.0080s"
// -> 0.008, "400" -> 400; NaN when it is not a number.
double LabelNumber(std::string label) {
  if (label.rfind("f/", 0) == 0) label = label.substr(2);
  if (!label.empty() && label.back() == 's') label.pop_back();
  const std::size_t slash = label.find('/');
  char* end = nullptr;
  if (slash != std::string::npos) {
    // `end` points into the parsed text: it must outlive the check.
    const std::string numerator = label.substr(0, slash);
    const std::string denominator = label.substr(slash + 1);
    const double a = std::strtod(numerator.c_str(), &end);
    if (numerator.empty() || *end != '\0') return std::nan("");
    const double b = std::strtod(denominator.c_str(), &end);
    if (denominator.empty() || *end != '\0' || b == 0) return std::nan("");
    return a / b;
  }
  const double v = std::strtod(label.c_str(), &end);
  if (label.empty() || *end != '\0') return std::nan("");
  return v;
}

// The camera's own label for `value`: an exact match, else (case aside) the same text, else
// the label of the same number within 3 % ("1/125" is the camera's "0.0080s"). Empty: none.
std::string MatchChoice(const std::string& value, const std::vector<std::string>& choices) {
  for (const std::string& c : choices) {
    if (c == value) return c;
  }
  for (const std::string& c : choices) {
    if (c.size() == value.size() &&
        std::equal(c.begin(), c.end(), value.begin(), [](char a, char b) {
          return std::tolower(static_cast<unsigned char>(a)) ==
                 std::tolower(static_cast<unsigned char>(b));
        })) {
      return c;
    }
  }
  const double wanted = LabelNumber(value);
  if (std::isnan(wanted) || wanted <= 0) return {};
  for (const std::string& c : choices) {
    const double v = LabelNumber(c);
    if (!std::isnan(v) && std::abs(v - wanted) <= 0.03 * wanted) return c;
  }
  return {};
}

// Owns a CameraWidget tree.
struct WidgetTree {
  CameraWidget* root = nullptr;
  WidgetTree() = default;
  WidgetTree(const WidgetTree&) = delete;
  WidgetTree& operator=(const WidgetTree&) = delete;
  ~WidgetTree() {
    if (root) gp_widget_free(root);
  }
};

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

void GPhotoCameraOptions::Validate() const {
  CAROUSEL_THROW_IF(connect_timeout.count() <= 0, InvalidArgument,
                    "camera " << port << ": connect timeout must be > 0");
  CAROUSEL_THROW_IF(busy_retries < 0 || busy_backoff.count() < 0, InvalidArgument,
                    "camera " << port << ": busy retries and backoff must be >= 0");
  CAROUSEL_THROW_IF(download_attempts < 1, InvalidArgument,
                    "camera " << port << ": download attempts must be >= 1");
}

std::string GPhotoVersion() {
  const char** version = gp_library_version(GP_VERSION_SHORT);
  return std::string("libgphoto2 ") + (version && version[0] ? version[0] : "?");
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

std::vector<DetectedCamera> DetectGPhotoCameras() {
  std::lock_guard<std::mutex> lock(LibraryMutex());
  KeepFdZeroOccupied();
  LoadPortDriversForGood();
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
  if (r < GP_OK) throw DeviceError("libgphoto2", "camera detection failed: " + Describe(r));
  return cameras;
}

// ---- the worker and the libgphoto2 session --------------------------------------------------

class GPhotoCamera::Impl : public std::enable_shared_from_this<GPhotoCamera::Impl> {
 public:
  explicit Impl(GPhotoCameraOptions options) : options_(std::move(options)) {
    options_.Validate();
    device_ = options_.port.empty() ? "camera" : "camera " + options_.port;
    {
      std::lock_guard<std::mutex> lock(LibraryMutex());
      KeepFdZeroOccupied();
    }
    context_ = gp_context_new();
    worker_ = std::thread([this] { Work(); });
  }

  ~Impl() {
    {
      std::lock_guard<std::mutex> lock(queue_mutex_);
      stopping_ = true;
    }
    queue_cv_.notify_all();
    worker_.join();
    Close();
    gp_context_unref(context_);
  }

  // Runs `job` on the worker; waits until `deadline`. A job that has not started by then is
  // abandoned (it never runs); one that is running finishes in the background and leaves the
  // session marked for a reconnect.
  // A job's lifecycle, shared by the caller and the worker.
  struct JobState {
    std::mutex mutex;
    bool started = false;
    bool abandoned = false;  // the caller gave up waiting
    bool committed = false;  // the job has made its result visible (a photo under its name)
  };

  template <typename R>
  R Run(std::function<R(Clock::time_point)> job, milliseconds timeout, const std::string& what) {
    const Clock::time_point deadline = Clock::now() + timeout;
    auto state = std::make_shared<JobState>();
    auto task = std::make_shared<std::packaged_task<R()>>([this, job, deadline, state] {
      {
        std::lock_guard<std::mutex> lock(state->mutex);
        if (state->abandoned) throw DeviceError(device_, "abandoned");
        state->started = true;
      }
      running_job_ = state;
      struct Clear {
        Impl* impl;
        ~Clear() { impl->running_job_.reset(); }
      } clear{this};
      return job(deadline);
    });
    std::future<R> result = task->get_future();
    {
      std::lock_guard<std::mutex> lock(queue_mutex_);
      queue_.push_back([task] { (*task)(); });
    }
    queue_cv_.notify_one();
    if (result.wait_until(deadline + milliseconds(250)) != std::future_status::ready) {
      bool running = false;
      bool committed = false;
      {
        std::lock_guard<std::mutex> lock(state->mutex);
        state->abandoned = true;
        running = state->started;
        committed = state->committed;
      }
      // The result is already visible (a photo linked under its name): what is left is a
      // folder sync, so report the outcome rather than a failure that did not happen.
      if (committed) return result.get();
      if (running) needs_reconnect_ = true;
      throw DeviceError(device_, what + " did not finish within " +
                                     std::to_string(timeout.count()) + " ms" +
                                     (running ? " (the camera is not answering)" : ""));
    }
    return result.get();
  }

  // ---- on the worker thread ----

  // Marks the running job's result as visible; false when its caller has given up.
  bool CommitRunningJob() {
    if (!running_job_) return true;
    std::lock_guard<std::mutex> lock(running_job_->mutex);
    if (running_job_->abandoned) return false;
    running_job_->committed = true;
    return true;
  }

  void Open(Clock::time_point deadline) {
    std::string model = options_.model;
    std::string port = options_.port;
    if (model.empty() && port.rfind("ptpip:", 0) == 0) model = "PTP/IP Camera";
    if (model.empty() || port.empty() || (port.rfind("usb:", 0) == 0 && !serial_.empty())) {
      ResolveUsb(&model, &port, deadline);
    }
    std::lock_guard<std::mutex> lock(LibraryMutex());
    gp_camera_new(&camera_);
    CameraAbilitiesList* abilities = Abilities();
    const int model_index = gp_abilities_list_lookup_model(abilities, model.c_str());
    if (model_index < GP_OK) {
      Close(false);
      throw DeviceError(device_, "libgphoto2 has no driver for the model '" + model + "'");
    }
    CameraAbilities a;
    gp_abilities_list_get_abilities(abilities, model_index, &a);
    gp_camera_set_abilities(camera_, a);
    const int port_index = gp_port_info_list_lookup_path(Ports(), port.c_str());
    if (port_index < GP_OK) {
      Close(false);
      throw DeviceError(device_, "libgphoto2 does not know the port '" + port + "'");
    }
    GPPortInfo info;
    gp_port_info_list_get_info(Ports(), port_index, &info);
    gp_camera_set_port_info(camera_, info);
    const int r = gp_camera_init(camera_, context_);
    PinLoadedDrivers();
    if (r < GP_OK) {
      Close(false);
      throw DeviceError(device_, "cannot open the camera: " + Describe(r));
    }
    current_port_ = port;
    current_model_ = model;
    needs_reconnect_ = false;
    ReadIdentity();
  }

  // Finds the USB camera to open: the one on the given port, the only one there is, or (on
  // a reconnect) the one with our serial number, wherever it re-appeared.
  void ResolveUsb(std::string* model, std::string* port, Clock::time_point deadline) {
    while (true) {
      std::vector<DetectedCamera> found = DetectGPhotoCameras();
      std::vector<DetectedCamera> candidates;
      for (const DetectedCamera& c : found) {
        if (!port->empty() && c.port == *port) candidates = {c};
      }
      if (candidates.empty()) {
        for (const DetectedCamera& c : found) {
          if (model->empty() || c.model == *model || c.model == current_model_) {
            candidates.push_back(c);
          }
        }
      }
      if (candidates.size() == 1 && serial_.empty()) {
        *model = candidates[0].model;
        *port = candidates[0].port;
        return;
      }
      if (!serial_.empty()) {
        for (const DetectedCamera& c : candidates) {
          if (ProbeSerial(c) == serial_) {
            *model = c.model;
            *port = c.port;
            return;
          }
        }
      } else if (candidates.size() > 1) {
        std::string list;
        for (const DetectedCamera& c : candidates) list += " " + c.model + " on " + c.port + ";";
        throw DeviceError(device_, "several cameras found, name one by its port:" + list);
      }
      if (Clock::now() + milliseconds(500) >= deadline) {
        throw DeviceError(
            device_, serial_.empty() ? "no camera found (is it on, in PTP mode, and free of "
                                       "other programs such as gvfs?)"
                                     : "the camera with serial " + serial_ + " has not come back");
      }
      std::this_thread::sleep_for(milliseconds(500));
    }
  }

  // The serial number of a detected camera (opens it briefly).
  std::string ProbeSerial(const DetectedCamera& c) {
    std::lock_guard<std::mutex> lock(LibraryMutex());
    ::Camera* probe = nullptr;
    gp_camera_new(&probe);
    CameraAbilities a;
    const int model_index = gp_abilities_list_lookup_model(Abilities(), c.model.c_str());
    const int port_index = gp_port_info_list_lookup_path(Ports(), c.port.c_str());
    std::string serial;
    if (model_index >= GP_OK && port_index >= GP_OK) {
      gp_abilities_list_get_abilities(Abilities(), model_index, &a);
      gp_camera_set_abilities(probe, a);
      GPPortInfo info;
      gp_port_info_list_get_info(Ports(), port_index, &info);
      gp_camera_set_port_info(probe, info);
      CameraText text;
      if (gp_camera_init(probe, context_) >= GP_OK &&
          gp_camera_get_summary(probe, &text, context_) >= GP_OK) {
        serial = SummaryField(text.text, "Serial Number");
      }
    }
    ExitCamera(probe, context_);
    return serial;
  }

  void ReadIdentity() {
    CameraText text;
    const int r = gp_camera_get_summary(camera_, &text, context_);
    if (r < GP_OK) throw DeviceError(Where(), "cannot read the camera summary: " + Describe(r));
    info_.manufacturer = SummaryField(text.text, "Manufacturer");
    info_.model = SummaryField(text.text, "Model");
    const std::string serial = SummaryField(text.text, "Serial Number");
    if (!serial_.empty() && !serial.empty() && serial != serial_) {
      throw DeviceError(
          Where(), "a different camera answered (serial " + serial + ", expected " + serial_ + ")");
    }
    if (!serial.empty()) serial_ = serial;
    info_.serial = serial_;
    info_.port = current_port_;
    info_.driver = GPhotoVersion();
    if (info_.model.empty()) info_.model = current_model_;
  }

  // The caller holds LibraryMutex() or calls it with lock = true.
  void Close(bool lock = true) {
    if (!camera_) return;
    std::unique_lock<std::mutex> guard(LibraryMutex(), std::defer_lock);
    if (lock) guard.lock();
    ExitCamera(camera_, context_);
    camera_ = nullptr;
  }

  // Reopens the session with bounded attempts until `deadline`.
  void Reopen(Clock::time_point deadline) {
    Close();
    Count(&GPhotoCounters::reconnects);
    milliseconds pause(200);
    while (true) {
      try {
        Open(deadline);
        CAROUSEL_LOG_INFO(Where() << ": reconnected");
        return;
      } catch (const DeviceError&) {
        if (Clock::now() + pause >= deadline) throw;
      }
      std::this_thread::sleep_for(pause);
      pause = std::min(pause * 2, milliseconds(2000));
    }
  }

  void EnsureOpen(Clock::time_point deadline) {
    if (!camera_ || needs_reconnect_) Reopen(deadline);
  }

  std::string Where() const {
    return "camera " + (serial_.empty() ? std::string() : serial_ + " on ") +
           (current_port_.empty() ? options_.port : current_port_);
  }

  // Discards events left from earlier captures (a late CaptureComplete, a stale ObjectAdded).
  void DrainEvents() {
    for (int i = 0; i < 50; ++i) {
      CameraEventType type = GP_EVENT_TIMEOUT;
      void* data = nullptr;
      const int r = gp_camera_wait_for_event(camera_, 1, &type, &data, context_);
      std::free(data);
      if (r < GP_OK || type == GP_EVENT_TIMEOUT) return;
    }
  }

  CapturedPhoto DoCapture(Clock::time_point deadline) {
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
        CAROUSEL_LOG_DEBUG(Where()
                           << ": busy, retrying the trigger in " << backoff.count() << " ms");
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

  // Waits for ObjectAdded after a release (ours or the controller's); the loop is ours because
  // wait_for_event does not block over PTP/IP (rig-notes 1.6.4).
  CapturedPhoto WaitForNewPhoto(Clock::time_point triggered, Clock::time_point deadline) {
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

  void DoDownload(const CapturedPhoto& photo, const std::filesystem::path& destination,
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

  // The widget of a rig setting (or a libgphoto2 widget name when `raw`).
  CameraWidget* FindWidget(CameraWidget* root, const std::string& name, bool raw,
                           std::string* found_name) {
    const std::vector<std::string> names = raw ? std::vector<std::string>{name} : WidgetNames(name);
    for (const std::string& n : names) {
      CameraWidget* widget = nullptr;
      if (gp_widget_get_child_by_name(root, n.c_str(), &widget) == GP_OK) {
        *found_name = n;
        return widget;
      }
    }
    return nullptr;
  }

  void GetConfig(WidgetTree* tree) {
    const int r = gp_camera_get_config(camera_, &tree->root, context_);
    if (r < GP_OK) {
      needs_reconnect_ = r != GP_ERROR_NOT_SUPPORTED;
      throw DeviceError(Where(), "cannot read the configuration: " + Describe(r));
    }
  }

  std::map<std::string, std::string> DoSettings(Clock::time_point deadline) {
    EnsureOpen(deadline);
    WidgetTree tree;
    GetConfig(&tree);
    std::map<std::string, std::string> settings;
    for (const char* key : {kSettingIso, kSettingAperture, kSettingShutterSpeed,
                            kSettingWhiteBalance, kSettingImageFormat, kSettingCaptureTarget}) {
      std::string widget_name;
      std::string value;
      if (CameraWidget* w = FindWidget(tree.root, key, false, &widget_name);
          w && WidgetValue(w, &value)) {
        settings[key] = value;
      }
    }
    return settings;
  }

  void DoSet(const std::string& name, const std::string& value, bool raw,
             Clock::time_point deadline) {
    EnsureOpen(deadline);
    WidgetTree tree;
    GetConfig(&tree);
    std::string widget_name;
    CameraWidget* widget = FindWidget(tree.root, name, raw, &widget_name);
    if (!widget) {
      throw InvalidArgument(Where() + ": the camera has no setting '" + name + "'");
    }
    int readonly = 0;
    gp_widget_get_readonly(widget, &readonly);
    if (readonly) throw InvalidArgument(Where() + ": '" + name + "' is read-only");
    CameraWidgetType type;
    gp_widget_get_type(widget, &type);
    int r = GP_OK;
    if (type == GP_WIDGET_RADIO || type == GP_WIDGET_MENU) {
      const std::vector<std::string> choices = WidgetChoices(widget);
      const std::string label = MatchChoice(value, choices);
      if (label.empty()) {
        std::string list;
        for (const std::string& c : choices) list += (list.empty() ? "" : ", ") + c;
        throw InvalidArgument(Where() + ": '" + value + "' is not a value of " + name +
                              " (the camera offers: " + list + ")");
      }
      r = gp_widget_set_value(widget, label.c_str());
    } else if (type == GP_WIDGET_TEXT) {
      r = gp_widget_set_value(widget, value.c_str());
    } else if (type == GP_WIDGET_RANGE || type == GP_WIDGET_TOGGLE) {
      char* end = nullptr;
      const double number = std::strtod(value.c_str(), &end);
      if (end == value.c_str() || *end != '\0') {
        throw InvalidArgument(Where() + ": '" + value + "' is not a number for " + name);
      }
      if (type == GP_WIDGET_RANGE) {
        float min = 0;
        float max = 0;
        float step = 0;
        gp_widget_get_range(widget, &min, &max, &step);
        if (number < min || number > max) {
          throw InvalidArgument(Where() + ": " + name + " must be within " + std::to_string(min) +
                                ".." + std::to_string(max));
        }
        const float f = static_cast<float>(number);
        r = gp_widget_set_value(widget, &f);
      } else {
        const int on = number != 0 ? 1 : 0;
        r = gp_widget_set_value(widget, &on);
      }
    } else {
      throw InvalidArgument(Where() + ": '" + name + "' cannot be set");
    }
    if (r >= GP_OK) r = gp_camera_set_single_config(camera_, widget_name.c_str(), widget, context_);
    if (r == GP_ERROR_NOT_SUPPORTED) r = gp_camera_set_config(camera_, tree.root, context_);
    if (r < GP_OK) {
      throw DeviceError(Where(), "cannot set " + name + " to '" + value + "': " + Describe(r));
    }
  }

  std::map<std::string, std::string> DoConfiguration(
      Clock::time_point deadline, std::map<std::string, std::vector<std::string>>* choices) {
    EnsureOpen(deadline);
    WidgetTree tree;
    GetConfig(&tree);
    std::map<std::string, std::string> values;
    CollectWidgets(tree.root, "", &values, choices);
    return values;
  }

  std::string DoSummary(Clock::time_point deadline) {
    EnsureOpen(deadline);
    CameraText text;
    const int r = gp_camera_get_summary(camera_, &text, context_);
    if (r < GP_OK) {
      needs_reconnect_ = true;
      throw DeviceError(Where(), "cannot read the summary: " + Describe(r));
    }
    return text.text;
  }

  cv::Mat DoPreview(Clock::time_point deadline) {
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
    const cv::Mat encoded(
        1, static_cast<int>(size), CV_8UC1,
        const_cast<char*>(data));  // NOLINT(cppcoreguidelines-pro-type-const-cast)
    cv::Mat frame = cv::imdecode(encoded, cv::IMREAD_COLOR);
    if (frame.empty()) throw DeviceError(Where(), "the live-view frame could not be decoded");
    return frame;
  }

  GPhotoCameraOptions options_;
  std::string device_;
  GPContext* context_ = nullptr;
  ::Camera* camera_ = nullptr;
  std::string current_port_;
  std::string current_model_;
  std::string serial_;
  CameraInfo info_;
  std::atomic<bool> needs_reconnect_{false};
  std::shared_ptr<JobState> running_job_;  // the worker's: the job it is running
  Clock::time_point external_armed_at_{};  // the worker's: when PrepareExternalRelease ran
  // The worker writes them; Counters() reads them without waiting for the worker.
  mutable std::mutex counters_mutex_;
  GPhotoCounters counters_;
  void Count(int GPhotoCounters::*counter) {
    std::lock_guard<std::mutex> lock(counters_mutex_);
    ++(counters_.*counter);
  }

 private:
  void Work() {
    // libgphoto2's PTP/IP code writes with plain write(): a camera that hung up would raise
    // SIGPIPE and kill the process. Blocked on this thread, the write fails with EPIPE instead.
    sigset_t pipe;
    sigemptyset(&pipe);
    sigaddset(&pipe, SIGPIPE);
    pthread_sigmask(SIG_BLOCK, &pipe, nullptr);
    while (true) {
      std::function<void()> job;
      {
        std::unique_lock<std::mutex> lock(queue_mutex_);
        queue_cv_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
        if (queue_.empty()) return;
        job = std::move(queue_.front());
        queue_.pop_front();
      }
      job();
    }
  }

  std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::deque<std::function<void()>> queue_;
  bool stopping_ = false;
  std::thread worker_;
};

GPhotoCamera::GPhotoCamera(GPhotoCameraOptions options)
    : impl_(std::make_shared<Impl>(std::move(options))) {
  Impl* impl = impl_.get();
  impl->Run<int>(
      [impl](Clock::time_point deadline) {
        impl->Open(deadline);
        return 0;
      },
      impl->options_.connect_timeout, "opening the camera");
}

GPhotoCamera::~GPhotoCamera() = default;

CameraInfo GPhotoCamera::Identify() {
  Impl* impl = impl_.get();
  return impl->Run<CameraInfo>([impl](Clock::time_point) { return impl->info_; },
                               milliseconds(5000), "identify");
}

std::map<std::string, std::string> GPhotoCamera::Settings(milliseconds timeout) {
  Impl* impl = impl_.get();
  return impl->Run<std::map<std::string, std::string>>(
      [impl](Clock::time_point deadline) { return impl->DoSettings(deadline); }, timeout,
      "reading the settings");
}

void GPhotoCamera::SetSetting(const std::string& name, const std::string& value,
                              milliseconds timeout) {
  CAROUSEL_THROW_IF(WidgetNames(name).empty(), InvalidArgument,
                    "unknown camera setting '" << name << "'");
  Impl* impl = impl_.get();
  impl->Run<int>(
      [impl, name, value](Clock::time_point deadline) {
        impl->DoSet(name, value, false, deadline);
        return 0;
      },
      timeout, "setting " + name);
}

void GPhotoCamera::SetConfiguration(const std::string& widget, const std::string& value,
                                    milliseconds timeout) {
  Impl* impl = impl_.get();
  impl->Run<int>(
      [impl, widget, value](Clock::time_point deadline) {
        impl->DoSet(widget, value, true, deadline);
        return 0;
      },
      timeout, "setting " + widget);
}

CapturedPhoto GPhotoCamera::Capture(milliseconds timeout) {
  Impl* impl = impl_.get();
  return impl->Run<CapturedPhoto>(
      [impl](Clock::time_point deadline) { return impl->DoCapture(deadline); }, timeout, "capture");
}

void GPhotoCamera::Download(const CapturedPhoto& photo, const std::filesystem::path& destination,
                            bool delete_from_camera, milliseconds timeout) {
  Impl* impl = impl_.get();
  impl->Run<int>(
      [impl, photo, destination, delete_from_camera](Clock::time_point deadline) {
        impl->DoDownload(photo, destination, delete_from_camera, deadline);
        return 0;
      },
      timeout, "download of " + photo.camera_path);
}

void GPhotoCamera::PrepareExternalRelease(milliseconds timeout) {
  Impl* impl = impl_.get();
  impl->Run<int>(
      [impl](Clock::time_point deadline) {
        impl->EnsureOpen(deadline);
        impl->DrainEvents();
        impl->external_armed_at_ = Clock::now();
        return 0;
      },
      timeout, "preparing for an external release");
}

CapturedPhoto GPhotoCamera::WaitForPhoto(milliseconds timeout) {
  Impl* impl = impl_.get();
  return impl->Run<CapturedPhoto>(
      [impl](Clock::time_point deadline) {
        return impl->WaitForNewPhoto(impl->external_armed_at_, deadline);
      },
      timeout, "waiting for the externally released photo");
}

cv::Mat GPhotoCamera::PreviewFrame(milliseconds timeout) {
  Impl* impl = impl_.get();
  return impl->Run<cv::Mat>(
      [impl](Clock::time_point deadline) { return impl->DoPreview(deadline); }, timeout,
      "live view");
}

std::string GPhotoCamera::Summary(milliseconds timeout) {
  Impl* impl = impl_.get();
  return impl->Run<std::string>(
      [impl](Clock::time_point deadline) { return impl->DoSummary(deadline); }, timeout, "summary");
}

std::map<std::string, std::string> GPhotoCamera::Configuration(
    milliseconds timeout, std::map<std::string, std::vector<std::string>>* choices) {
  Impl* impl = impl_.get();
  auto result = impl->Run<std::pair<std::map<std::string, std::string>,
                                    std::map<std::string, std::vector<std::string>>>>(
      [impl](Clock::time_point deadline) {
        std::map<std::string, std::vector<std::string>> c;
        auto values = impl->DoConfiguration(deadline, &c);
        return std::make_pair(std::move(values), std::move(c));
      },
      timeout, "reading the configuration");
  if (choices) *choices = std::move(result.second);
  return std::move(result.first);
}

void GPhotoCamera::Reconnect(milliseconds timeout) {
  Impl* impl = impl_.get();
  impl->Run<int>(
      [impl](Clock::time_point deadline) {
        impl->Reopen(deadline);
        return 0;
      },
      timeout, "reconnect");
}

GPhotoCounters GPhotoCamera::Counters() const {
  std::lock_guard<std::mutex> lock(impl_->counters_mutex_);
  return impl_->counters_;
}

}  // namespace carousel::rig
