#include "carousel/rig/usb_devices.h"

#include <libusb-1.0/libusb.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <thread>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"

namespace carousel::rig {
namespace {

struct KnownVendor {
  std::uint16_t id;
  const char* name;
};

// Camera makers (for naming PTP devices).
constexpr KnownVendor kCameraVendors[] = {
    {0x04a9, "Canon"},     {0x04b0, "Nikon"},   {0x054c, "Sony"},       {0x04cb, "Fujifilm"},
    {0x04da, "Panasonic"}, {0x07b4, "Olympus"}, {0x33a2, "OM Digital"}, {0x25fb, "Pentax"},
    {0x1003, "Sigma"},     {0x1a98, "Leica"},   {0x0a17, "Pentax"},
};

struct KnownSerial {
  std::uint16_t vendor;
  std::uint16_t product;  // 0: any product of the vendor
  const char* vendor_name;
  const char* description;
};

// USB-serial bridges and boards the turntable controller may sit behind.
constexpr KnownSerial kSerialAdapters[] = {
    {0x0403, 0x6001, "FTDI", "FT232R USB-serial"},
    {0x0403, 0x6010, "FTDI", "FT2232 USB-serial"},
    {0x0403, 0x6014, "FTDI", "FT232H USB-serial"},
    {0x0403, 0x6015, "FTDI", "FT-X USB-serial"},
    {0x1a86, 0x7523, "QinHeng", "CH340 USB-serial"},
    {0x1a86, 0x5523, "QinHeng", "CH341 USB-serial"},
    {0x1a86, 0x55d4, "QinHeng", "CH9102 USB-serial"},
    {0x10c4, 0xea60, "Silicon Labs", "CP210x USB-serial"},
    {0x10c4, 0xea70, "Silicon Labs", "CP2105 USB-serial"},
    {0x067b, 0x2303, "Prolific", "PL2303 USB-serial"},
    {0x2341, 0x0043, "Arduino", "Arduino Uno"},
    {0x2341, 0x0001, "Arduino", "Arduino Uno"},
    {0x2341, 0x0042, "Arduino", "Arduino Mega 2560"},
    {0x2341, 0x0010, "Arduino", "Arduino Mega 2560"},
    {0x2341, 0x8036, "Arduino", "Arduino Leonardo"},
    {0x2341, 0, "Arduino", "Arduino board"},
    {0x2a03, 0, "Arduino", "Arduino board"},
};

std::string Hex4(std::uint16_t v) {
  char text[8];
  std::snprintf(text, sizeof text, "%04x", v);
  return text;
}

struct Context {
  libusb_context* context = nullptr;
  Context() {
    const int r = libusb_init(&context);
    if (r != 0) {
      context = nullptr;
      throw DeviceError("usb", std::string("libusb cannot reach the USB bus: ") +
                                   libusb_strerror(static_cast<libusb_error>(r)) +
                                   " (no /dev/bus/usb here, or no permission)");
    }
  }
  ~Context() {
    if (context) libusb_exit(context);
  }
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;
};

// Reads one device's descriptors and classifies it; false for devices we do not use.
bool Describe(libusb_device* dev, UsbDevice* out) {
  libusb_device_descriptor descriptor{};
  if (libusb_get_device_descriptor(dev, &descriptor) != 0) return false;
  std::vector<UsbInterfaceClass> interfaces;
  if (descriptor.bDeviceClass != 0) {
    interfaces.push_back(
        {descriptor.bDeviceClass, descriptor.bDeviceSubClass, descriptor.bDeviceProtocol});
  }
  libusb_config_descriptor* config = nullptr;
  if (libusb_get_active_config_descriptor(dev, &config) == 0 ||
      libusb_get_config_descriptor(dev, 0, &config) == 0) {
    for (int i = 0; i < config->bNumInterfaces; ++i) {
      const libusb_interface& interface = config->interface[i];
      for (int a = 0; a < interface.num_altsetting; ++a) {
        const libusb_interface_descriptor& d = interface.altsetting[a];
        interfaces.push_back({d.bInterfaceClass, d.bInterfaceSubClass, d.bInterfaceProtocol});
      }
    }
    libusb_free_config_descriptor(config);
  }
  if (!ClassifyUsbDevice(descriptor.idVendor, descriptor.idProduct, interfaces, out)) {
    return false;
  }
  out->bus = libusb_get_bus_number(dev);
  out->address = libusb_get_device_address(dev);
  std::uint8_t ports[8];
  const int n = libusb_get_port_numbers(dev, ports, sizeof ports);
  out->port_path = std::to_string(out->bus);
  for (int i = 0; i < n; ++i) {
    out->port_path += i == 0 ? '-' : '.';
    out->port_path += std::to_string(ports[i]);
  }
  return true;
}

std::vector<UsbDevice> List(libusb_context* context) {
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(context, &list);
  if (n < 0) {
    throw DeviceError("usb", std::string("cannot list USB devices: ") +
                                 libusb_strerror(static_cast<libusb_error>(n)));
  }
  std::vector<UsbDevice> devices;
  for (ssize_t i = 0; i < n; ++i) {
    UsbDevice d;
    if (Describe(list[i], &d)) devices.push_back(d);
  }
  libusb_free_device_list(list, 1);
  std::sort(devices.begin(), devices.end(), [](const UsbDevice& a, const UsbDevice& b) {
    return std::tie(a.bus, a.address) < std::tie(b.bus, b.address);
  });
  return devices;
}

}  // namespace

std::string UsbDevice::gphoto_port() const {
  char text[32];
  std::snprintf(text, sizeof text, "usb:%03d,%03d", bus, address);
  return text;
}

std::string UsbDevice::ids() const { return Hex4(vendor_id) + ":" + Hex4(product_id); }

bool UsbDevice::operator==(const UsbDevice& other) const {
  return bus == other.bus && address == other.address && vendor_id == other.vendor_id &&
         product_id == other.product_id;
}

bool ClassifyUsbDevice(std::uint16_t vendor_id, std::uint16_t product_id,
                       const std::vector<UsbInterfaceClass>& interfaces, UsbDevice* device) {
  device->vendor_id = vendor_id;
  device->product_id = product_id;
  // A still-image (PTP) interface: class 6, subclass 1, protocol 1.
  const bool ptp = std::any_of(interfaces.begin(), interfaces.end(), [](const auto& c) {
    return c.interface_class == LIBUSB_CLASS_IMAGE && c.subclass == 1 && c.protocol == 1;
  });
  if (ptp) {
    device->kind = UsbDeviceKind::kCamera;
    device->vendor = Hex4(vendor_id);
    for (const KnownVendor& v : kCameraVendors) {
      if (v.id == vendor_id) device->vendor = v.name;
    }
    device->description = "PTP camera";
    return true;
  }
  for (const KnownSerial& s : kSerialAdapters) {
    if (s.vendor == vendor_id && (s.product == product_id || s.product == 0)) {
      device->kind = UsbDeviceKind::kSerialAdapter;
      device->vendor = s.vendor_name;
      device->description = s.description;
      return true;
    }
  }
  // Boards with a native USB-serial (CDC ACM: communications class 2, subclass 2).
  const bool acm = std::any_of(interfaces.begin(), interfaces.end(), [](const auto& c) {
    return c.interface_class == LIBUSB_CLASS_COMM && c.subclass == 2;
  });
  if (acm) {
    device->kind = UsbDeviceKind::kSerialAdapter;
    device->vendor = Hex4(vendor_id);
    device->description = "CDC ACM serial";
    return true;
  }
  return false;
}

std::vector<UsbDevice> ListUsbDevices() {
  Context context;
  return List(context.context);
}

UsbChanges DiffUsbDevices(const std::vector<UsbDevice>& before,
                          const std::vector<UsbDevice>& after) {
  UsbChanges changes;
  for (const UsbDevice& d : after) {
    if (std::find(before.begin(), before.end(), d) == before.end()) changes.arrived.push_back(d);
  }
  for (const UsbDevice& d : before) {
    if (std::find(after.begin(), after.end(), d) == after.end()) changes.left.push_back(d);
  }
  return changes;
}

class UsbMonitor::Impl {
 public:
  Impl(Callback on_change, std::chrono::milliseconds poll_interval)
      : on_change_(std::move(on_change)), poll_interval_(poll_interval) {
    try {
      context_ = std::make_unique<Context>();
      known_ = List(context_->context);
    } catch (const DeviceError& e) {
      context_.reset();
      mode_ = UsbMonitorMode::kUnavailable;
      reason_ = e.what();
      CAROUSEL_LOG_INFO("USB monitor: " << reason_ << "; no device events");
      return;
    }
    initial_ = known_;
    if (libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) &&
        libusb_hotplug_register_callback(
            context_->context,
            static_cast<libusb_hotplug_event>(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED |
                                              LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
            LIBUSB_HOTPLUG_NO_FLAGS, LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY,
            LIBUSB_HOTPLUG_MATCH_ANY, &Impl::OnHotplug, this, &hotplug_) == 0) {
      mode_ = UsbMonitorMode::kHotplug;
    } else {
      mode_ = UsbMonitorMode::kPolling;
      reason_ = "libusb has no hotplug support here; listing the bus every " +
                std::to_string(poll_interval_.count()) + " ms";
    }
    thread_ = std::thread([this] { Run(); });
  }

  ~Impl() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    if (mode_ == UsbMonitorMode::kHotplug) {
      libusb_hotplug_deregister_callback(context_->context, hotplug_);  // wakes the event loop
    }
    if (thread_.joinable()) thread_.join();
  }

  UsbMonitorMode mode_ = UsbMonitorMode::kUnavailable;
  std::string reason_;
  std::vector<UsbDevice> initial_;

 private:
  static int LIBUSB_CALL OnHotplug(libusb_context*, libusb_device*, libusb_hotplug_event,
                                   void* self) {
    // Descriptors are read again, and compared, on the monitor's thread.
    static_cast<Impl*>(self)->changed_ = true;
    return 0;
  }

  void Run() {
    while (true) {
      {
        std::unique_lock<std::mutex> lock(mutex_);
        if (stopping_) return;
        if (mode_ == UsbMonitorMode::kPolling) {
          wake_.wait_for(lock, poll_interval_, [this] { return stopping_; });
          if (stopping_) return;
        }
      }
      if (mode_ == UsbMonitorMode::kHotplug) {
        timeval tv{0, 200000};
        libusb_handle_events_timeout_completed(context_->context, &tv, nullptr);
        if (!changed_.exchange(false)) continue;
      }
      std::vector<UsbDevice> now;
      try {
        now = List(context_->context);
      } catch (const DeviceError& e) {
        CAROUSEL_LOG_WARN("USB monitor: " << e.what());
        continue;
      }
      const UsbChanges changes = DiffUsbDevices(known_, now);
      known_ = std::move(now);
      for (const UsbDevice& d : changes.left) on_change_(d, false);
      for (const UsbDevice& d : changes.arrived) on_change_(d, true);
    }
  }

  Callback on_change_;
  std::chrono::milliseconds poll_interval_;
  std::unique_ptr<Context> context_;
  libusb_hotplug_callback_handle hotplug_ = 0;
  std::vector<UsbDevice> known_;
  std::atomic<bool> changed_{false};
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::thread thread_;
};

UsbMonitor::UsbMonitor(Callback on_change, std::chrono::milliseconds poll_interval)
    : impl_(std::make_unique<Impl>(std::move(on_change), poll_interval)) {}
UsbMonitor::~UsbMonitor() = default;
UsbMonitorMode UsbMonitor::mode() const { return impl_->mode_; }
const std::string& UsbMonitor::reason() const { return impl_->reason_; }
const std::vector<UsbDevice>& UsbMonitor::initial() const { return impl_->initial_; }

}  // namespace carousel::rig
