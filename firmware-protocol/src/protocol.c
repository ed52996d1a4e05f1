/* carousel_protocol: frames, decoder and payload codecs (see protocol.h, PROTOCOL.md). */
#include "carousel/protocol/protocol.h"

#include <string.h>

int cp_make_frame(cp_frame* frame, uint8_t type, uint8_t seq, const uint8_t* payload, size_t size) {
  if (frame == NULL || size > CP_MAX_PAYLOAD || (payload == NULL && size > 0))
    return CP_ERR_ARGUMENT;
  frame->type = type;
  frame->seq = seq;
  frame->len = (uint8_t)size;
  if (size > 0) memcpy(frame->payload, payload, size);
  return CP_OK;
}

uint16_t cp_crc16_update(uint16_t crc, uint8_t byte) {
  int bit;
  crc ^= (uint16_t)((uint16_t)byte << 8);
  for (bit = 0; bit < 8; ++bit)
    crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
  return crc;
}

uint16_t cp_crc16(const uint8_t* data, size_t size) {
  uint16_t crc = 0xFFFFu;
  size_t i;
  for (i = 0; i < size; ++i) crc = cp_crc16_update(crc, data[i]);
  return crc;
}

void cp_put_u16(uint8_t* p, uint16_t v) {
  p[0] = (uint8_t)(v & 0xFFu);
  p[1] = (uint8_t)(v >> 8);
}

void cp_put_i32(uint8_t* p, int32_t v) {
  const uint32_t u = (uint32_t)v;
  p[0] = (uint8_t)(u & 0xFFu);
  p[1] = (uint8_t)((u >> 8) & 0xFFu);
  p[2] = (uint8_t)((u >> 16) & 0xFFu);
  p[3] = (uint8_t)(u >> 24);
}

uint16_t cp_get_u16(const uint8_t* p) { return (uint16_t)(p[0] | ((uint16_t)p[1] << 8)); }

int32_t cp_get_i32(const uint8_t* p) {
  const uint32_t u =
      (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
  /* Two's complement without implementation-defined conversion. */
  if (u <= 0x7FFFFFFFu) return (int32_t)u;
  return (int32_t)(u - 0x80000000u) - (int32_t)0x7FFFFFFF - 1;
}

int cp_encode(const cp_frame* frame, uint8_t* out, size_t capacity) {
  uint8_t raw[CP_MAX_RAW];
  size_t raw_size, i, code_at, written;
  uint8_t code;
  uint16_t crc;
  if (frame == NULL || out == NULL || frame->len > CP_MAX_PAYLOAD) return CP_ERR_ARGUMENT;
  raw[0] = frame->type;
  raw[1] = frame->seq;
  raw[2] = frame->len;
  memcpy(raw + CP_HEADER_SIZE, frame->payload, frame->len);
  crc = cp_crc16(raw, (size_t)CP_HEADER_SIZE + frame->len);
  cp_put_u16(raw + CP_HEADER_SIZE + frame->len, crc);
  raw_size = (size_t)CP_HEADER_SIZE + frame->len + CP_CRC_SIZE;
  /* COBS: raw_size < 254, so one overhead byte; plus the delimiter. */
  if (capacity < raw_size + 2) return CP_ERR_ARGUMENT;
  code_at = 0;
  code = 1;
  written = 1;
  for (i = 0; i < raw_size; ++i) {
    if (raw[i] == 0) {
      out[code_at] = code;
      code_at = written++;
      code = 1;
    } else {
      out[written++] = raw[i];
      ++code;
    }
  }
  out[code_at] = code;
  out[written++] = 0;
  return (int)written;
}

int cp_decode(const uint8_t* encoded, size_t size, cp_frame* frame) {
  uint8_t raw[CP_MAX_RAW];
  size_t in = 0, raw_size = 0;
  uint16_t crc;
  if (encoded == NULL || frame == NULL) return CP_ERR_ARGUMENT;
  if (size > CP_MAX_ENCODED) return CP_ERR_TOO_LONG;
  while (in < size) {
    const uint8_t code = encoded[in++];
    uint8_t k;
    if (code == 0 || in + (size_t)code - 1 > size) return CP_ERR_COBS;
    for (k = 1; k < code; ++k) {
      if (encoded[in] == 0) return CP_ERR_COBS;
      if (raw_size >= CP_MAX_RAW) return CP_ERR_TOO_LONG;
      raw[raw_size++] = encoded[in++];
    }
    /* A code below 0xFF stands for a zero, except at the very end. */
    if (code < 0xFF && in < size) {
      if (raw_size >= CP_MAX_RAW) return CP_ERR_TOO_LONG;
      raw[raw_size++] = 0;
    }
  }
  if (raw_size < CP_MIN_RAW) return CP_ERR_TRUNCATED;
  if (raw[2] > CP_MAX_PAYLOAD || raw_size != (size_t)CP_HEADER_SIZE + raw[2] + CP_CRC_SIZE)
    return CP_ERR_LENGTH;
  crc = cp_crc16(raw, (size_t)CP_HEADER_SIZE + raw[2]);
  if (crc != cp_get_u16(raw + CP_HEADER_SIZE + raw[2])) return CP_ERR_CRC;
  frame->type = raw[0];
  frame->seq = raw[1];
  frame->len = raw[2];
  memcpy(frame->payload, raw + CP_HEADER_SIZE, raw[2]);
  return CP_OK;
}

void cp_decoder_init(cp_decoder* decoder) {
  decoder->size = 0;
  decoder->overflow = 0;
}

int cp_decoder_push(cp_decoder* decoder, uint8_t byte, cp_frame* frame) {
  if (byte == 0) {
    int result;
    if (decoder->overflow) {
      decoder->overflow = 0;
      decoder->size = 0;
      return 0; /* already reported */
    }
    if (decoder->size == 0) return 0; /* an empty frame: a flush */
    result = cp_decode(decoder->buffer, decoder->size, frame);
    decoder->size = 0;
    return result == CP_OK ? 1 : result;
  }
  if (decoder->overflow) return 0;
  if (decoder->size >= CP_MAX_ENCODED) {
    decoder->overflow = 1;
    decoder->size = 0;
    return CP_ERR_TOO_LONG;
  }
  decoder->buffer[decoder->size++] = byte;
  return 0;
}

void cp_put_status(cp_frame* frame, const cp_status* status) {
  cp_put_i32(frame->payload, status->position);
  cp_put_i32(frame->payload + 4, status->target);
  frame->payload[8] = status->flags;
  frame->payload[9] = status->fault;
  cp_put_u16(frame->payload + 10, status->dropped_frames);
  frame->len = CP_STATUS_SIZE;
}

int cp_get_status(const cp_frame* frame, cp_status* status) {
  if (frame->len < CP_STATUS_SIZE) return CP_ERR_LENGTH;
  status->position = cp_get_i32(frame->payload);
  status->target = cp_get_i32(frame->payload + 4);
  status->flags = frame->payload[8];
  status->fault = frame->payload[9];
  status->dropped_frames = cp_get_u16(frame->payload + 10);
  return CP_OK;
}

void cp_put_config(cp_frame* frame, const cp_config* config) {
  uint8_t* p = frame->payload;
  cp_put_u16(p, config->steps_per_rev);
  cp_put_u16(p + 2, config->microsteps);
  cp_put_u16(p + 4, config->gear_num);
  cp_put_u16(p + 6, config->gear_den);
  cp_put_u16(p + 8, config->max_speed);
  cp_put_u16(p + 10, config->acceleration);
  cp_put_u16(p + 12, config->homing_speed);
  cp_put_u16(p + 14, config->backlash);
  frame->len = CP_CONFIG_SIZE;
}

int cp_get_config(const cp_frame* frame, cp_config* config) {
  const uint8_t* p = frame->payload;
  if (frame->len < CP_CONFIG_SIZE) return CP_ERR_LENGTH;
  config->steps_per_rev = cp_get_u16(p);
  config->microsteps = cp_get_u16(p + 2);
  config->gear_num = cp_get_u16(p + 4);
  config->gear_den = cp_get_u16(p + 6);
  config->max_speed = cp_get_u16(p + 8);
  config->acceleration = cp_get_u16(p + 10);
  config->homing_speed = cp_get_u16(p + 12);
  config->backlash = cp_get_u16(p + 14);
  return cp_check_config(config);
}

void cp_put_trigger(cp_frame* frame, const cp_trigger* trigger) {
  frame->payload[0] = trigger->cameras;
  frame->payload[1] = trigger->outputs;
  cp_put_u16(frame->payload + 2, trigger->duration_ms);
  frame->len = CP_TRIGGER_SIZE;
}

int cp_get_trigger(const cp_frame* frame, cp_trigger* trigger) {
  if (frame->len < CP_TRIGGER_SIZE) return CP_ERR_LENGTH;
  trigger->cameras = frame->payload[0];
  trigger->outputs = frame->payload[1];
  trigger->duration_ms = cp_get_u16(frame->payload + 2);
  if (trigger->cameras == 0 || trigger->cameras >= (1u << CP_MAX_CAMERAS) ||
      trigger->outputs == 0 || trigger->outputs > (CP_OUTPUT_SHUTTER | CP_OUTPUT_FOCUS) ||
      trigger->duration_ms == 0 || trigger->duration_ms > CP_MAX_TRIGGER_MS)
    return CP_ERR_RANGE;
  return CP_OK;
}

uint32_t cp_steps_per_table_rev(const cp_config* config) {
  uint32_t motor;
  if (cp_check_config(config) != CP_OK) return 0;
  motor = (uint32_t)config->steps_per_rev * config->microsteps;
  /* table rev = motor revs x den / num  ->  microsteps per table rev = motor x num / den. */
  return (uint32_t)(((uint64_t)motor * config->gear_num + config->gear_den / 2) / config->gear_den);
}

int cp_check_config(const cp_config* c) {
  uint64_t per_table;
  if (c->steps_per_rev == 0 || c->microsteps == 0 || c->microsteps > 256 || c->gear_num == 0 ||
      c->gear_den == 0 || c->max_speed < CP_MIN_STEP_RATE || c->max_speed > CP_MAX_STEP_RATE ||
      c->acceleration < CP_MIN_ACCELERATION || c->homing_speed < 4 * CP_MIN_STEP_RATE ||
      c->homing_speed > c->max_speed || c->backlash > CP_MAX_BACKLASH)
    return CP_ERR_RANGE;
  /* A table revolution must fit comfortably in a signed 32-bit position. */
  per_table = (uint64_t)c->steps_per_rev * c->microsteps * c->gear_num / c->gear_den;
  if (per_table == 0 || per_table > 0x00FFFFFFu) return CP_ERR_RANGE;
  return CP_OK;
}

void cp_default_config(cp_config* c) {
  c->steps_per_rev = 200;
  c->microsteps = 16;
  c->gear_num = 3; /* a 60:20 belt reduction: 9600 microsteps per table revolution */
  c->gear_den = 1;
  c->max_speed = 4000;
  c->acceleration = 8000;
  c->homing_speed = 1600;
  c->backlash = 32;
}

const char* cp_error_name(int code) {
  switch (code) {
    case CP_OK:
      return "ok";
    case CP_ERR_ARGUMENT:
      return "invalid argument";
    case CP_ERR_TOO_LONG:
      return "frame too long";
    case CP_ERR_COBS:
      return "malformed COBS encoding";
    case CP_ERR_CRC:
      return "CRC mismatch";
    case CP_ERR_LENGTH:
      return "length mismatch";
    case CP_ERR_TRUNCATED:
      return "truncated frame";
    case CP_ERR_UNKNOWN:
      return "unknown message type";
    case CP_ERR_VERSION:
      return "incompatible protocol version";
    case CP_ERR_BUSY:
      return "busy (moving or homing)";
    case CP_ERR_RANGE:
      return "value out of range";
    default:
      return "unknown error";
  }
}

const char* cp_type_name(uint8_t type) {
  if (type & CP_ACK_FLAG) type = (uint8_t)(type & ~CP_ACK_FLAG);
  switch (type) {
    case CP_HELLO:
      return "HELLO";
    case CP_IDENTIFY:
      return "IDENTIFY";
    case CP_STATUS:
      return "STATUS";
    case CP_HOME:
      return "HOME";
    case CP_MOVE_ABS:
      return "MOVE_ABS";
    case CP_MOVE_REL:
      return "MOVE_REL";
    case CP_STOP:
      return "STOP";
    case CP_ESTOP:
      return "ESTOP";
    case CP_GET_CONFIG:
      return "GET_CONFIG";
    case CP_SET_CONFIG:
      return "SET_CONFIG";
    case CP_TRIGGER:
      return "TRIGGER";
    case CP_ENABLE:
      return "ENABLE";
    case CP_LIGHT:
      return "LIGHT";
    case CP_EVENT_BOOT:
      return "BOOT";
    case CP_EVENT_MOVE_DONE:
      return "MOVE_DONE";
    case CP_EVENT_FAULT:
      return "FAULT";
    case CP_NAK:
      return "NAK";
    default:
      return "?";
  }
}
