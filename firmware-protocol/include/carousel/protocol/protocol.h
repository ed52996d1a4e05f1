/* carousel_protocol: the turntable controller's wire protocol (firmware-protocol/PROTOCOL.md).
 *
 * Pure C99 with no dependencies, compiled both into the host (rig/) and into the ATmega328P
 * firmware: frames (COBS, header, CRC-16), a byte-at-a-time decoder, and the payload codecs
 * of the status, configuration and trigger messages. Every function carries the prefix
 * `cp_` and returns 0 (or a byte count) on success or one of the negative CP_ERR_* codes;
 * rig/ converts codes to carousel::ProtocolError / DeviceError at its boundary.
 */
/* C99 names (cp_ functions, CP_ constants), not the C++ style of STYLE.md:
 * NOLINTBEGIN(readability-identifier-naming) */
#ifndef CAROUSEL_PROTOCOL_PROTOCOL_H_
#define CAROUSEL_PROTOCOL_PROTOCOL_H_

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CP_VERSION_MAJOR 1
#define CP_VERSION_MINOR 1

#define CP_MAX_PAYLOAD 32
#define CP_HEADER_SIZE 3 /* type, seq, len */
#define CP_CRC_SIZE 2
#define CP_MIN_RAW (CP_HEADER_SIZE + CP_CRC_SIZE)                  /* 5 */
#define CP_MAX_RAW (CP_HEADER_SIZE + CP_MAX_PAYLOAD + CP_CRC_SIZE) /* 37 */
#define CP_MAX_ENCODED (CP_MAX_RAW + 1)                            /* COBS: 38 */
#define CP_MAX_WIRE (CP_MAX_ENCODED + 1)                           /* with the 0x00: 39 */

/* Error codes (negative). A NAK carries the negated code in one byte. */
enum {
  CP_OK = 0,
  CP_ERR_ARGUMENT = -1, /* a null pointer, a buffer too small, a payload over 32 bytes */
  CP_ERR_TOO_LONG = -2, /* a frame exceeded CP_MAX_ENCODED before its delimiter */
  CP_ERR_COBS = -3,     /* a malformed COBS code */
  CP_ERR_CRC = -4,      /* the CRC does not match */
  CP_ERR_LENGTH = -5,   /* `len` disagrees with the frame's size, or a payload has the wrong size */
  CP_ERR_TRUNCATED = -6, /* fewer than CP_MIN_RAW bytes */
  CP_ERR_UNKNOWN = -7,   /* unknown message type */
  CP_ERR_VERSION = -8,   /* incompatible protocol major version, or no HELLO yet */
  CP_ERR_BUSY = -9,      /* moving or homing */
  CP_ERR_RANGE = -10     /* a value outside its documented range */
};

/* Message types. */
enum {
  CP_HELLO = 0x01,
  CP_IDENTIFY = 0x02,
  CP_STATUS = 0x03,
  CP_HOME = 0x04,
  CP_MOVE_ABS = 0x05,
  CP_MOVE_REL = 0x06,
  CP_STOP = 0x07,
  CP_ESTOP = 0x08,
  CP_GET_CONFIG = 0x09,
  CP_SET_CONFIG = 0x0A,
  CP_TRIGGER = 0x0B,
  CP_ENABLE = 0x0C,
  CP_LIGHT = 0x0D, /* since 1.1 */
  CP_EVENT_BOOT = 0x40,
  CP_EVENT_MOVE_DONE = 0x41,
  CP_EVENT_FAULT = 0x42,
  CP_NAK = 0x7F,
  CP_ACK_FLAG = 0x80 /* ACK type = command | CP_ACK_FLAG */
};

/* Status flags and faults. */
enum {
  CP_FLAG_MOVING = 0x01,
  CP_FLAG_HOMED = 0x02,
  CP_FLAG_ENABLED = 0x04,
  CP_FLAG_HOMING = 0x08,
  CP_FLAG_SENSOR = 0x10,
  CP_FLAG_HOLD = 0x20,
  CP_FLAG_BACKLIGHT = 0x40 /* since 1.1 */
};
enum { CP_FAULT_NONE = 0, CP_FAULT_HOME_NOT_FOUND = 1, CP_FAULT_ESTOP = 2, CP_FAULT_WATCHDOG = 3 };
/* MOVE_DONE reasons. */
enum { CP_DONE_REACHED = 0, CP_DONE_STOPPED = 1, CP_DONE_ESTOP = 2, CP_DONE_HOMED = 3 };
/* TRIGGER outputs. */
enum { CP_OUTPUT_SHUTTER = 0x01, CP_OUTPUT_FOCUS = 0x02 };
/* LIGHT's payload: the lights to switch on (the others go off). */
enum { CP_LIGHT_BACKLIGHT = 0x01 };
#define CP_LIGHT_ALL CP_LIGHT_BACKLIGHT

#define CP_MAX_CAMERAS 4
#define CP_MIN_STEP_RATE 32u     /* microsteps/s: one step interval fits timer 1 */
#define CP_MAX_STEP_RATE 8000u   /* microsteps/s the firmware can generate */
#define CP_MIN_ACCELERATION 500u /* microsteps/s^2: the first step interval fits timer 1 */
#define CP_MAX_BACKLASH 10000u
#define CP_MAX_TRIGGER_MS 10000u
#define CP_MAX_MODEL 24

typedef struct {
  uint8_t type;
  uint8_t seq;
  uint8_t len;
  uint8_t payload[CP_MAX_PAYLOAD];
} cp_frame;

typedef struct {
  int32_t position;
  int32_t target;
  uint8_t flags;
  uint8_t fault;
  uint16_t dropped_frames;
} cp_status;
#define CP_STATUS_SIZE 12

typedef struct {
  uint16_t steps_per_rev;
  uint16_t microsteps;
  uint16_t gear_num;
  uint16_t gear_den;
  uint16_t max_speed;
  uint16_t acceleration;
  uint16_t homing_speed;
  uint16_t backlash;
} cp_config;
#define CP_CONFIG_SIZE 16

typedef struct {
  uint8_t cameras;
  uint8_t outputs;
  uint16_t duration_ms;
} cp_trigger;
#define CP_TRIGGER_SIZE 4

/* Fills `frame` with a type, sequence number and a copy of `size` payload bytes (`payload`
 * may be NULL when `size` is 0). CP_ERR_ARGUMENT for a null frame or size > CP_MAX_PAYLOAD. */
int cp_make_frame(cp_frame* frame, uint8_t type, uint8_t seq, const uint8_t* payload, size_t size);

/* CRC-16/CCITT-FALSE. */
uint16_t cp_crc16(const uint8_t* data, size_t size);
uint16_t cp_crc16_update(uint16_t crc, uint8_t byte);

/* Encodes `frame` as wire bytes (COBS + 0x00) into `out`; returns the byte count or
 * CP_ERR_ARGUMENT (null, len > CP_MAX_PAYLOAD, capacity < CP_MAX_WIRE for that frame). */
int cp_encode(const cp_frame* frame, uint8_t* out, size_t capacity);

/* Decodes one COBS-encoded frame (`size` bytes, without its 0x00 delimiter). Returns CP_OK
 * or CP_ERR_TOO_LONG, CP_ERR_COBS, CP_ERR_TRUNCATED, CP_ERR_LENGTH, CP_ERR_CRC. */
int cp_decode(const uint8_t* encoded, size_t size, cp_frame* frame);

/* A byte-at-a-time receiver: feeds bytes, yields frames at delimiters, resynchronises on
 * errors. */
typedef struct {
  uint8_t buffer[CP_MAX_ENCODED];
  uint8_t size;
  uint8_t overflow; /* discarding until the next delimiter */
} cp_decoder;

void cp_decoder_init(cp_decoder* decoder);
/* Returns 1 when `byte` completed a valid frame (written to `frame`), 0 when more bytes are
 * needed (or an empty frame was skipped), or a negative code when a frame was dropped
 * (reported once per frame, at its delimiter or at the overflow). */
int cp_decoder_push(cp_decoder* decoder, uint8_t byte, cp_frame* frame);

/* Little-endian field access. */
void cp_put_u16(uint8_t* p, uint16_t v);
void cp_put_i32(uint8_t* p, int32_t v);
uint16_t cp_get_u16(const uint8_t* p);
int32_t cp_get_i32(const uint8_t* p);

/* Payload codecs: `put` fills frame->payload and frame->len; `get` checks the length
 * (at least the documented size: newer minor versions may append bytes) and the ranges. */
void cp_put_status(cp_frame* frame, const cp_status* status);
int cp_get_status(const cp_frame* frame, cp_status* status);
void cp_put_config(cp_frame* frame, const cp_config* config);
int cp_get_config(const cp_frame* frame, cp_config* config);
void cp_put_trigger(cp_frame* frame, const cp_trigger* trigger);
int cp_get_trigger(const cp_frame* frame, cp_trigger* trigger);

/* CP_OK or CP_ERR_RANGE with the rules of PROTOCOL.md. */
int cp_check_config(const cp_config* config);
void cp_default_config(cp_config* config);

/* Microsteps per table revolution for `config` (0 when the configuration is invalid). */
uint32_t cp_steps_per_table_rev(const cp_config* config);

/* A static, human-readable name for an error code ("CRC mismatch"). */
const char* cp_error_name(int code);
/* A static name for a message type ("MOVE_ABS"), "?" when unknown. */
const char* cp_type_name(uint8_t type);

#ifdef __cplusplus
}
#endif

#endif /* CAROUSEL_PROTOCOL_PROTOCOL_H_ */
/* NOLINTEND(readability-identifier-naming) */
