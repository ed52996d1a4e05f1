// The PTP/IP wire format the emulator speaks, as libgphoto2 2.5.30 does
// (../shared/reference/rig-notes.md section 1.2; PIMA 15740 for PTP): the packet types, the PTP
// operation, response, event, property and format codes, a little-endian dataset writer, and
// the encoding and decoding of PTP/IP packets and of the PTP containers they carry (operation
// requests, responses, events, data phases). Pure: no sockets, no state. Private to sim.
//
// A PTP/IP packet: u32 length (counting the 8-byte header), u32 type, payload; every number
// little-endian.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace carousel::sim::ptpip {

// PTP/IP packet types (rig-notes 1.2).
enum PacketType : std::uint32_t {
  kInitCommandRequest = 1,
  kInitCommandAck = 2,
  kInitEventRequest = 3,
  kInitEventAck = 4,
  kInitFail = 5,
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

// The PTP data types of the property values the emulator has.
enum DataType : std::uint16_t {
  kUint8 = 0x0002,
  kUint16 = 0x0004,
  kUint32 = 0x0006,
};

// Object formats.
constexpr std::uint16_t kFormatAssociation = 0x3001;  // a folder
constexpr std::uint16_t kFormatJpeg = 0x3801;

constexpr std::size_t kHeaderSize = 8;
// Longer packets are refused as garbage.
constexpr std::uint32_t kMaxPacket = 64u << 20;

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
  void Str(const std::string& s);
  void Array16(const std::vector<std::uint16_t>& values);
  void Array32(const std::vector<std::uint32_t>& values);
  // A value of PTP data type `type` (kUint8, kUint16, else 32 bits).
  void Value(std::uint16_t type, std::uint32_t v);
  void Bytes(const std::uint8_t* data, std::size_t n) {
    bytes_.insert(bytes_.end(), data, data + n);
  }
  std::vector<std::uint8_t>& bytes() { return bytes_; }

 private:
  std::vector<std::uint8_t> bytes_;
};

std::uint32_t Le32(const std::uint8_t* p);
std::uint16_t Le16(const std::uint8_t* p);

// The size of a value of PTP data type `type` (kUint8: 1, kUint16: 2, else 4 bytes).
std::size_t ValueSize(std::uint16_t type);
// A value of PTP data type `type` from exactly ValueSize(type) bytes; empty for another size.
std::optional<std::uint32_t> DecodeValue(std::uint16_t type, const std::vector<std::uint8_t>& data);

struct Packet {
  std::uint32_t type = 0;
  std::vector<std::uint8_t> payload;
};

struct PacketHeader {
  std::uint32_t type = 0;
  std::uint32_t payload_size = 0;  // the length field less the header
};

// The whole packet: header, then `payload`.
std::vector<std::uint8_t> EncodePacket(std::uint32_t type,
                                       const std::vector<std::uint8_t>& payload);
// The kHeaderSize bytes at `header`; empty when the length is below the header's or above
// kMaxPacket.
std::optional<PacketHeader> DecodePacketHeader(const std::uint8_t* header);

// A PTP operation request.
struct Command {
  std::uint16_t code = 0;
  std::uint32_t tid = 0;              // transaction id
  std::vector<std::uint32_t> params;  // always 5, absent ones 0
  bool host_data = false;             // a host-to-device data phase follows
  std::vector<std::uint8_t> data;     // that data phase, once read
};

// A Cmd Request packet (data phase u32, operation code u16, transaction id u32, up to five u32
// parameters); empty for another packet or a payload too short.
std::optional<Command> DecodeCommand(const Packet& packet);

// Payloads of the packets the camera sends.
// Init Command Ack: our connection number, our GUID, our name, protocol version 1.0.
std::vector<std::uint8_t> EncodeInitCommandAck(std::uint32_t connection_number,
                                               const std::string& name);
std::vector<std::uint8_t> EncodeInitFail(std::uint32_t reason);
// The connection number an Init Event Request names; empty when its payload is too short.
std::optional<std::uint32_t> DecodeInitEventRequest(const Packet& packet);
std::vector<std::uint8_t> EncodeResponse(std::uint16_t code, std::uint32_t tid,
                                         const std::vector<std::uint32_t>& params);
std::vector<std::uint8_t> EncodeEvent(std::uint16_t code, std::uint32_t tid, std::uint32_t param);
// Start Data: the transaction and the size of the whole data phase.
std::vector<std::uint8_t> EncodeStartData(std::uint32_t tid, std::uint64_t size);
// Data and End Data: the transaction, then `n` bytes of the data phase.
std::vector<std::uint8_t> EncodeData(std::uint32_t tid, const std::uint8_t* data, std::size_t n);
// The bytes of a (host-to-device) Data or End Data packet after its transaction id.
std::vector<std::uint8_t> DataOf(const Packet& packet);

}  // namespace carousel::sim::ptpip
