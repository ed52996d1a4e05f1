// The libgphoto2 camera: the worker thread every libgphoto2 call runs on, the session (open,
// find a camera again by its serial number, reopen with bounded attempts) and the public calls.
#include "carousel/rig/gphoto_camera.h"

#include <algorithm>
#include <csignal>
#include <sstream>

#include "carousel/core/logging.h"
#include "gphoto_internal.h"

namespace carousel::rig {
namespace {

using Clock = std::chrono::steady_clock;
using gphoto_internal::Abilities;
using gphoto_internal::Describe;
using gphoto_internal::ExitCamera;
using gphoto_internal::KeepFdZeroOccupied;
using gphoto_internal::LibraryMutex;
using gphoto_internal::PinLoadedDrivers;
using gphoto_internal::Ports;
using gphoto_internal::WidgetNames;
using std::chrono::milliseconds;

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

}  // namespace

void GPhotoCameraOptions::Validate() const {
  CAROUSEL_THROW_IF(connect_timeout.count() <= 0, InvalidArgument,
                    "camera " << port << ": connect timeout must be > 0");
  CAROUSEL_THROW_IF(busy_retries < 0 || busy_backoff.count() < 0, InvalidArgument,
                    "camera " << port << ": busy retries and backoff must be >= 0");
  CAROUSEL_THROW_IF(download_attempts < 1, InvalidArgument,
                    "camera " << port << ": download attempts must be >= 1");
}

// ---- the worker and the libgphoto2 session --------------------------------------------------

GPhotoCamera::Impl::Impl(GPhotoCameraOptions options) : options_(std::move(options)) {
  options_.Validate();
  device_ = options_.port.empty() ? "camera" : "camera " + options_.port;
  {
    std::lock_guard<std::mutex> lock(LibraryMutex());
    KeepFdZeroOccupied();
  }
  context_ = gp_context_new();
  worker_ = std::thread([this] { Work(); });
}

GPhotoCamera::Impl::~Impl() {
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    // Closing says goodbye to the camera (PTP CloseSession): on the worker, where SIGPIPE is
    // blocked, so that a camera that hung up cannot kill the process that lets go of it.
    queue_.push_back([this] { Close(); });
    stopping_ = true;
  }
  queue_cv_.notify_all();
  worker_.join();
  gp_context_unref(context_);
}

bool GPhotoCamera::Impl::CommitRunningJob() {
  if (!running_job_) return true;
  std::lock_guard<std::mutex> lock(running_job_->mutex);
  if (running_job_->abandoned) return false;
  running_job_->committed = true;
  return true;
}

void GPhotoCamera::Impl::Open(Clock::time_point deadline) {
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

void GPhotoCamera::Impl::ResolveUsb(std::string* model, std::string* port,
                                    Clock::time_point deadline) {
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
      throw DeviceError(device_, serial_.empty()
                                     ? "no camera found (is it on, in PTP mode, and free of "
                                       "other programs such as gvfs?)"
                                     : "the camera with serial " + serial_ + " has not come back");
    }
    std::this_thread::sleep_for(milliseconds(500));
  }
}

std::string GPhotoCamera::Impl::ProbeSerial(const DetectedCamera& c) {
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

void GPhotoCamera::Impl::ReadIdentity() {
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

void GPhotoCamera::Impl::Close(bool lock) {
  if (!camera_) return;
  std::unique_lock<std::mutex> guard(LibraryMutex(), std::defer_lock);
  if (lock) guard.lock();
  ExitCamera(camera_, context_);
  camera_ = nullptr;
}

void GPhotoCamera::Impl::Reopen(Clock::time_point deadline) {
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

void GPhotoCamera::Impl::EnsureOpen(Clock::time_point deadline) {
  if (!camera_ || needs_reconnect_) Reopen(deadline);
}

std::string GPhotoCamera::Impl::Where() const {
  return "camera " + (serial_.empty() ? std::string() : serial_ + " on ") +
         (current_port_.empty() ? options_.port : current_port_);
}

void GPhotoCamera::Impl::Work() {
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

// ---- the public calls ------------------------------------------------------------------------

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
