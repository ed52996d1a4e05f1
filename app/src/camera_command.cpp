#include "camera_command.h"

#include <memory>

#include <chrono>
#include <cmath>
#include <csignal>
#include <iomanip>
#include <mutex>
#include <numbers>
#include <thread>

#include "carousel/core/error.h"
#include "carousel/rig/gphoto_camera.h"
#include "carousel/rig/usb_devices.h"
#include "carousel/sim/ptpip_camera.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/studio/defaults.h"
#include "carousel/studio/sim_capture.h"
#include "command.h"

namespace carousel::app {
namespace {

volatile std::sig_atomic_t g_stop = 0;
extern "C" void OnSimCameraStop(int) { g_stop = 1; }

std::chrono::milliseconds Millis(double seconds) {
  return std::chrono::milliseconds(static_cast<long long>(seconds * 1000));
}

void PrintDevice(const rig::UsbDevice& d, std::ostream& out) {
  out << (d.kind == rig::UsbDeviceKind::kCamera ? "camera " : "serial ") << d.ids() << " "
      << d.vendor << " " << d.description << " on port " << d.port_path;
  if (d.kind == rig::UsbDeviceKind::kCamera) out << " (" << d.gphoto_port() << ")";
}

int List(std::ostream& out) {
  out << rig::GPhotoVersion() << '\n';
  const std::vector<rig::DetectedCamera> cameras = rig::DetectGPhotoCameras();
  out << "cameras (libgphoto2): " << cameras.size() << '\n';
  for (const rig::DetectedCamera& c : cameras) out << "  " << c.model << " on " << c.port << '\n';
  try {
    const std::vector<rig::UsbDevice> devices = rig::ListUsbDevices();
    out << "USB devices (libusb): " << devices.size() << '\n';
    for (const rig::UsbDevice& d : devices) {
      out << "  ";
      PrintDevice(d, out);
      out << '\n';
    }
  } catch (const DeviceError& e) {
    out << "USB devices (libusb): " << e.what() << '\n';
  }
  out << "network cameras are not detected: name them, e.g. --port "
         "ptpip:192.168.1.20:15740:15740\n";
  return 0;
}

// Cameras and serial adapters arriving and leaving, as the studio sees them (hotplug events,
// or listing the bus every second where libusb has no hotplug).
int Watch(double seconds, std::ostream& out) {
  std::mutex mutex;
  rig::UsbMonitor monitor([&](const rig::UsbDevice& device, bool arrived) {
    std::lock_guard<std::mutex> lock(mutex);
    out << (arrived ? "arrived: " : "left: ");
    PrintDevice(device, out);
    out << std::endl;
  });
  {
    std::lock_guard<std::mutex> lock(mutex);
    switch (monitor.mode()) {
      case rig::UsbMonitorMode::kHotplug:
        out << "watching USB through libusb hotplug events";
        break;
      case rig::UsbMonitorMode::kPolling:
        out << "watching USB by listing the bus every second (" << monitor.reason() << ")";
        break;
      case rig::UsbMonitorMode::kUnavailable:
        out << "USB cannot be watched here: " << monitor.reason() << std::endl;
        return 0;
    }
    out << "; " << monitor.initial().size() << " camera(s) and serial adapter(s) present"
        << std::endl;
    for (const rig::UsbDevice& d : monitor.initial()) {
      out << "  ";
      PrintDevice(d, out);
      out << '\n';
    }
  }
  g_stop = 0;
  auto previous_int = std::signal(SIGINT, OnSimCameraStop);
  auto previous_term = std::signal(SIGTERM, OnSimCameraStop);
  const auto end = std::chrono::steady_clock::now() + Millis(seconds);
  while (!g_stop && (seconds <= 0 || std::chrono::steady_clock::now() < end)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  std::signal(SIGINT, previous_int);
  std::signal(SIGTERM, previous_term);
  return 0;
}

}  // namespace

int RunCamera(const CameraArgs& args, std::ostream& out, std::ostream& err) {
  if (args.action == "list") return List(out);
  if (args.action == "watch") return Watch(args.seconds, out);
  CAROUSEL_THROW_IF(
      args.action != "summary" && args.action != "config" && args.action != "capture",
      InvalidArgument,
      "unknown camera action '" << args.action << "' (list, watch, summary, config or capture)");
  CAROUSEL_THROW_IF(args.count < 1, InvalidArgument, "--count must be >= 1");
  rig::GPhotoCameraOptions options;
  options.port = args.port;
  options.model = args.model;
  options.connect_timeout = Millis(args.timeout_s);
  rig::GPhotoCamera camera(options);
  const auto timeout = Millis(args.timeout_s);
  const rig::CameraInfo info = camera.Identify();
  if (args.action == "summary") {
    out << info.manufacturer << " " << info.model << ", serial " << info.serial << ", on "
        << info.port << " (" << info.driver << ")\n";
    for (const auto& [name, value] : camera.Settings(timeout)) {
      out << "  " << name << " = " << value << '\n';
    }
    out << camera.Summary(timeout);
    return 0;
  }
  if (args.action == "config") {
    for (const std::string& assignment : args.set) {
      const std::size_t eq = assignment.find('=');
      CAROUSEL_THROW_IF(eq == std::string::npos || eq == 0, InvalidArgument,
                        "--set wants NAME=VALUE, not '" << assignment << "'");
      const std::string name = assignment.substr(0, eq);
      const std::string value = assignment.substr(eq + 1);
      if (name == rig::kSettingIso || name == rig::kSettingAperture ||
          name == rig::kSettingShutterSpeed || name == rig::kSettingWhiteBalance ||
          name == rig::kSettingImageFormat || name == rig::kSettingCaptureTarget) {
        camera.SetSetting(name, value, timeout);
      } else {
        camera.SetConfiguration(name, value, timeout);
      }
      out << "set " << name << " = " << value << '\n';
    }
    std::map<std::string, std::vector<std::string>> choices;
    for (const auto& [path, value] : camera.Configuration(timeout, &choices)) {
      out << path << " = " << value;
      const auto it = choices.find(path);
      if (it != choices.end() && !it->second.empty()) {
        const std::vector<std::string>& c = it->second;
        out << "  [";
        if (c.size() <= 12) {
          for (std::size_t i = 0; i < c.size(); ++i) out << (i ? ", " : "") << c[i];
        } else {
          out << c[0] << ", " << c[1] << ", ..., " << c.back() << "; " << c.size() << " values";
        }
        out << "]";
      }
      out << '\n';
    }
    return 0;
  }
  // capture
  std::filesystem::create_directories(args.out);
  for (int i = 0; i < args.count; ++i) {
    const auto start = std::chrono::steady_clock::now();
    const rig::CapturedPhoto photo = camera.Capture(timeout);
    const auto captured = std::chrono::steady_clock::now();
    const std::string name = photo.camera_path.substr(photo.camera_path.find_last_of('/') + 1);
    const std::filesystem::path destination = args.out / name;
    camera.Download(photo, destination, args.delete_after, timeout);
    const auto done = std::chrono::steady_clock::now();
    out << destination.string() << "  " << photo.size_bytes << " bytes, capture "
        << std::chrono::duration_cast<std::chrono::milliseconds>(captured - start).count()
        << " ms, download "
        << std::chrono::duration_cast<std::chrono::milliseconds>(done - captured).count()
        << " ms\n";
  }
  const rig::GPhotoCounters counters = camera.Counters();
  if (counters.busy_retries || counters.download_retries || counters.reconnects) {
    err << "camera " << info.serial << ": " << counters.busy_retries << " busy retries, "
        << counters.download_retries << " download retries, " << counters.reconnects
        << " reconnects\n";
  }
  return 0;
}

int RunSimCamera(const SimCameraArgs& args, std::ostream& out, std::ostream& /*err*/) {
  CAROUSEL_THROW_IF(args.port < 0 || args.port > 65535, InvalidArgument, "--port must be 0..65535");
  sim::PtpIpEvents events = sim::PtpIpEvents::kAll;
  if (args.events == "added-only") {
    events = sim::PtpIpEvents::kAddedOnly;
  } else if (args.events == "complete-only") {
    events = sim::PtpIpEvents::kCompleteOnly;
  } else if (args.events == "none") {
    events = sim::PtpIpEvents::kNone;
  } else {
    CAROUSEL_THROW_IF(args.events != "all", InvalidArgument,
                      "--events must be all, added-only, complete-only or none");
  }
  sim::SimRigOptions rig;
  rig.elevations_deg = {args.elevation_deg};
  studio::ParseImageSize(args.size, "size", &rig.width, &rig.height);
  rig.Validate();
  auto scene =
      std::make_shared<sim::Scene>(sim::LoadScene(studio::ResolveScene(args.scene, args.data_dir)));
  sim::PlaceOnTurntable(*scene, {});
  auto table = std::make_shared<sim::SimTurntable>(sim::SimTurntableOptions{.time_scale = 0.0});
  auto sim_camera =
      std::make_shared<sim::SimCamera>(scene, sim::MakeSimRig(rig, scene->Bounds()).front(), table,
                                       sim::SimCameraOptions{.serial = args.serial});
  const double turn_rad = args.turn_deg * std::numbers::pi / 180.0;
  auto shots = std::make_shared<int>(0);
  sim::PtpIpCameraOptions options;
  options.serial = args.serial;
  options.port = static_cast<std::uint16_t>(args.port);
  options.capture_delay = std::chrono::milliseconds(args.capture_delay_ms);
  sim::PtpIpCamera emulator(
      [sim_camera, table, turn_rad, shots](const std::map<std::string, std::string>& settings) {
        // Each photo at the next table angle when --turn-deg is set.
        table->StartMoveTo(turn_rad * (*shots)++);
        table->WaitUntilStopped(std::chrono::seconds(1));
        for (const auto& [name, value] : settings) {
          sim_camera->SetSetting(name, value, std::chrono::milliseconds(0));
        }
        return sim_camera->Shoot();
      },
      options);
  emulator.SetBusy(args.busy);
  emulator.SetEvents(events);
  if (args.drop_after_bytes > 0) emulator.DropDuringDownloads(args.drop_after_bytes, 1 << 30);
  emulator.SetDownloadDelay(std::chrono::milliseconds(args.download_delay_ms));
  out << "PTP/IP camera " << args.serial << " (" << args.scene << ", " << rig.width << "x"
      << rig.height << ") listening: --port " << emulator.gphoto_port()
      << " --camera \"PTP/IP Camera\"" << std::endl;
  g_stop = 0;
  auto previous_int = std::signal(SIGINT, OnSimCameraStop);
  auto previous_term = std::signal(SIGTERM, OnSimCameraStop);
  const auto end = std::chrono::steady_clock::now() + Millis(args.seconds);
  while (!g_stop && (args.seconds <= 0 || std::chrono::steady_clock::now() < end)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  std::signal(SIGINT, previous_int);
  std::signal(SIGTERM, previous_term);
  const sim::PtpIpCounters c = emulator.Counters();
  out << "served " << c.captures << " captures, " << c.bytes_served << " bytes in " << c.sessions
      << " sessions\n";
  return 0;
}

void AddCameraCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<CameraArgs>();
  command.add_option("action", args->action, "list, watch, summary, config or capture")->required();
  command.add_option("--port", args->port,
                     "libgphoto2 port: usb:BUS,DEV or ptpip:HOST:PORT:PORT (default: the only "
                     "camera found)");
  command.add_option("--model", args->model,
                     "libgphoto2 model (default: detected; \"PTP/IP Camera\" for ptpip:)");
  command.add_option("--camera", args->model, "same as --model (gphoto2's name)");
  command.add_option("--set", args->set,
                     "config: NAME=VALUE, e.g. iso=400, aperture=f/8 (repeatable)");
  command.add_option("--out", args->out, "capture: folder for the photos")->capture_default_str();
  command.add_option("--count", args->count, "capture: photos to take")->capture_default_str();
  command.add_flag("--delete", args->delete_after,
                   "capture: delete each photo from the camera once saved");
  command.add_option("--seconds", args->seconds, "watch: how long to watch, 0 = until Ctrl-C");
  command.add_option("--timeout", args->timeout_s, "per operation, seconds")->capture_default_str();
  dispatch.On(&command, [args](Io& io) { return RunCamera(*args, io.out, io.err); });
}

void AddSimCameraCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<SimCameraArgs>();
  args->data_dir = studio::DefaultDataDir();
  command.add_option("--port", args->port, "TCP port (0: any free)")->capture_default_str();
  command.add_option("--scene", args->scene, "shoe, bottle, avocado, duck or a file")
      ->capture_default_str();
  command.add_option("--data", args->data_dir, "shared test data folder");
  command.add_option("--size", args->size, "photo size WxH")->capture_default_str();
  command.add_option("--elevation", args->elevation_deg, "camera elevation, deg")
      ->capture_default_str();
  command.add_option("--serial", args->serial, "serial number")->capture_default_str();
  command.add_option("--turn-deg", args->turn_deg, "turn the table this far after every capture")
      ->capture_default_str();
  command
      .add_option("--capture-delay", args->capture_delay_ms,
                  "ms from the trigger to the new-photo event")
      ->capture_default_str();
  command.add_option("--busy", args->busy, "fault: the first N captures answer Device Busy");
  command.add_option("--events", args->events, "fault: all, added-only, complete-only or none")
      ->capture_default_str();
  command.add_option("--drop-after", args->drop_after_bytes,
                     "fault: drop the connection this many bytes into every download");
  command.add_option("--download-delay", args->download_delay_ms,
                     "fault: ms before each 256 KiB chunk of a download (slow link)");
  command.add_option("--seconds", args->seconds, "run time, 0 = until Ctrl-C")
      ->capture_default_str();
  dispatch.On(&command, [args](Io& io) { return RunSimCamera(*args, io.out, io.err); });
}

}  // namespace carousel::app
