#include "carousel/sim/ptpip_camera.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <deque>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/rig/camera.h"
#include "carousel/sim/sim_rig.h"

namespace carousel::sim {
namespace {

using Clock = std::chrono::steady_clock;

// PTP/IP packet types (rig-notes 1.2).
enum PacketType : std::uint32_t {
  kInitCommandRequest = 1,
  kInitCommandAck = 2,
  kInitEventRequest = 3,
  kInitEventAck = 4,
  kCmdRequest = 6,
  kCmdResponse = 7,
  kEvent = 8,
  kStartData = 9,
  kData = 10,
  kEndData = 12,
  kPing = 13,
  kPong = 14,
};

// PTP operation, response and event codes (PIMA 15740).
enum Op : std::uint16_t {
  kGetDeviceInfo = 0x1001,
  kOpenSession = 0x1002,
  kCloseSession = 0x1003,
  kGetStorageIds = 0x1004,
  kGetStorageInfo = 0x1005,
  kGetNumObjects = 0x1006,
  kGetObjectHandles = 0x1007,
  kGetObjectInfo = 0x1008,
  kGetObject = 0x1009,
  kDeleteObject = 0x100B,
  kInitiateCapture = 0x100E,
  kGetDevicePropDesc = 0x1014,
  kGetDevicePropValue = 0x1015,
  kSetDevicePropValue = 0x1016,
  kGetPartialObject = 0x101B,
  kGetStreamInfo = 0x1024,  // PTP 1.1 streams: libgphoto2's live view for generic cameras
  kGetStream = 0x1025,
};

enum Response : std::uint16_t {
  kOk = 0x2001,
  kGeneralError = 0x2002,
  kSessionNotOpen = 0x2003,
  kOperationNotSupported = 0x2005,
  kInvalidStorageId = 0x2008,
  kInvalidObjectHandle = 0x2009,
  kDevicePropNotSupported = 0x200A,
  kObjectWriteProtected = 0x200D,
  kAccessDenied = 0x200F,
  kDeviceBusy = 0x2019,
  kInvalidParentObject = 0x201A,
  kInvalidDevicePropFormat = 0x201B,
  kInvalidDevicePropValue = 0x201C,
  kSessionAlreadyOpen = 0x201E,
};

enum EventCode : std::uint16_t {
  kObjectAdded = 0x4002,
  kCaptureComplete = 0x400D,
};

enum Prop : std::uint16_t {
  kBatteryLevel = 0x5001,
  kCompressionSetting = 0x5004,
  kWhiteBalance = 0x5005,
  kFNumber = 0x5007,
  kExposureTime = 0x500D,
  kExposureIndex = 0x500F,
  kSupportedStreams = 0x5020,
  kEnabledStreams = 0x5021,
};

constexpr std::uint32_t kStorageId = 0x00010001;
constexpr std::uint32_t kDcimHandle = 1;
constexpr std::uint32_t kFolderHandle = 2;
constexpr std::uint32_t kFirstPhotoHandle = 3;
constexpr std::uint16_t kFormatAssociation = 0x3001;
constexpr std::uint16_t kFormatJpeg = 0x3801;
constexpr std::size_t kDataChunk = 256 * 1024;
constexpr std::uint32_t kMaxPacket = 64u << 20;

// A property: PTP data type, current value, allowed values (empty: range 0..100).
struct Property {
  std::uint16_t type = 0x0004;  // UINT16
  bool writable = true;
  std::uint32_t value = 0;
  std::uint32_t default_value = 0;
  std::vector<std::uint32_t> values;
};

// Little-endian PTP dataset writer.
class Writer {
 public:
  void U8(std::uint32_t v) { bytes_.push_back(static_cast<std::uint8_t>(v)); }
  void U16(std::uint32_t v) {
    U8(v & 0xFF);
    U8((v >> 8) & 0xFF);
  }
  void U32(std::uint32_t v) {
    U16(v & 0xFFFF);
    U16(v >> 16);
  }
  void U64(std::uint64_t v) {
    U32(static_cast<std::uint32_t>(v));
    U32(static_cast<std::uint32_t>(v >> 32));
  }
  // PTP string: u8 character count including the NUL, then UCS-2LE (empty: a single 0).
  void Str(const std::string& s) {
    if (s.empty()) {
      U8(0);
      return;
    }
    const std::size_t n = std::min<std::size_t>(s.size(), 254);
    U8(static_cast<std::uint32_t>(n + 1));
    for (std::size_t i = 0; i < n; ++i) U16(static_cast<unsigned char>(s[i]));
    U16(0);
  }
  void Array16(const std::vector<std::uint16_t>& values) {
    U32(static_cast<std::uint32_t>(values.size()));
    for (const std::uint16_t v : values) U16(v);
  }
  void Array32(const std::vector<std::uint32_t>& values) {
    U32(static_cast<std::uint32_t>(values.size()));
    for (const std::uint32_t v : values) U32(v);
  }
  // A value of PTP data type `type` (UINT8/16/32).
  void Value(std::uint16_t type, std::uint32_t v) {
    if (type == 0x0002) {
      U8(v);
    } else if (type == 0x0004) {
      U16(v);
    } else {
      U32(v);
    }
  }
  void Bytes(const std::uint8_t* data, std::size_t n) {
    bytes_.insert(bytes_.end(), data, data + n);
  }
  std::vector<std::uint8_t>& bytes() { return bytes_; }

 private:
  std::vector<std::uint8_t> bytes_;
};

std::uint32_t Le32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
std::uint16_t Le16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }

std::string FormatAperture(std::uint32_t v) {
  std::ostringstream out;
  out << "f/" << v / 100.0;
  return out.str();
}

std::string FormatShutter(std::uint32_t tenths_of_ms) {
  const double seconds = tenths_of_ms / 10000.0;
  std::ostringstream out;
  if (seconds >= 1.0) {
    out << seconds;
  } else {
    out << "1/" << std::lround(1.0 / seconds);
  }
  return out.str();
}

std::string WhiteBalanceName(std::uint32_t v) {
  switch (v) {
    case 2:
      return "auto";
    case 4:
      return "daylight";
    case 5:
      return "fluorescent";
    case 6:
      return "tungsten";
    case 7:
      return "flash";
    default:
      return "manual";
  }
}

struct Packet {
  std::uint32_t type = 0;
  std::vector<std::uint8_t> payload;
};

struct Command {
  std::uint16_t code = 0;
  std::uint32_t tid = 0;
  std::vector<std::uint32_t> params;
  std::vector<std::uint8_t> data;  // host-to-device data phase
};

struct PendingEvent {
  Clock::time_point due;
  std::uint16_t code = 0;
  std::uint32_t tid = 0;
  std::uint32_t param = 0;
};

// The connection is gone (peer closed, error, or a drop on purpose).
struct ConnectionLost {};

void SetTimeouts(int fd, int seconds) {
  timeval tv{seconds, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  const int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
}

void ReadExact(int fd, std::uint8_t* data, std::size_t n) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t r = ::recv(fd, data + done, n - done, 0);
    if (r > 0) {
      done += static_cast<std::size_t>(r);
    } else if (r < 0 && errno == EINTR) {
      continue;
    } else {
      throw ConnectionLost{};
    }
  }
}

Packet ReadPacket(int fd) {
  std::uint8_t header[8];
  ReadExact(fd, header, sizeof header);
  const std::uint32_t length = Le32(header);
  if (length < 8 || length > kMaxPacket) throw ConnectionLost{};
  Packet packet;
  packet.type = Le32(header + 4);
  packet.payload.resize(length - 8);
  if (!packet.payload.empty()) ReadExact(fd, packet.payload.data(), packet.payload.size());
  return packet;
}

void WriteAll(int fd, const std::uint8_t* data, std::size_t n) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t w = ::send(fd, data + done, n - done, MSG_NOSIGNAL);
    if (w > 0) {
      done += static_cast<std::size_t>(w);
    } else if (w < 0 && errno == EINTR) {
      continue;
    } else {
      throw ConnectionLost{};
    }
  }
}

void WritePacket(int fd, std::uint32_t type, const std::vector<std::uint8_t>& payload) {
  Writer w;
  w.U32(static_cast<std::uint32_t>(payload.size() + 8));
  w.U32(type);
  w.Bytes(payload.data(), payload.size());
  WriteAll(fd, w.bytes().data(), w.bytes().size());
}

}  // namespace

void PtpIpCameraOptions::Validate() const {
  CAROUSEL_THROW_IF(serial.empty() || model.empty(), InvalidArgument,
                    "PTP/IP emulator: model and serial must not be empty");
  CAROUSEL_THROW_IF(capture_delay.count() < 0, InvalidArgument,
                    "PTP/IP emulator: capture delay must be >= 0");
}

class PtpIpCamera::Impl {
 public:
  Impl(PtpIpShutter shutter, PtpIpCameraOptions options,
       std::function<std::vector<std::uint8_t>()> preview)
      : shutter_(std::move(shutter)), preview_(std::move(preview)), options_(std::move(options)) {
    options_.Validate();
    CAROUSEL_THROW_IF(!shutter_, InvalidArgument, "PTP/IP emulator needs a shutter");
    capture_delay_ = options_.capture_delay;
    properties_[kBatteryLevel] = {0x0002, false, 100, 100, {}};
    properties_[kWhiteBalance] = {0x0004, true, 4, 4, {2, 4, 5, 6, 7}};
    properties_[kCompressionSetting] = {0x0002, true, 2, 2, {0, 1, 2}};  // JPEG basic/normal/fine
    properties_[kFNumber] = {0x0004, true, 800, 800, {280, 400, 560, 800, 1100, 1600, 2200}};
    properties_[kExposureTime] = {
        0x0006, true, 80, 80, {10000, 5000, 2500, 1250, 666, 333, 166, 80, 40, 20, 10}};
    properties_[kExposureIndex] = {0x0004, true, 100, 100, {100, 200, 400, 800, 1600, 3200, 6400}};
    properties_[kSupportedStreams] = {0x0006, false, 1, 1, {1}};  // bit 0: video
    properties_[kEnabledStreams] = {0x0006, true, 0, 0, {0, 1}};

    const std::string where = options_.bind_address + ":" + std::to_string(options_.port);
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (listen_fd_ < 0) throw DeviceError("ptpip:" + where, std::strerror(errno));
    const int one = 1;
    ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(options_.port);
    if (::inet_pton(AF_INET, options_.bind_address.c_str(), &address.sin_addr) != 1) {
      ::close(listen_fd_);
      throw InvalidArgument("PTP/IP emulator: '" + options_.bind_address +
                            "' is not an IPv4 address");
    }
    if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0 ||
        ::listen(listen_fd_, 4) != 0) {
      const std::string reason = std::strerror(errno);
      ::close(listen_fd_);
      throw DeviceError("ptpip:" + where, "cannot listen: " + reason);
    }
    socklen_t length = sizeof address;
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&address), &length);
    port_ = ntohs(address.sin_port);
    wake_fd_ = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    thread_ = std::thread([this] { Serve(); });
  }

  ~Impl() {
    stopping_ = true;
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t w = ::write(wake_fd_, &one, sizeof one);
    thread_.join();
    CloseSession();
    ::close(listen_fd_);
    ::close(wake_fd_);
  }

  std::uint16_t port() const { return port_; }
  std::string Address() const { return options_.bind_address; }

  void SetBusy(int count) {
    std::lock_guard<std::mutex> lock(mutex_);
    busy_ = std::max(0, count);
  }
  void SetEvents(PtpIpEvents events) {
    std::lock_guard<std::mutex> lock(mutex_);
    events_ = events;
  }
  void SetCaptureDelay(std::chrono::milliseconds delay) {
    std::lock_guard<std::mutex> lock(mutex_);
    capture_delay_ = std::max(delay, std::chrono::milliseconds(0));
  }
  void SetDownloadDelay(std::chrono::milliseconds per_chunk) {
    std::lock_guard<std::mutex> lock(mutex_);
    download_delay_ = std::max(per_chunk, std::chrono::milliseconds(0));
  }
  void ReleaseShutter() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      external_releases_.push_back(Clock::now());
      ++counters_.external_releases;
    }
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t w = ::write(wake_fd_, &one, sizeof one);
  }

  void DropDuringDownloads(std::uint64_t after_bytes, int count) {
    std::lock_guard<std::mutex> lock(mutex_);
    drop_after_bytes_ = after_bytes;
    drops_left_ = std::max(0, count);
    if (drops_left_ > 0) {
      drop_after_ = after_bytes;
    } else {
      drop_after_.reset();
    }
  }
  std::vector<PtpIpPhoto> Photos() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return photos_;
  }
  PtpIpCounters Counters() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return counters_;
  }
  std::map<std::uint16_t, std::uint32_t> PropertyValues() const {
    std::lock_guard<std::mutex> lock(mutex_);
    std::map<std::uint16_t, std::uint32_t> values;
    for (const auto& [code, p] : properties_) values[code] = p.value;
    return values;
  }

 private:
  // ---- connection handling (the server thread only) ----
  void Serve() {
    while (!stopping_) {
      std::vector<pollfd> fds = {{listen_fd_, POLLIN, 0}, {wake_fd_, POLLIN, 0}};
      if (cmd_fd_ >= 0) fds.push_back({cmd_fd_, POLLIN, 0});
      if (event_fd_ >= 0) fds.push_back({event_fd_, POLLIN, 0});
      int timeout_ms = -1;
      if (!pending_events_.empty()) {
        const auto wait = std::chrono::ceil<std::chrono::milliseconds>(pending_events_.front().due -
                                                                       Clock::now());
        timeout_ms = static_cast<int>(std::clamp<std::int64_t>(wait.count(), 0, 60000));
      }
      const int ready = ::poll(fds.data(), fds.size(), timeout_ms);
      if (ready < 0 && errno != EINTR) break;
      if (stopping_) break;
      try {
        SendDueEvents();
        for (const pollfd& p : fds) {
          if (p.revents == 0) continue;
          if (p.fd == wake_fd_) {
            std::uint64_t count = 0;
            [[maybe_unused]] const ssize_t r = ::read(wake_fd_, &count, sizeof count);
            TakeExternalReleases();
          } else if (p.fd == listen_fd_) {
            Accept();
          } else if (p.fd == cmd_fd_ && cmd_fd_ >= 0) {
            HandleCommand(ReadPacket(cmd_fd_));
          } else if (p.fd == event_fd_ && event_fd_ >= 0) {
            // The client never sends on the event socket except to close it.
            std::uint8_t byte = 0;
            if (::recv(event_fd_, &byte, 1, MSG_DONTWAIT) <= 0) throw ConnectionLost{};
          }
        }
      } catch (const ConnectionLost&) {
        CloseSession();
      }
    }
  }

  void Accept() {
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) return;
    SetTimeouts(fd, 5);
    try {
      const Packet init = ReadPacket(fd);
      if (init.type == kInitCommandRequest) {
        // A new client replaces whatever session was left (a camera that lost its client).
        CloseSession();
        cmd_fd_ = fd;
        ++connection_number_;
        Writer ack;
        ack.U32(connection_number_);
        for (std::uint8_t i = 0; i < 16; ++i) ack.U8(0x10 + i);  // our GUID
        const std::string name = options_.model;
        for (const char c : name) ack.U16(static_cast<unsigned char>(c));
        ack.U16(0);
        ack.U32(0x00010000);  // version 1.0
        WritePacket(fd, kInitCommandAck, ack.bytes());
        std::lock_guard<std::mutex> lock(mutex_);
        ++counters_.connections;
      } else if (init.type == kInitEventRequest && cmd_fd_ >= 0 && init.payload.size() >= 4 &&
                 Le32(init.payload.data()) == connection_number_) {
        if (event_fd_ >= 0) ::close(event_fd_);
        event_fd_ = fd;
        WritePacket(fd, kInitEventAck, {});
      } else {
        Writer fail;
        fail.U32(1);  // rejected
        WritePacket(fd, 5, fail.bytes());
        ::close(fd);
      }
    } catch (const ConnectionLost&) {
      if (fd == cmd_fd_ || fd == event_fd_) {
        CloseSession();
      } else {
        ::close(fd);
      }
    }
  }

  // Photos released from outside (the remote socket) since the last look.
  void TakeExternalReleases() {
    std::vector<Clock::time_point> releases;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      releases.swap(external_releases_);
    }
    for (const Clock::time_point at : releases) TakePhoto(0, at);
  }

  void CloseSession() {
    if (cmd_fd_ >= 0) ::close(cmd_fd_);
    if (event_fd_ >= 0) ::close(event_fd_);
    cmd_fd_ = event_fd_ = -1;
    session_open_ = false;
    pending_events_.clear();
  }

  // Closes both sockets on purpose (a fault).
  [[noreturn]] void Drop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      ++counters_.drops;
    }
    CAROUSEL_LOG_DEBUG("PTP/IP emulator " << options_.serial << ": dropping the connection");
    throw ConnectionLost{};
  }

  void SendDueEvents() {
    while (!pending_events_.empty() && pending_events_.front().due <= Clock::now()) {
      const PendingEvent e = pending_events_.front();
      pending_events_.pop_front();
      if (event_fd_ < 0) continue;
      Writer w;
      w.U16(e.code);
      w.U32(e.tid);
      w.U32(e.param);
      WritePacket(event_fd_, kEvent, w.bytes());
    }
  }

  void HandleCommand(const Packet& packet) {
    if (packet.type == kPing) {
      WritePacket(cmd_fd_, kPong, {});
      return;
    }
    if (packet.type != kCmdRequest || packet.payload.size() < 10) return;
    Command command;
    const std::uint32_t dataphase = Le32(packet.payload.data());
    command.code = Le16(packet.payload.data() + 4);
    command.tid = Le32(packet.payload.data() + 6);
    for (std::size_t at = 10; at + 4 <= packet.payload.size() && command.params.size() < 5;
         at += 4) {
      command.params.push_back(Le32(packet.payload.data() + at));
    }
    command.params.resize(5, 0);
    if (dataphase == 2) ReadHostData(&command);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      ++counters_.operations;
    }
    Dispatch(command);
  }

  // Start Data, then Data packets up to End Data (host-to-device).
  void ReadHostData(Command* command) {
    while (true) {
      const Packet p = ReadPacket(cmd_fd_);
      if (p.type == kStartData) continue;
      if (p.type != kData && p.type != kEndData) throw ConnectionLost{};
      if (p.payload.size() >= 4) {
        command->data.insert(command->data.end(), p.payload.begin() + 4, p.payload.end());
      }
      if (p.type == kEndData) return;
    }
  }

  void Respond(const Command& command, std::uint16_t code,
               const std::vector<std::uint32_t>& params = {}) {
    Writer w;
    w.U16(code);
    w.U32(command.tid);
    for (const std::uint32_t p : params) w.U32(p);
    WritePacket(cmd_fd_, kCmdResponse, w.bytes());
  }

  // Sends a device-to-host data phase; with `object` set, counts object bytes and applies
  // an armed drop.
  void SendData(const Command& command, const std::uint8_t* data, std::size_t size,
                bool object = false) {
    Writer start;
    start.U32(command.tid);
    start.U64(size);
    WritePacket(cmd_fd_, kStartData, start.bytes());
    std::optional<std::uint64_t> drop_after;
    std::chrono::milliseconds delay{0};
    if (object) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (drop_after_) drop_after = *drop_after_;
      delay = download_delay_;
    }
    std::size_t sent = 0;
    do {
      if (delay.count() > 0) std::this_thread::sleep_for(delay);  // a slow link
      std::size_t n = std::min(kDataChunk, size - sent);
      const bool last = sent + n == size;
      if (drop_after && sent + n > *drop_after) {
        n = static_cast<std::size_t>(*drop_after - std::min<std::uint64_t>(*drop_after, sent));
        Writer w;
        w.U32(command.tid);
        w.Bytes(data + sent, n);
        WritePacket(cmd_fd_, kData, w.bytes());
        {
          std::lock_guard<std::mutex> lock(mutex_);
          drop_after_.reset();
          if (--drops_left_ > 0) drop_after_ = drop_after_bytes_;
          counters_.bytes_served += n;
        }
        Drop();
      }
      Writer w;
      w.U32(command.tid);
      w.Bytes(data + sent, n);
      WritePacket(cmd_fd_, last ? kEndData : kData, w.bytes());
      sent += n;
    } while (sent < size);
    if (object) {
      std::lock_guard<std::mutex> lock(mutex_);
      counters_.bytes_served += size;
      if (drop_after_) *drop_after_ = *drop_after_ > size ? *drop_after_ - size : 0;
    }
  }
  void SendData(const Command& command, Writer& w) {
    SendData(command, w.bytes().data(), w.bytes().size());
  }

  // ---- the object store ----
  // Photos not deleted, by handle (the caller holds mutex_).
  const PtpIpPhoto* FindPhoto(std::uint32_t handle) const {
    for (const PtpIpPhoto& p : photos_) {
      if (p.handle == handle && !p.deleted) return &p;
    }
    return nullptr;
  }
  static std::uint32_t ParentOf(std::uint32_t handle) {
    if (handle == kDcimHandle) return 0;
    if (handle == kFolderHandle) return kDcimHandle;
    return kFolderHandle;
  }
  std::vector<std::uint32_t> Handles(std::uint32_t format, std::uint32_t parent) const {
    std::vector<std::uint32_t> all = {kDcimHandle, kFolderHandle};
    for (const PtpIpPhoto& p : photos_) {
      if (!p.deleted) all.push_back(p.handle);
    }
    std::vector<std::uint32_t> out;
    for (const std::uint32_t h : all) {
      const std::uint16_t f = h < kFirstPhotoHandle ? kFormatAssociation : kFormatJpeg;
      if (format != 0 && format != f) continue;
      if (parent == 0xFFFFFFFF && ParentOf(h) != 0) continue;
      if (parent != 0 && parent != 0xFFFFFFFF && ParentOf(h) != parent) continue;
      out.push_back(h);
    }
    return out;
  }

  void Dispatch(const Command& c) {
    if (c.code == kGetDeviceInfo) return DeviceInfo(c);
    if (c.code == kOpenSession) {
      if (session_open_) return Respond(c, kSessionAlreadyOpen);
      session_open_ = true;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        ++counters_.sessions;
      }
      return Respond(c, kOk);
    }
    if (!session_open_) return Respond(c, kSessionNotOpen);
    switch (c.code) {
      case kCloseSession:
        session_open_ = false;
        return Respond(c, kOk);
      case kGetStorageIds: {
        Writer w;
        w.Array32({kStorageId});
        SendData(c, w);
        return Respond(c, kOk);
      }
      case kGetStorageInfo: {
        if (c.params[0] != kStorageId) return Respond(c, kInvalidStorageId);
        std::uint64_t used = 0;
        {
          std::lock_guard<std::mutex> lock(mutex_);
          for (const PtpIpPhoto& p : photos_) used += p.deleted ? 0 : p.bytes.size();
        }
        const std::uint64_t capacity = 32ULL << 30;
        Writer w;
        w.U16(4);  // removable RAM (a memory card)
        w.U16(2);  // generic hierarchical
        w.U16(0);  // read-write
        w.U64(capacity);
        w.U64(capacity - std::min(used, capacity));
        w.U32(0xFFFFFFFF);
        w.Str("SD card");
        w.Str("CAROUSEL");
        SendData(c, w);
        return Respond(c, kOk);
      }
      case kGetNumObjects:
      case kGetObjectHandles: {
        if (c.params[0] != kStorageId && c.params[0] != 0xFFFFFFFF) {
          return Respond(c, kInvalidStorageId);
        }
        const std::uint32_t parent = c.params[2];
        std::vector<std::uint32_t> handles;
        {
          std::lock_guard<std::mutex> lock(mutex_);
          if (parent != 0 && parent != 0xFFFFFFFF && parent != kDcimHandle &&
              parent != kFolderHandle) {
            return Respond(c, FindPhoto(parent) ? kInvalidParentObject : kInvalidObjectHandle);
          }
          handles = Handles(c.params[1], parent);
        }
        if (c.code == kGetNumObjects) {
          return Respond(c, kOk, {static_cast<std::uint32_t>(handles.size())});
        }
        Writer w;
        w.Array32(handles);
        SendData(c, w);
        return Respond(c, kOk);
      }
      case kGetObjectInfo:
        return ObjectInfo(c);
      case kGetObject:
      case kGetPartialObject:
        return GetObject(c);
      case kDeleteObject:
        return DeleteObject(c);
      case kInitiateCapture:
        return InitiateCapture(c);
      case kGetDevicePropDesc:
      case kGetDevicePropValue:
        return PropertyDesc(c);
      case kSetDevicePropValue:
        return SetProperty(c);
      case kGetStreamInfo: {
        Writer w;
        w.U64(36);                             // dataset size
        w.U64(1000000);                        // time resolution: microseconds
        for (int i = 0; i < 5; ++i) w.U32(0);  // no frame/packet headers, sizes unbounded
        SendData(c, w);
        return Respond(c, kOk);
      }
      case kGetStream:
        return Stream(c);
      default:
        return Respond(c, kOperationNotSupported);
    }
  }

  void DeviceInfo(const Command& c) {
    Writer w;
    w.U16(100);  // PTP 1.00
    w.U32(0);    // no vendor extension: libgphoto2 takes its generic paths
    w.U16(0);
    w.Str("");
    w.U16(0);
    w.Array16({kGetDeviceInfo, kOpenSession, kCloseSession, kGetStorageIds, kGetStorageInfo,
               kGetNumObjects, kGetObjectHandles, kGetObjectInfo, kGetObject, kDeleteObject,
               kInitiateCapture, kGetDevicePropDesc, kGetDevicePropValue, kSetDevicePropValue,
               kGetPartialObject, kGetStreamInfo, kGetStream});
    w.Array16({kObjectAdded, 0x4003, 0x4006, kCaptureComplete});
    std::vector<std::uint16_t> props;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const auto& [code, p] : properties_) props.push_back(code);
    }
    w.Array16(props);
    w.Array16({kFormatJpeg});
    w.Array16({kFormatJpeg, kFormatAssociation});
    w.Str(options_.manufacturer);
    w.Str(options_.model);
    w.Str("1.0");
    w.Str(options_.serial);
    SendData(c, w);
    Respond(c, kOk);
  }

  void ObjectInfo(const Command& c) {
    const std::uint32_t h = c.params[0];
    Writer w;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const PtpIpPhoto* photo = FindPhoto(h);
      if (!photo && h != kDcimHandle && h != kFolderHandle) {
        return Respond(c, kInvalidObjectHandle);
      }
      w.U32(kStorageId);
      w.U16(photo ? kFormatJpeg : kFormatAssociation);
      w.U16(0);  // no protection
      w.U32(photo ? static_cast<std::uint32_t>(photo->bytes.size()) : 0);
      w.U16(0);  // no thumbnail
      w.U32(0);
      w.U32(0);
      w.U32(0);
      w.U32(0);  // image width and height: not known without decoding
      w.U32(0);
      w.U32(photo ? 24 : 0);
      w.U32(ParentOf(h));
      w.U16(photo ? 0 : 1);  // folders: generic folder association
      w.U32(0);
      w.U32(0);
      w.Str(photo ? photo->name : (h == kDcimHandle ? "DCIM" : "100CAROU"));
      w.Str("20261201T120000");
      w.Str("20261201T120000");
      w.Str("");
    }
    SendData(c, w);
    Respond(c, kOk);
  }

  void GetObject(const Command& c) {
    std::vector<std::uint8_t> bytes;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const PtpIpPhoto* photo = FindPhoto(c.params[0]);
      if (!photo) return Respond(c, kInvalidObjectHandle);
      bytes = photo->bytes;
    }
    std::size_t offset = 0;
    std::size_t size = bytes.size();
    if (c.code == kGetPartialObject) {
      offset = std::min<std::size_t>(c.params[1], bytes.size());
      size = std::min<std::size_t>(c.params[2], bytes.size() - offset);
    }
    SendData(c, bytes.data() + offset, size, true);
    if (c.code == kGetPartialObject) return Respond(c, kOk, {static_cast<std::uint32_t>(size)});
    Respond(c, kOk);
  }

  void DeleteObject(const Command& c) {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::uint32_t h = c.params[0];
    if (h == 0xFFFFFFFF) {
      for (PtpIpPhoto& p : photos_) p.deleted = true;
      return Respond(c, kOk);
    }
    if (h == kDcimHandle || h == kFolderHandle) return Respond(c, kObjectWriteProtected);
    for (PtpIpPhoto& p : photos_) {
      if (p.handle == h && !p.deleted) {
        p.deleted = true;
        return Respond(c, kOk);
      }
    }
    Respond(c, kInvalidObjectHandle);
  }

  void InitiateCapture(const Command& c) {
    const Clock::time_point arrived = Clock::now();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (busy_ > 0) {
        --busy_;
        ++counters_.busy_answers;
        return Respond(c, kDeviceBusy);
      }
      ++counters_.captures;
    }
    // Answer first, like a camera: the photo appears later, announced by the events.
    Respond(c, kOk);
    TakePhoto(c.tid, arrived);
  }

  // Exposes, stores and announces a photo (InitiateCapture, or a release from outside with
  // transaction id 0).
  void TakePhoto(std::uint32_t tid, Clock::time_point arrived) {
    PtpIpEvents events;
    std::chrono::milliseconds delay;
    std::map<std::string, std::string> settings;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      events = events_;
      delay = capture_delay_;
      settings[rig::kSettingIso] = std::to_string(properties_[kExposureIndex].value);
      settings[rig::kSettingAperture] = FormatAperture(properties_[kFNumber].value);
      settings[rig::kSettingShutterSpeed] = FormatShutter(properties_[kExposureTime].value);
      settings[rig::kSettingWhiteBalance] = WhiteBalanceName(properties_[kWhiteBalance].value);
    }
    PtpIpPhoto photo;
    photo.bytes = shutter_(settings);
    photo.triggered_at = arrived;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const int number = static_cast<int>(photos_.size()) + 1;
      photo.handle = kFirstPhotoHandle + static_cast<std::uint32_t>(photos_.size());
      photo.name = "IMG_" + std::to_string(10000 + number % 10000).substr(1) + ".JPG";
      photos_.push_back(photo);
    }
    const Clock::time_point due = std::max(Clock::now(), arrived + delay);
    if (events == PtpIpEvents::kAll || events == PtpIpEvents::kAddedOnly) {
      pending_events_.push_back({due, kObjectAdded, tid, photo.handle});
    }
    if (events == PtpIpEvents::kAll || events == PtpIpEvents::kCompleteOnly) {
      pending_events_.push_back({due, kCaptureComplete, tid, tid});
    }
  }

  // One live-view frame: a complete JPEG (libgphoto2 hands the data phase over as it is).
  void Stream(const Command& c) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if ((properties_[kEnabledStreams].value & 1) == 0) return Respond(c, kAccessDenied);
      ++counters_.preview_frames;
    }
    std::vector<std::uint8_t> frame =
        preview_ ? preview_() : shutter_(std::map<std::string, std::string>{});
    SendData(c, frame.data(), frame.size());
    Respond(c, kOk);
  }

  void PropertyDesc(const Command& c) {
    Writer w;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const auto it = properties_.find(static_cast<std::uint16_t>(c.params[0]));
      if (it == properties_.end()) return Respond(c, kDevicePropNotSupported);
      const Property& p = it->second;
      if (c.code == kGetDevicePropValue) {
        w.Value(p.type, p.value);
      } else {
        w.U16(it->first);
        w.U16(p.type);
        w.U8(p.writable ? 1 : 0);
        w.Value(p.type, p.default_value);
        w.Value(p.type, p.value);
        if (p.values.empty()) {
          w.U8(1);  // range 0..100 step 1
          w.Value(p.type, 0);
          w.Value(p.type, 100);
          w.Value(p.type, 1);
        } else {
          w.U8(2);  // enumeration
          w.U16(static_cast<std::uint32_t>(p.values.size()));
          for (const std::uint32_t v : p.values) w.Value(p.type, v);
        }
      }
    }
    SendData(c, w);
    Respond(c, kOk);
  }

  void SetProperty(const Command& c) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = properties_.find(static_cast<std::uint16_t>(c.params[0]));
    if (it == properties_.end()) return Respond(c, kDevicePropNotSupported);
    Property& p = it->second;
    if (!p.writable) return Respond(c, kAccessDenied);
    const std::size_t size = p.type == 0x0002 ? 1 : p.type == 0x0004 ? 2 : 4;
    if (c.data.size() != size) return Respond(c, kInvalidDevicePropFormat);
    std::uint32_t v = 0;
    for (std::size_t i = 0; i < size; ++i) v |= static_cast<std::uint32_t>(c.data[i]) << (8 * i);
    if (std::find(p.values.begin(), p.values.end(), v) == p.values.end()) {
      return Respond(c, kInvalidDevicePropValue);
    }
    p.value = v;
    Respond(c, kOk);
  }

  PtpIpShutter shutter_;
  std::function<std::vector<std::uint8_t>()> preview_;  // empty: a full photo per frame
  PtpIpCameraOptions options_;
  std::uint16_t port_ = 0;
  int listen_fd_ = -1;
  int wake_fd_ = -1;
  std::atomic<bool> stopping_{false};
  std::thread thread_;

  // The server thread's own state.
  int cmd_fd_ = -1;
  int event_fd_ = -1;
  std::uint32_t connection_number_ = 0;
  bool session_open_ = false;
  std::deque<PendingEvent> pending_events_;

  // Shared with the API (mutex_).
  mutable std::mutex mutex_;
  std::map<std::uint16_t, Property> properties_;
  std::vector<PtpIpPhoto> photos_;
  PtpIpCounters counters_;
  int busy_ = 0;
  PtpIpEvents events_ = PtpIpEvents::kAll;
  std::chrono::milliseconds capture_delay_{0};
  std::chrono::milliseconds download_delay_{0};
  std::vector<Clock::time_point> external_releases_;  // not yet taken
  std::optional<std::uint64_t> drop_after_;           // object bytes still to serve before the drop
  std::uint64_t drop_after_bytes_ = 0;
  int drops_left_ = 0;
};

PtpIpCamera::PtpIpCamera(PtpIpShutter shutter, PtpIpCameraOptions options)
    : impl_(std::make_unique<Impl>(std::move(shutter), std::move(options), nullptr)) {}

PtpIpCamera::PtpIpCamera(const std::shared_ptr<SimCamera>& camera, PtpIpCameraOptions options) {
  CAROUSEL_THROW_IF(!camera, InvalidArgument, "PTP/IP emulator needs a simulated camera");
  impl_ = std::make_unique<Impl>(
      [camera](const std::map<std::string, std::string>& settings) {
        for (const auto& [name, value] : settings) {
          camera->SetSetting(name, value, std::chrono::milliseconds(0));
        }
        return camera->Shoot();
      },
      std::move(options),
      [camera] {
        std::vector<std::uint8_t> jpeg;
        cv::imencode(".jpg", camera->PreviewFrame(std::chrono::milliseconds(0)), jpeg,
                     {cv::IMWRITE_JPEG_QUALITY, 80});
        return jpeg;
      });
}

PtpIpCamera::~PtpIpCamera() = default;

std::uint16_t PtpIpCamera::port() const { return impl_->port(); }

std::string PtpIpCamera::gphoto_port() const {
  const std::string p = std::to_string(impl_->port());
  return "ptpip:" + impl_->Address() + ":" + p + ":" + p;
}

void PtpIpCamera::SetBusy(int count) { impl_->SetBusy(count); }
void PtpIpCamera::ReleaseShutter() { impl_->ReleaseShutter(); }
void PtpIpCamera::SetEvents(PtpIpEvents events) { impl_->SetEvents(events); }
void PtpIpCamera::SetCaptureDelay(std::chrono::milliseconds delay) {
  impl_->SetCaptureDelay(delay);
}
void PtpIpCamera::SetDownloadDelay(std::chrono::milliseconds per_chunk) {
  impl_->SetDownloadDelay(per_chunk);
}
void PtpIpCamera::DropDuringDownloads(std::uint64_t after_bytes, int count) {
  impl_->DropDuringDownloads(after_bytes, count);
}
std::vector<PtpIpPhoto> PtpIpCamera::Photos() const { return impl_->Photos(); }
PtpIpCounters PtpIpCamera::Counters() const { return impl_->Counters(); }
std::map<std::uint16_t, std::uint32_t> PtpIpCamera::PropertyValues() const {
  return impl_->PropertyValues();
}

}  // namespace carousel::sim
