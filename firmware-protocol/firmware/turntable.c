/* Carousel turntable controller firmware: ATmega328P at 16 MHz, a STEP/DIR stepper driver,
 * a home sensor, camera shutter/focus outputs and the backlight output, driven over the UART with
 * the protocol of firmware-protocol/PROTOCOL.md (carousel_protocol is compiled in).
 *
 * Timer 1 (CTC, 2 MHz) generates the steps: each compare match is one step, and the ISR
 * computes the next interval from a trapezoidal profile exact in distance
 * (v_k^2 = min(v_(k-1)^2 + 2a, vmax^2, 2a * steps left)). Timer 2 ticks at 1 kHz: trigger
 * outputs and the main loop's wake-ups for the watchdog. The main loop decodes frames, runs
 * the move segments (backlash take-up, homing phases) and sleeps between interrupts.
 */
#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <math.h>
#include <stdint.h>
#include <string.h>
#include <util/atomic.h>

#include "carousel/protocol/protocol.h"

#define FW_MAJOR 1
#define FW_MINOR 1
#define FW_PATCH 0
#define MODEL "Carousel TT-328"

#define TIMER1_HZ 2000000.0f /* F_CPU / 8 */

/* Pins (PROTOCOL.md section 6). */
#define STEP_BIT (1u << PD2)
#define DIR_BIT (1u << PD5)
#define ENABLE_BIT (1u << PB0) /* active low */
#define HOME_BIT (1u << PB1)   /* active low, pull-up */
#define FOCUS_C_BITS ((1u << PC4) | (1u << PC5))
#define FOCUS_D_BITS ((1u << PD6) | (1u << PD7))
#define BACKLIGHT_BIT (1u << PB4) /* active high: the backlight panel's driver */

/* The reset cause, read before anything clears it. */
static uint8_t reset_cause __attribute__((section(".noinit")));

void early_init(void) __attribute__((naked, used, section(".init3")));
void early_init(void) {
  reset_cause = MCUSR;
  MCUSR = 0;
  wdt_disable(); /* a watchdog reset leaves the watchdog running */
}

/* ---- configuration in EEPROM ---------------------------------------------------------------- */
#define EEPROM_MAGIC 0xC7A1u
typedef struct {
  uint16_t magic;
  uint8_t version;
  uint8_t raw[CP_CONFIG_SIZE];
  uint16_t crc;
} stored_config;
static stored_config EEMEM eeprom_config;
static cp_config config;

static void load_config(void) {
  stored_config s;
  cp_frame f;
  eeprom_read_block(&s, &eeprom_config, sizeof s);
  memcpy(f.payload, s.raw, CP_CONFIG_SIZE);
  f.len = CP_CONFIG_SIZE;
  if (s.magic != EEPROM_MAGIC || s.version != 1 || s.crc != cp_crc16(s.raw, CP_CONFIG_SIZE) ||
      cp_get_config(&f, &config) != CP_OK)
    cp_default_config(&config);
}

static void save_config(void) {
  stored_config s;
  cp_frame f;
  cp_put_config(&f, &config);
  s.magic = EEPROM_MAGIC;
  s.version = 1;
  memcpy(s.raw, f.payload, CP_CONFIG_SIZE);
  s.crc = cp_crc16(s.raw, CP_CONFIG_SIZE);
  eeprom_update_block(&s, &eeprom_config, sizeof s);
}

/* ---- UART ------------------------------------------------------------------------------------ */
#define RX_SIZE 128u
static volatile uint8_t rx_buffer[RX_SIZE];
static volatile uint8_t rx_head, rx_tail;
static volatile uint16_t dropped_frames;

ISR(USART_RX_vect) {
  /* A framing error or an overrun shows as a CRC failure; a full buffer drops the byte,
   * and with it the frame. */
  const uint8_t byte = UDR0;
  const uint8_t next = (uint8_t)((rx_head + 1u) % RX_SIZE);
  if (next == rx_tail) return;
  rx_buffer[rx_head] = byte;
  rx_head = next;
}

static int rx_pop(uint8_t* byte) {
  int got = 0;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    if (rx_tail != rx_head) {
      *byte = rx_buffer[rx_tail];
      rx_tail = (uint8_t)((rx_tail + 1u) % RX_SIZE);
      got = 1;
    }
  }
  return got;
}

static void uart_send(const uint8_t* data, uint8_t size) {
  uint8_t i;
  for (i = 0; i < size; ++i) {
    while (!(UCSR0A & (1u << UDRE0))) {
    }
    UDR0 = data[i];
  }
}

static void uart_init(void) {
  /* 115200 baud: U2X, UBRR 16 (2.1 % error, within the 8N1 tolerance). */
  UCSR0A = (1u << U2X0);
  UBRR0H = 0;
  UBRR0L = 16;
  UCSR0C = (1u << UCSZ01) | (1u << UCSZ00);
  UCSR0B = (1u << RXEN0) | (1u << TXEN0) | (1u << RXCIE0);
}

/* ---- motion ---------------------------------------------------------------------------------- */
enum phase { IDLE, MOVE, MOVE_APPROACH, HOME_SEEK, HOME_RELEASE };
static volatile int32_t position;   /* microsteps */
static volatile int32_t seg_target; /* end of the running segment */
static volatile int8_t dir;         /* +1 / -1 */
static volatile float v2;           /* speed^2 of the last interval */
static float two_a, vmax2;          /* the running segment's limits */
static volatile uint8_t running;    /* timer 1 is stepping */
static volatile uint8_t segment_done;
static volatile uint8_t stop_request;
static volatile uint8_t seen_sensor; /* HOME_RELEASE: the sensor was active */
static volatile uint8_t edge_found;
static volatile int32_t edge_position;
static volatile uint8_t phase = IDLE;
static int32_t final_target; /* the command's target */
static uint8_t stopping;     /* STOP received: no further segment */
static uint8_t homed, hold, fault;

static uint8_t sensor_active(void) { return (PINB & HOME_BIT) == 0; }

static void driver_enable(uint8_t on) {
  if (on)
    PORTB &= (uint8_t)~ENABLE_BIT;
  else
    PORTB |= ENABLE_BIT;
}

static uint16_t interval_ticks(float speed2) {
  const float ticks = ceilf(TIMER1_HZ / sqrtf(speed2));
  return ticks >= 65536.0f ? 65535u : (uint16_t)ticks;
}

ISR(TIMER1_COMPA_vect) {
  uint32_t remaining;
  PORTD |= STEP_BIT;
  position += dir;
  remaining = dir > 0 ? (uint32_t)(seg_target - position) : (uint32_t)(position - seg_target);
  if (phase == HOME_SEEK && sensor_active()) stop_request = 1;
  if (phase == HOME_RELEASE && !edge_found) {
    if (sensor_active()) {
      seen_sensor = 1;
    } else if (seen_sensor) {
      edge_found = 1;
      edge_position = position;
      stop_request = 1;
    }
  }
  if (stop_request) {
    const uint32_t need = (uint32_t)ceilf(v2 / two_a);
    stop_request = 0;
    if (need < remaining) {
      remaining = need;
      seg_target = position + (dir > 0 ? (int32_t)need : -(int32_t)need);
    }
  }
  if (remaining == 0) {
    TCCR1B = 0;
    TIMSK1 = 0;
    v2 = 0.0f;
    running = 0;
    segment_done = 1;
  } else {
    float next = v2 + two_a;
    const float limit = two_a * (float)remaining;
    if (next > vmax2) next = vmax2;
    if (next > limit) next = limit;
    v2 = next;
    OCR1A = interval_ticks(next) - 1u;
  }
  PORTD &= (uint8_t)~STEP_BIT;
}

/* Starts a segment from rest towards `target` with top speed `speed`. */
static void start_segment(int32_t target, uint16_t speed) {
  const int32_t delta = target - position;
  uint32_t steps;
  float first;
  if (delta == 0) {
    segment_done = 1;
    return;
  }
  dir = delta > 0 ? 1 : -1;
  steps = delta > 0 ? (uint32_t)delta : (uint32_t)(-delta);
  if (dir > 0)
    PORTD |= DIR_BIT;
  else
    PORTD &= (uint8_t)~DIR_BIT;
  two_a = 2.0f * (float)config.acceleration;
  vmax2 = (float)speed * (float)speed;
  first = two_a;
  if (first > vmax2) first = vmax2;
  if (first > two_a * (float)steps) first = two_a * (float)steps;
  /* The driver is enabled at least one interval (>= 2.7 ms) before the first step. */
  driver_enable(1);
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    seg_target = target;
    v2 = first;
    stop_request = 0;
    segment_done = 0;
    running = 1;
    TCCR1A = 0;
    TCNT1 = 0;
    OCR1A = interval_ticks(first) - 1u;
    TIFR1 = (1u << OCF1A);
    TIMSK1 = (1u << OCIE1A);
    TCCR1B = (1u << WGM12) | (1u << CS11);
  }
}

static void halt_now(void) {
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TCCR1B = 0;
    TIMSK1 = 0;
    running = 0;
    segment_done = 0;
    v2 = 0.0f;
    seg_target = position;
  }
}

/* ---- trigger outputs ----------------------------------------------------------------------- */
static volatile uint16_t trigger_ms_left;
static volatile uint16_t milliseconds;

static void outputs_off(void) {
  PORTC &= (uint8_t) ~(0x0Fu | FOCUS_C_BITS);
  PORTD &= (uint8_t)~FOCUS_D_BITS;
}

ISR(TIMER2_COMPA_vect) {
  ++milliseconds;
  if (trigger_ms_left != 0 && --trigger_ms_left == 0) outputs_off();
}

static void trigger(const cp_trigger* t) {
  uint8_t c = 0, d = 0;
  if (t->outputs & CP_OUTPUT_SHUTTER) c |= (uint8_t)(t->cameras & 0x0Fu);
  if (t->outputs & CP_OUTPUT_FOCUS) {
    if (t->cameras & 1u) c |= (1u << PC4);
    if (t->cameras & 2u) c |= (1u << PC5);
    if (t->cameras & 4u) d |= (1u << PD6);
    if (t->cameras & 8u) d |= (1u << PD7);
  }
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    outputs_off();
    PORTC |= c;
    PORTD |= d;
    trigger_ms_left = t->duration_ms;
  }
}

/* ---- frames ---------------------------------------------------------------------------------- */
static uint8_t event_seq;
static uint8_t hello_ok;
static uint8_t last_type, last_seq, last_valid;
static uint8_t last_reply[CP_MAX_WIRE];
static uint8_t last_reply_size;

static void send_frame(const cp_frame* f) {
  uint8_t wire[CP_MAX_WIRE];
  const int n = cp_encode(f, wire, sizeof wire);
  if (n > 0) uart_send(wire, (uint8_t)n);
}

static void fill_status(cp_frame* f) {
  cp_status s;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    s.position = position;
    s.dropped_frames = dropped_frames;
  }
  s.target = final_target;
  s.flags = 0;
  if (phase != IDLE) s.flags |= CP_FLAG_MOVING;
  if (homed) s.flags |= CP_FLAG_HOMED;
  if (!(PORTB & ENABLE_BIT)) s.flags |= CP_FLAG_ENABLED;
  if (phase == HOME_SEEK || phase == HOME_RELEASE) s.flags |= CP_FLAG_HOMING;
  if (sensor_active()) s.flags |= CP_FLAG_SENSOR;
  if (hold) s.flags |= CP_FLAG_HOLD;
  if (PORTB & BACKLIGHT_BIT) s.flags |= CP_FLAG_BACKLIGHT;
  s.fault = fault;
  cp_put_status(f, &s);
}

static void send_event(uint8_t type, uint8_t reason) {
  cp_frame f;
  f.type = type;
  f.seq = event_seq++;
  fill_status(&f);
  if (type == CP_EVENT_MOVE_DONE) f.payload[f.len++] = reason;
  send_frame(&f);
}

static void finish(uint8_t reason) {
  phase = IDLE;
  stopping = 0;
  if (!hold) driver_enable(0);
  send_event(CP_EVENT_MOVE_DONE, reason);
}

/* Starts a move to `target`, ending with a positive approach. */
static void begin_move(int32_t target) {
  int32_t first = target;
  fault = fault == CP_FAULT_HOME_NOT_FOUND ? fault : CP_FAULT_NONE;
  final_target = target;
  stopping = 0;
  if (target < position && config.backlash > 0) first = target - (int32_t)config.backlash;
  phase = first == target ? MOVE_APPROACH : MOVE;
  start_segment(first, config.max_speed);
}

static uint32_t search_span(void) {
  return cp_steps_per_table_rev(&config) + cp_steps_per_table_rev(&config) / 4u;
}

/* Homing ended without finding the sensor (or its edge). */
static void home_failed(void) {
  fault = CP_FAULT_HOME_NOT_FOUND;
  final_target = position;
  phase = IDLE;
  if (!hold) driver_enable(0);
  send_event(CP_EVENT_FAULT, 0);
}

/* The main loop's part of the motion: what follows a finished segment. */
static void advance_motion(void) {
  uint8_t done;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    done = segment_done;
    segment_done = 0;
  }
  if (!done || phase == IDLE) return;
  if (stopping) {
    final_target = position;
    finish(CP_DONE_STOPPED);
    return;
  }
  switch (phase) {
    case MOVE:
      phase = MOVE_APPROACH;
      start_segment(final_target, config.max_speed);
      break;
    case MOVE_APPROACH:
      finish(CP_DONE_REACHED);
      break;
    case HOME_SEEK:
      if (!sensor_active()) {
        home_failed();
        break;
      }
      phase = HOME_RELEASE;
      seen_sensor = 0;
      edge_found = 0;
      start_segment(position + (int32_t)search_span(), config.homing_speed / 4u);
      break;
    case HOME_RELEASE:
      if (!edge_found) {
        home_failed();
        break;
      }
      ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { position -= edge_position; }
      final_target = position;
      homed = 1;
      finish(CP_DONE_HOMED);
      break;
    default:
      break;
  }
}

static int busy(void) { return phase != IDLE; }

/* Executes one command; fills `reply` (type, payload) or returns a negative code for a NAK. */
static int execute(const cp_frame* cmd, cp_frame* reply) {
  reply->len = 0;
  if (!hello_ok && cmd->type != CP_HELLO && cmd->type != CP_IDENTIFY) return CP_ERR_VERSION;
  switch (cmd->type) {
    case CP_HELLO:
      if (cmd->len < 2 || cmd->payload[0] != CP_VERSION_MAJOR) return CP_ERR_VERSION;
      hello_ok = 1;
      reply->payload[0] = CP_VERSION_MAJOR;
      reply->payload[1] = CP_VERSION_MINOR;
      reply->payload[2] = reset_cause;
      reply->len = 3;
      return CP_OK;
    case CP_IDENTIFY: {
      const uint8_t n = (uint8_t)strlen(MODEL);
      reply->payload[0] = CP_VERSION_MAJOR;
      reply->payload[1] = CP_VERSION_MINOR;
      reply->payload[2] = FW_MAJOR;
      reply->payload[3] = FW_MINOR;
      reply->payload[4] = FW_PATCH;
      memcpy(reply->payload + 5, MODEL, n);
      reply->len = (uint8_t)(5u + n);
      return CP_OK;
    }
    case CP_STATUS:
      break;
    case CP_HOME:
      if (busy()) return CP_ERR_BUSY;
      fault = CP_FAULT_NONE;
      homed = 0;
      stopping = 0;
      phase = HOME_SEEK;
      final_target = 0;
      if (sensor_active()) {
        /* Already on the sensor: release from here. */
        segment_done = 1;
      } else {
        start_segment(position - (int32_t)search_span(), config.homing_speed);
      }
      break;
    case CP_MOVE_ABS:
    case CP_MOVE_REL: {
      int32_t value;
      if (cmd->len < 4) return CP_ERR_LENGTH;
      if (busy()) return CP_ERR_BUSY;
      value = cp_get_i32(cmd->payload);
      if (cmd->type == CP_MOVE_REL) {
        const int32_t from = final_target;
        if ((value > 0 && from > INT32_MAX / 2 - value) ||
            (value < 0 && from < INT32_MIN / 2 - value))
          return CP_ERR_RANGE;
        value = from + value;
      }
      if (value > INT32_MAX / 2 || value < INT32_MIN / 2) return CP_ERR_RANGE;
      begin_move(value);
      break;
    }
    case CP_STOP:
      if (busy()) {
        stopping = 1;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
          if (running) stop_request = 1;
        }
      }
      break;
    case CP_ESTOP:
      halt_now();
      driver_enable(0);
      if (busy()) {
        phase = IDLE;
        stopping = 0;
        fault = CP_FAULT_ESTOP;
        final_target = position;
        send_event(CP_EVENT_MOVE_DONE, CP_DONE_ESTOP);
      }
      break;
    case CP_GET_CONFIG:
      cp_put_config(reply, &config);
      return CP_OK;
    case CP_SET_CONFIG: {
      cp_config next;
      if (busy()) return CP_ERR_BUSY;
      if (cmd->len < CP_CONFIG_SIZE) return CP_ERR_LENGTH;
      if (cp_get_config(cmd, &next) != CP_OK) return CP_ERR_RANGE;
      config = next;
      save_config();
      cp_put_config(reply, &config);
      return CP_OK;
    }
    case CP_TRIGGER: {
      cp_trigger t;
      const int r = cp_get_trigger(cmd, &t);
      if (r != CP_OK) return r;
      trigger(&t);
      return CP_OK;
    }
    case CP_LIGHT:
      /* Lights switch at once, moving or not (a mask shot is taken at rest anyway). */
      if (cmd->len < 1) return CP_ERR_LENGTH;
      if (cmd->payload[0] & (uint8_t)~CP_LIGHT_ALL) return CP_ERR_RANGE;
      if (cmd->payload[0] & CP_LIGHT_BACKLIGHT)
        PORTB |= BACKLIGHT_BIT;
      else
        PORTB &= (uint8_t)~BACKLIGHT_BIT;
      break;
    case CP_ENABLE:
      if (cmd->len < 1) return CP_ERR_LENGTH;
      hold = cmd->payload[0] ? 1u : 0u;
      if (!busy()) driver_enable(hold);
      break;
    default:
      return CP_ERR_UNKNOWN;
  }
  fill_status(reply);
  return CP_OK;
}

static void handle(const cp_frame* cmd) {
  cp_frame reply;
  int result, n;
  if (cmd->type >= CP_EVENT_BOOT) return; /* not a command */
  if (last_valid && cmd->type == last_type && cmd->seq == last_seq) {
    uart_send(last_reply, last_reply_size); /* a retransmission: same reply, no new action */
    return;
  }
  result = execute(cmd, &reply);
  reply.seq = cmd->seq;
  if (result == CP_OK) {
    reply.type = (uint8_t)(cmd->type | CP_ACK_FLAG);
  } else {
    reply.type = CP_NAK;
    reply.payload[0] = cmd->type;
    reply.payload[1] = (uint8_t)(-result);
    reply.len = 2;
  }
  n = cp_encode(&reply, last_reply, sizeof last_reply);
  if (n <= 0) return;
  last_reply_size = (uint8_t)n;
  last_type = cmd->type;
  last_seq = cmd->seq;
  last_valid = 1;
  uart_send(last_reply, last_reply_size);
}

/* ---- start-up and main loop ------------------------------------------------------------------ */
int main(void) {
  cp_decoder decoder;
  cp_frame frame;
  uint8_t byte;
  /* The driver's /ENABLE has a pull-up: drive it high before it becomes an output, so the
   * driver is never enabled, not even for a cycle, at reset. */
  PORTB |= ENABLE_BIT | HOME_BIT;   /* HOME_BIT: the sensor input's pull-up */
  PORTB &= (uint8_t)~BACKLIGHT_BIT; /* the backlight starts off (after any reset) */
  DDRB |= ENABLE_BIT | BACKLIGHT_BIT;
  PORTD &= (uint8_t) ~(STEP_BIT | DIR_BIT | FOCUS_D_BITS);
  DDRD |= STEP_BIT | DIR_BIT | FOCUS_D_BITS;
  PORTC &= (uint8_t) ~(0x0Fu | FOCUS_C_BITS);
  DDRC |= 0x0Fu | FOCUS_C_BITS;
  if (reset_cause & (1u << WDRF)) fault = CP_FAULT_WATCHDOG;

  load_config();
  uart_init();
  /* Timer 2: 1 kHz (CTC, clk/64, 250 counts). */
  TCCR2A = (1u << WGM21);
  OCR2A = 249;
  TIMSK2 = (1u << OCIE2A);
  TCCR2B = (1u << CS22);
  cp_decoder_init(&decoder);
  wdt_enable(WDTO_500MS);
  sei();

  {
    cp_frame boot;
    boot.type = CP_EVENT_BOOT;
    boot.seq = event_seq++;
    boot.payload[0] = CP_VERSION_MAJOR;
    boot.payload[1] = CP_VERSION_MINOR;
    boot.payload[2] = reset_cause;
    boot.len = 3;
    byte = 0;
    uart_send(&byte, 1); /* flush whatever partial frame the host's receiver holds */
    send_frame(&boot);
  }

  set_sleep_mode(SLEEP_MODE_IDLE);
  for (;;) {
    wdt_reset();
    while (rx_pop(&byte)) {
      const int r = cp_decoder_push(&decoder, byte, &frame);
      if (r == 1) {
        handle(&frame);
      } else if (r < 0) {
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { ++dropped_frames; }
      }
    }
    advance_motion();
    cli();
    if (rx_head == rx_tail && !segment_done) {
      sleep_enable();
      sei();
      sleep_cpu();
      sleep_disable();
    }
    sei();
  }
}
