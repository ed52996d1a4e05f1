// carousel_protocol: golden byte vectors (computed independently of this codec, from the
// definitions in PROTOCOL.md), round trips, and truncated, oversized, bit-flipped and garbage
// input.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <vector>

#include "carousel/protocol/protocol.h"

namespace {

using Bytes = std::vector<std::uint8_t>;

Bytes Encode(const cp_frame& f) {
  Bytes out(CP_MAX_WIRE);
  const int n = cp_encode(&f, out.data(), out.size());
  EXPECT_GT(n, 0);
  out.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
  return out;
}

cp_frame Frame(std::uint8_t type, std::uint8_t seq, const Bytes& payload) {
  cp_frame f{};
  EXPECT_EQ(cp_make_frame(&f, type, seq, payload.data(), payload.size()), CP_OK);
  return f;
}

// Feeds bytes to a fresh decoder; returns the frames and counts the errors.
std::vector<cp_frame> Feed(const Bytes& bytes, int* errors = nullptr) {
  cp_decoder d;
  cp_decoder_init(&d);
  std::vector<cp_frame> frames;
  int bad = 0;
  for (const std::uint8_t b : bytes) {
    cp_frame f{};
    const int r = cp_decoder_push(&d, b, &f);
    if (r == 1) frames.push_back(f);
    if (r < 0) ++bad;
  }
  if (errors != nullptr) *errors = bad;
  return frames;
}

TEST(ProtocolCrc, CheckValue) {
  const std::uint8_t text[] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  EXPECT_EQ(cp_crc16(text, sizeof text), 0x29B1);
}

TEST(ProtocolGolden, HelloBytes) {
  EXPECT_EQ(Encode(Frame(CP_HELLO, 1, {1, 0})),
            (Bytes{0x05, 0x01, 0x01, 0x02, 0x01, 0x03, 0xB8, 0x90, 0x00}));
}

TEST(ProtocolGolden, MoveAbsNegativeTarget) {
  cp_frame f = Frame(CP_MOVE_ABS, 7, {});
  cp_put_i32(f.payload, -1000);
  f.len = 4;
  EXPECT_EQ(Encode(f), (Bytes{0x0A, 0x05, 0x07, 0x04, 0x18, 0xFC, 0xFF, 0xFF, 0x76, 0xDC, 0x00}));
}

TEST(ProtocolGolden, StatusAckWithZeroBytes) {
  cp_frame f = Frame(CP_STATUS | CP_ACK_FLAG, 200, {});
  const cp_status s{9600, -5, CP_FLAG_MOVING | CP_FLAG_HOMED, CP_FAULT_NONE, 258};
  cp_put_status(&f, &s);
  const Bytes golden{0x06, 0x83, 0xC8, 0x0C, 0x80, 0x25, 0x01, 0x06, 0xFB, 0xFF,
                     0xFF, 0xFF, 0x03, 0x05, 0x02, 0x01, 0xA0, 0x34, 0x00};
  EXPECT_EQ(Encode(f), golden);
  const auto frames = Feed(golden);
  ASSERT_EQ(frames.size(), 1u);
  cp_status back{};
  ASSERT_EQ(cp_get_status(&frames[0], &back), CP_OK);
  EXPECT_EQ(back.position, 9600);
  EXPECT_EQ(back.target, -5);
  EXPECT_EQ(back.flags, CP_FLAG_MOVING | CP_FLAG_HOMED);
  EXPECT_EQ(back.dropped_frames, 258);
}

TEST(ProtocolGolden, NakAndEmptyPayload) {
  EXPECT_EQ(Encode(Frame(CP_NAK, 9, {CP_MOVE_ABS, 9})),
            (Bytes{0x08, 0x7F, 0x09, 0x02, 0x05, 0x09, 0xB8, 0x9A, 0x00}));
  EXPECT_EQ(Encode(Frame(CP_STATUS, 0, {})), (Bytes{0x02, 0x03, 0x01, 0x03, 0xCC, 0x95, 0x00}));
}

TEST(ProtocolFrames, RoundTripEveryLengthAndZeroPattern) {
  std::mt19937 random(3);
  for (int len = 0; len <= CP_MAX_PAYLOAD; ++len) {
    Bytes payload(len);
    for (auto& b : payload) b = static_cast<std::uint8_t>(random() % 3 == 0 ? 0 : random());
    const cp_frame f =
        Frame(static_cast<std::uint8_t>(random()), static_cast<std::uint8_t>(len), payload);
    const Bytes wire = Encode(f);
    ASSERT_LE(wire.size(), static_cast<std::size_t>(CP_MAX_WIRE));
    // No zero inside a frame: the delimiter is unambiguous.
    for (std::size_t i = 0; i + 1 < wire.size(); ++i) ASSERT_NE(wire[i], 0) << "len " << len;
    const auto frames = Feed(wire);
    ASSERT_EQ(frames.size(), 1u);
    EXPECT_EQ(frames[0].type, f.type);
    EXPECT_EQ(frames[0].seq, f.seq);
    ASSERT_EQ(frames[0].len, f.len);
    EXPECT_TRUE(std::equal(payload.begin(), payload.end(), frames[0].payload));
  }
}

TEST(ProtocolFrames, MakeFrameChecksItsArguments) {
  cp_frame f{};
  const std::uint8_t big[CP_MAX_PAYLOAD + 1] = {};
  EXPECT_EQ(cp_make_frame(&f, CP_STATUS, 1, big, sizeof big), CP_ERR_ARGUMENT);
  EXPECT_EQ(cp_make_frame(&f, CP_STATUS, 1, nullptr, 2), CP_ERR_ARGUMENT);
  EXPECT_EQ(cp_make_frame(nullptr, CP_STATUS, 1, big, 1), CP_ERR_ARGUMENT);
  ASSERT_EQ(cp_make_frame(&f, CP_STATUS, 1, nullptr, 0), CP_OK);
  EXPECT_EQ(f.len, 0);
}

TEST(ProtocolFrames, EncodeRejectsOversizedPayloadAndSmallBuffer) {
  cp_frame f = Frame(CP_STATUS, 1, {});
  f.len = CP_MAX_PAYLOAD + 1;
  std::uint8_t out[CP_MAX_WIRE + 8];
  EXPECT_EQ(cp_encode(&f, out, sizeof out), CP_ERR_ARGUMENT);
  f.len = 4;
  EXPECT_EQ(cp_encode(&f, out, 6), CP_ERR_ARGUMENT);
  EXPECT_EQ(cp_encode(nullptr, out, sizeof out), CP_ERR_ARGUMENT);
}

TEST(ProtocolFrames, TruncatedFramesAreRejected) {
  const Bytes wire = Encode(Frame(CP_MOVE_REL, 4, {1, 2, 3, 4}));
  for (std::size_t cut = 1; cut + 1 < wire.size(); ++cut) {
    Bytes partial(wire.begin(), wire.begin() + static_cast<std::ptrdiff_t>(cut));
    partial.push_back(0);
    int errors = 0;
    EXPECT_TRUE(Feed(partial, &errors).empty()) << "cut at " << cut;
    EXPECT_EQ(errors, 1) << "cut at " << cut;
  }
  cp_frame f{};
  const std::uint8_t tiny[] = {0x03, 0x01, 0x02};
  EXPECT_EQ(cp_decode(tiny, sizeof tiny, &f), CP_ERR_TRUNCATED);
}

TEST(ProtocolFrames, EveryBitFlipIsDetected) {
  const Bytes wire = Encode(Frame(CP_MOVE_ABS, 9, {0x10, 0x27, 0x00, 0x00}));
  for (std::size_t i = 0; i + 1 < wire.size(); ++i)
    for (int bit = 0; bit < 8; ++bit) {
      Bytes bad = wire;
      bad[i] = static_cast<std::uint8_t>(bad[i] ^ (1u << bit));
      // A flip that makes a zero splits the frame; either way no frame may come out.
      EXPECT_TRUE(Feed(bad).empty()) << "byte " << i << " bit " << bit;
    }
}

TEST(ProtocolFrames, LengthFieldMustMatch) {
  // A valid CRC over a header whose len says 3 while 2 payload bytes follow.
  std::uint8_t raw[] = {CP_TRIGGER, 1, 3, 0x01, 0x01, 0, 0};
  cp_put_u16(raw + 5, cp_crc16(raw, 5));
  // COBS by hand: no zeros except possibly in the CRC.
  Bytes encoded{0};
  std::size_t code_at = 0;
  std::uint8_t code = 1;
  for (const std::uint8_t b : raw) {
    if (b == 0) {
      encoded[code_at] = code;
      code_at = encoded.size();
      encoded.push_back(0);
      code = 1;
    } else {
      encoded.push_back(b);
      ++code;
    }
  }
  encoded[code_at] = code;
  cp_frame f{};
  EXPECT_EQ(cp_decode(encoded.data(), encoded.size(), &f), CP_ERR_LENGTH);
}

TEST(ProtocolDecoder, OversizedInputIsDroppedAndTheNextFrameDecodes) {
  Bytes garbage(200, 0x55);
  garbage.push_back(0);
  const Bytes good = Encode(Frame(CP_STATUS, 3, {}));
  garbage.insert(garbage.end(), good.begin(), good.end());
  int errors = 0;
  const auto frames = Feed(garbage, &errors);
  EXPECT_EQ(errors, 1);  // reported once, not once per byte
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0].seq, 3);
}

TEST(ProtocolDecoder, ResynchronisesAfterRandomGarbage) {
  std::mt19937 random(11);
  const Bytes good = Encode(Frame(CP_HOME, 42, {}));
  int recovered = 0;
  for (int trial = 0; trial < 500; ++trial) {
    Bytes stream(random() % 80);
    for (auto& b : stream) b = static_cast<std::uint8_t>(random());
    stream.push_back(0);  // the sender's flush byte
    stream.insert(stream.end(), good.begin(), good.end());
    const auto frames = Feed(stream);
    // Garbage can (rarely) contain a valid frame of its own; the good one must come last.
    ASSERT_FALSE(frames.empty()) << "trial " << trial;
    EXPECT_EQ(frames.back().type, CP_HOME);
    EXPECT_EQ(frames.back().seq, 42);
    recovered += frames.size() == 1 ? 1 : 0;
  }
  EXPECT_GT(recovered, 490);
}

TEST(ProtocolDecoder, EmptyFramesAreIgnored) {
  int errors = 0;
  EXPECT_TRUE(Feed(Bytes{0, 0, 0}, &errors).empty());
  EXPECT_EQ(errors, 0);
}

TEST(ProtocolPayloads, ConfigRoundTripAndRanges) {
  cp_config c{};
  cp_default_config(&c);
  ASSERT_EQ(cp_check_config(&c), CP_OK);
  EXPECT_EQ(cp_steps_per_table_rev(&c), 9600u);
  cp_frame f{};
  cp_put_config(&f, &c);
  EXPECT_EQ(f.len, CP_CONFIG_SIZE);
  cp_config back{};
  ASSERT_EQ(cp_get_config(&f, &back), CP_OK);
  EXPECT_EQ(back.acceleration, c.acceleration);
  EXPECT_EQ(back.backlash, c.backlash);

  auto bad = [&](auto mutate) {
    cp_config x = c;
    mutate(x);
    return cp_check_config(&x);
  };
  EXPECT_EQ(bad([](cp_config& x) { x.max_speed = CP_MAX_STEP_RATE + 1; }), CP_ERR_RANGE);
  EXPECT_EQ(bad([](cp_config& x) { x.acceleration = CP_MIN_ACCELERATION - 1; }), CP_ERR_RANGE);
  EXPECT_EQ(bad([](cp_config& x) { x.gear_den = 0; }), CP_ERR_RANGE);
  EXPECT_EQ(bad([](cp_config& x) { x.homing_speed = x.max_speed + 1; }), CP_ERR_RANGE);
  EXPECT_EQ(bad([](cp_config& x) { x.microsteps = 512; }), CP_ERR_RANGE);
  EXPECT_EQ(bad([](cp_config& x) { x.backlash = CP_MAX_BACKLASH + 1; }), CP_ERR_RANGE);
  f.len = CP_CONFIG_SIZE - 1;
  EXPECT_EQ(cp_get_config(&f, &back), CP_ERR_LENGTH);
}

TEST(ProtocolPayloads, TriggerRanges) {
  cp_frame f{};
  cp_trigger t{0x05, CP_OUTPUT_SHUTTER, 50};
  cp_put_trigger(&f, &t);
  cp_trigger back{};
  ASSERT_EQ(cp_get_trigger(&f, &back), CP_OK);
  EXPECT_EQ(back.cameras, 0x05);
  EXPECT_EQ(back.duration_ms, 50);
  t.cameras = 0x10;
  cp_put_trigger(&f, &t);
  EXPECT_EQ(cp_get_trigger(&f, &back), CP_ERR_RANGE);
  t = {1, CP_OUTPUT_SHUTTER, 0};
  cp_put_trigger(&f, &t);
  EXPECT_EQ(cp_get_trigger(&f, &back), CP_ERR_RANGE);
}

TEST(ProtocolPayloads, SignedIntegersRoundTrip) {
  std::uint8_t b[4];
  for (const std::int32_t v : {0, 1, -1, 123456789, -123456789, INT32_MAX, INT32_MIN}) {
    cp_put_i32(b, v);
    EXPECT_EQ(cp_get_i32(b), v);
  }
  cp_put_i32(b, -2);
  EXPECT_EQ(b[0], 0xFE);
  EXPECT_EQ(b[3], 0xFF);
}

TEST(ProtocolNames, ErrorsAndTypes) {
  EXPECT_STREQ(cp_error_name(CP_ERR_CRC), "CRC mismatch");
  EXPECT_STREQ(cp_type_name(CP_MOVE_ABS | CP_ACK_FLAG), "MOVE_ABS");
  EXPECT_STREQ(cp_type_name(0x3E), "?");
}

}  // namespace
