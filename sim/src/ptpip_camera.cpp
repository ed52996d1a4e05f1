// The PTP/IP camera emulator's server: the listening socket, the command and event
// connections with their Init handshakes, sessions, data phases in both directions, events,
// and the faults tests arm; and the public PtpIpCamera calls.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <opencv2/imgcodecs.hpp>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/sim/sim_rig.h"
#include "ptpip_emulator.h"

namespace carousel::sim {
namespace {

using ptpip::Command;
using ptpip::Packet;
using ptpip::Writer;
using enum ptpip::PacketType;
using enum ptpip::Prop;
using enum ptpip::DataType;

constexpr std::size_t kDataChunk = 256 * 1024;

// The connection is gone (peer closed, error, or a drop on purpose).
struct ConnectionLost {};

void SetTimeouts(int fd, int seconds) {
  timeval tv{seconds, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  const int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
}

// Calls `step(done)`, one recv() or send() from offset `done` returning its result, until `n`
// bytes have gone through, again after EINTR; ConnectionLost when the peer closed or failed.
template <typename Step>
void Transfer(std::size_t n, Step step) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t r = step(done);
    if (r > 0) {
      done += static_cast<std::size_t>(r);
    } else if (r < 0 && errno == EINTR) {
      continue;
    } else {
      throw ConnectionLost{};
    }
  }
}

void ReadExact(int fd, std::uint8_t* data, std::size_t n) {
  Transfer(n, [&](std::size_t done) { return ::recv(fd, data + done, n - done, 0); });
}

void WriteAll(int fd, const std::uint8_t* data, std::size_t n) {
  Transfer(n, [&](std::size_t done) { return ::send(fd, data + done, n - done, MSG_NOSIGNAL); });
}

Packet ReadPacket(int fd) {
  std::uint8_t header[ptpip::kHeaderSize];
  ReadExact(fd, header, sizeof header);
  const std::optional<ptpip::PacketHeader> decoded = ptpip::DecodePacketHeader(header);
  if (!decoded) throw ConnectionLost{};
  Packet packet;
  packet.type = decoded->type;
  packet.payload.resize(decoded->payload_size);
  if (!packet.payload.empty()) ReadExact(fd, packet.payload.data(), packet.payload.size());
  return packet;
}

void WritePacket(int fd, std::uint32_t type, const std::vector<std::uint8_t>& payload) {
  const std::vector<std::uint8_t> packet = ptpip::EncodePacket(type, payload);
  WriteAll(fd, packet.data(), packet.size());
}

}  // namespace

void PtpIpCameraOptions::Validate() const {
  CAROUSEL_THROW_IF(serial.empty() || model.empty(), InvalidArgument,
                    "PTP/IP emulator: model and serial must not be empty");
  CAROUSEL_THROW_IF(capture_delay.count() < 0, InvalidArgument,
                    "PTP/IP emulator: capture delay must be >= 0");
}

PtpIpCamera::Impl::Impl(PtpIpShutter shutter, PtpIpCameraOptions options,
                        std::function<std::vector<std::uint8_t>()> preview)
    : shutter_(std::move(shutter)), preview_(std::move(preview)), options_(std::move(options)) {
  options_.Validate();
  CAROUSEL_THROW_IF(!shutter_, InvalidArgument, "PTP/IP emulator needs a shutter");
  capture_delay_ = options_.capture_delay;
  properties_[kBatteryLevel] = {kUint8, false, 100, 100, {}};
  properties_[kWhiteBalance] = {kUint16, true, 4, 4, {2, 4, 5, 6, 7}};
  properties_[kCompressionSetting] = {kUint8, true, 2, 2, {0, 1, 2}};  // JPEG basic/normal/fine
  properties_[kFNumber] = {kUint16, true, 800, 800, {280, 400, 560, 800, 1100, 1600, 2200}};
  properties_[kExposureTime] = {
      kUint32, true, 80, 80, {10000, 5000, 2500, 1250, 666, 333, 166, 80, 40, 20, 10}};
  properties_[kExposureIndex] = {kUint16, true, 100, 100, {100, 200, 400, 800, 1600, 3200, 6400}};
  properties_[kSupportedStreams] = {kUint32, false, 1, 1, {1}};  // bit 0: video
  properties_[kEnabledStreams] = {kUint32, true, 0, 0, {0, 1}};

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

PtpIpCamera::Impl::~Impl() {
  stopping_ = true;
  const std::uint64_t one = 1;
  [[maybe_unused]] const ssize_t w = ::write(wake_fd_, &one, sizeof one);
  thread_.join();
  CloseSession();
  ::close(listen_fd_);
  ::close(wake_fd_);
}

void PtpIpCamera::Impl::SetBusy(int count) {
  std::lock_guard<std::mutex> lock(mutex_);
  busy_ = std::max(0, count);
}
void PtpIpCamera::Impl::SetEvents(PtpIpEvents events) {
  std::lock_guard<std::mutex> lock(mutex_);
  events_ = events;
}
void PtpIpCamera::Impl::SetCaptureDelay(std::chrono::milliseconds delay) {
  std::lock_guard<std::mutex> lock(mutex_);
  capture_delay_ = std::max(delay, std::chrono::milliseconds(0));
}
void PtpIpCamera::Impl::SetDownloadDelay(std::chrono::milliseconds per_chunk) {
  std::lock_guard<std::mutex> lock(mutex_);
  download_delay_ = std::max(per_chunk, std::chrono::milliseconds(0));
}
void PtpIpCamera::Impl::ReleaseShutter() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    external_releases_.push_back(Clock::now());
    ++counters_.external_releases;
  }
  const std::uint64_t one = 1;
  [[maybe_unused]] const ssize_t w = ::write(wake_fd_, &one, sizeof one);
}

void PtpIpCamera::Impl::DropDuringDownloads(std::uint64_t after_bytes, int count) {
  std::lock_guard<std::mutex> lock(mutex_);
  drop_after_bytes_ = after_bytes;
  drops_left_ = std::max(0, count);
  if (drops_left_ > 0) {
    drop_after_ = after_bytes;
  } else {
    drop_after_.reset();
  }
}
std::vector<PtpIpPhoto> PtpIpCamera::Impl::Photos() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return photos_;
}
PtpIpCounters PtpIpCamera::Impl::Counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return counters_;
}
std::map<std::uint16_t, std::uint32_t> PtpIpCamera::Impl::PropertyValues() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::map<std::uint16_t, std::uint32_t> values;
  for (const auto& [code, p] : properties_) values[code] = p.value;
  return values;
}

// ---- connection handling (the server thread only) ----

void PtpIpCamera::Impl::Serve() {
  while (!stopping_) {
    std::vector<pollfd> fds = {{listen_fd_, POLLIN, 0}, {wake_fd_, POLLIN, 0}};
    if (cmd_fd_ >= 0) fds.push_back({cmd_fd_, POLLIN, 0});
    if (event_fd_ >= 0) fds.push_back({event_fd_, POLLIN, 0});
    int timeout_ms = -1;
    if (!pending_events_.empty()) {
      const auto wait =
          std::chrono::ceil<std::chrono::milliseconds>(pending_events_.front().due - Clock::now());
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

void PtpIpCamera::Impl::Accept() {
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
      WritePacket(fd, kInitCommandAck,
                  ptpip::EncodeInitCommandAck(connection_number_, options_.model));
      std::lock_guard<std::mutex> lock(mutex_);
      ++counters_.connections;
    } else if (cmd_fd_ >= 0 && ptpip::DecodeInitEventRequest(init) == connection_number_) {
      if (event_fd_ >= 0) ::close(event_fd_);
      event_fd_ = fd;
      WritePacket(fd, kInitEventAck, {});
    } else {
      WritePacket(fd, kInitFail, ptpip::EncodeInitFail(1));  // rejected
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

void PtpIpCamera::Impl::CloseSession() {
  if (cmd_fd_ >= 0) ::close(cmd_fd_);
  if (event_fd_ >= 0) ::close(event_fd_);
  cmd_fd_ = event_fd_ = -1;
  session_open_ = false;
  pending_events_.clear();
}

void PtpIpCamera::Impl::Drop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counters_.drops;
  }
  CAROUSEL_LOG_DEBUG("PTP/IP emulator " << options_.serial << ": dropping the connection");
  throw ConnectionLost{};
}

void PtpIpCamera::Impl::SendDueEvents() {
  while (!pending_events_.empty() && pending_events_.front().due <= Clock::now()) {
    const PendingEvent e = pending_events_.front();
    pending_events_.pop_front();
    if (event_fd_ < 0) continue;
    WritePacket(event_fd_, kEvent, ptpip::EncodeEvent(e.code, e.tid, e.param));
  }
}

void PtpIpCamera::Impl::HandleCommand(const Packet& packet) {
  if (packet.type == kPing) {
    WritePacket(cmd_fd_, kPong, {});
    return;
  }
  std::optional<Command> command = ptpip::DecodeCommand(packet);
  if (!command) return;
  if (command->host_data) ReadHostData(&*command);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counters_.operations;
  }
  Dispatch(*command);
}

void PtpIpCamera::Impl::ReadHostData(Command* command) {
  while (true) {
    const Packet p = ReadPacket(cmd_fd_);
    if (p.type == kStartData) continue;
    if (p.type != kData && p.type != kEndData) throw ConnectionLost{};
    const std::vector<std::uint8_t> data = ptpip::DataOf(p);
    command->data.insert(command->data.end(), data.begin(), data.end());
    if (p.type == kEndData) return;
  }
}

void PtpIpCamera::Impl::Respond(const Command& command, std::uint16_t code,
                                const std::vector<std::uint32_t>& params) {
  WritePacket(cmd_fd_, kCmdResponse, ptpip::EncodeResponse(code, command.tid, params));
}

void PtpIpCamera::Impl::SendData(const Command& command, const std::uint8_t* data, std::size_t size,
                                 bool object) {
  WritePacket(cmd_fd_, kStartData, ptpip::EncodeStartData(command.tid, size));
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
      WritePacket(cmd_fd_, kData, ptpip::EncodeData(command.tid, data + sent, n));
      {
        std::lock_guard<std::mutex> lock(mutex_);
        drop_after_.reset();
        if (--drops_left_ > 0) drop_after_ = drop_after_bytes_;
        counters_.bytes_served += n;
      }
      Drop();
    }
    WritePacket(cmd_fd_, last ? kEndData : kData, ptpip::EncodeData(command.tid, data + sent, n));
    sent += n;
  } while (sent < size);
  if (object) {
    std::lock_guard<std::mutex> lock(mutex_);
    counters_.bytes_served += size;
    if (drop_after_) *drop_after_ = *drop_after_ > size ? *drop_after_ - size : 0;
  }
}
void PtpIpCamera::Impl::SendData(const Command& command, Writer& w) {
  SendData(command, w.bytes().data(), w.bytes().size());
}

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
