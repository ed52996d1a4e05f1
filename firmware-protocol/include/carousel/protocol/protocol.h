/* carousel_protocol: the turntable controller's wire protocol (contract; issue 7 builds it).
 *
 * Pure C99 with no dependencies, compiled both into the host (rig/) and into the ATmega328P
 * firmware. Specified first in firmware-protocol/PROTOCOL.md:
 *   - framing: sync byte or COBS, length, sequence number, payload, CRC-16; a maximum frame
 *     size; a version handshake (host and firmware refuse incompatible versions);
 *   - commands: identify, home, move absolute/relative (microsteps), stop, emergency stop,
 *     status, set configuration (persisted in EEPROM), trigger shutter/focus outputs;
 *   - events (move done, fault), ack/nak, retransmission on timeout, idempotent replays by
 *     sequence number.
 * Every function carries the prefix `cp_` and returns 0 or a documented negative error code;
 * rig/ converts codes to carousel::ProtocolError / DeviceError at its boundary.
 */
#ifndef CAROUSEL_PROTOCOL_PROTOCOL_H_
#define CAROUSEL_PROTOCOL_PROTOCOL_H_
#endif /* CAROUSEL_PROTOCOL_PROTOCOL_H_ */
