#include "ptpip_codec.h"

#include <algorithm>

namespace carousel::sim::ptpip {

void Writer::Str(const std::string& s) {
  if (s.empty()) {
    U8(0);
    return;
  }
  const std::size_t n = std::min<std::size_t>(s.size(), 254);
  U8(static_cast<std::uint32_t>(n + 1));
  for (std::size_t i = 0; i < n; ++i) U16(static_cast<unsigned char>(s[i]));
  U16(0);
}

void Writer::Array16(const std::vector<std::uint16_t>& values) {
  U32(static_cast<std::uint32_t>(values.size()));
  for (const std::uint16_t v : values) U16(v);
}

void Writer::Array32(const std::vector<std::uint32_t>& values) {
  U32(static_cast<std::uint32_t>(values.size()));
  for (const std::uint32_t v : values) U32(v);
}

void Writer::Value(std::uint16_t type, std::uint32_t v) {
  if (type == kUint8) {
    U8(v);
  } else if (type == kUint16) {
    U16(v);
  } else {
    U32(v);
  }
}

std::uint32_t Le32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}

std::uint16_t Le16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }

std::size_t ValueSize(std::uint16_t type) { return type == kUint8 ? 1 : type == kUint16 ? 2 : 4; }

std::optional<std::uint32_t> DecodeValue(std::uint16_t type,
                                         const std::vector<std::uint8_t>& data) {
  const std::size_t size = ValueSize(type);
  if (data.size() != size) return std::nullopt;
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < size; ++i) v |= static_cast<std::uint32_t>(data[i]) << (8 * i);
  return v;
}

std::vector<std::uint8_t> EncodePacket(std::uint32_t type,
                                       const std::vector<std::uint8_t>& payload) {
  Writer w;
  w.U32(static_cast<std::uint32_t>(payload.size() + kHeaderSize));
  w.U32(type);
  w.Bytes(payload.data(), payload.size());
  return std::move(w.bytes());
}

std::optional<PacketHeader> DecodePacketHeader(const std::uint8_t* header) {
  const std::uint32_t length = Le32(header);
  if (length < kHeaderSize || length > kMaxPacket) return std::nullopt;
  return PacketHeader{.type = Le32(header + 4),
                      .payload_size = static_cast<std::uint32_t>(length - kHeaderSize)};
}

std::optional<Command> DecodeCommand(const Packet& packet) {
  if (packet.type != kCmdRequest || packet.payload.size() < 10) return std::nullopt;
  const std::uint8_t* p = packet.payload.data();
  Command command;
  command.host_data = Le32(p) == 2;
  command.code = Le16(p + 4);
  command.tid = Le32(p + 6);
  for (std::size_t at = 10; at + 4 <= packet.payload.size() && command.params.size() < 5; at += 4) {
    command.params.push_back(Le32(p + at));
  }
  command.params.resize(5, 0);
  return command;
}

std::vector<std::uint8_t> EncodeInitCommandAck(std::uint32_t connection_number,
                                               const std::string& name) {
  Writer ack;
  ack.U32(connection_number);
  for (std::uint8_t i = 0; i < 16; ++i) ack.U8(0x10 + i);  // our GUID
  for (const char c : name) ack.U16(static_cast<unsigned char>(c));
  ack.U16(0);
  ack.U32(0x00010000);  // version 1.0
  return std::move(ack.bytes());
}

std::vector<std::uint8_t> EncodeInitFail(std::uint32_t reason) {
  Writer w;
  w.U32(reason);
  return std::move(w.bytes());
}

std::optional<std::uint32_t> DecodeInitEventRequest(const Packet& packet) {
  if (packet.type != kInitEventRequest || packet.payload.size() < 4) return std::nullopt;
  return Le32(packet.payload.data());
}

std::vector<std::uint8_t> EncodeResponse(std::uint16_t code, std::uint32_t tid,
                                         const std::vector<std::uint32_t>& params) {
  Writer w;
  w.U16(code);
  w.U32(tid);
  for (const std::uint32_t p : params) w.U32(p);
  return std::move(w.bytes());
}

std::vector<std::uint8_t> EncodeEvent(std::uint16_t code, std::uint32_t tid, std::uint32_t param) {
  Writer w;
  w.U16(code);
  w.U32(tid);
  w.U32(param);
  return std::move(w.bytes());
}

std::vector<std::uint8_t> EncodeStartData(std::uint32_t tid, std::uint64_t size) {
  Writer w;
  w.U32(tid);
  w.U64(size);
  return std::move(w.bytes());
}

std::vector<std::uint8_t> EncodeData(std::uint32_t tid, const std::uint8_t* data, std::size_t n) {
  Writer w;
  w.U32(tid);
  w.Bytes(data, n);
  return std::move(w.bytes());
}

std::vector<std::uint8_t> DataOf(const Packet& packet) {
  if (packet.payload.size() < 4) return {};
  return {packet.payload.begin() + 4, packet.payload.end()};
}

}  // namespace carousel::sim::ptpip
