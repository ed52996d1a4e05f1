/* libFuzzer target for carousel_protocol's frame decoder (scripts/fuzz-protocol runs it for
 * a bounded time in CI). Every byte string is fed to the streaming decoder; each frame it
 * yields must re-encode to a wire frame that decodes to the same frame, and the payload
 * codecs must accept or reject it without reading outside the frame. */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "carousel/protocol/protocol.h"

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  cp_decoder decoder;
  size_t i;
  cp_decoder_init(&decoder);
  for (i = 0; i < size; ++i) {
    cp_frame frame, again;
    uint8_t wire[CP_MAX_WIRE];
    int n, r;
    cp_status status;
    cp_config config;
    cp_trigger trigger;
    memset(&frame, 0, sizeof frame);
    r = cp_decoder_push(&decoder, data[i], &frame);
    if (r < 0 && (r < CP_ERR_TRUNCATED || r > CP_ERR_TOO_LONG)) abort(); /* only frame errors */
    if (r != 1) continue;
    if (frame.len > CP_MAX_PAYLOAD) abort();
    n = cp_encode(&frame, wire, sizeof wire);
    if (n < CP_MIN_RAW + 2 || n > CP_MAX_WIRE) abort();
    memset(&again, 0, sizeof again);
    if (cp_decode(wire, (size_t)n - 1, &again) != CP_OK) abort();
    if (again.type != frame.type || again.seq != frame.seq || again.len != frame.len ||
        memcmp(again.payload, frame.payload, frame.len) != 0)
      abort();
    (void)cp_get_status(&frame, &status);
    (void)cp_get_config(&frame, &config);
    (void)cp_get_trigger(&frame, &trigger);
    (void)cp_type_name(frame.type);
  }
  return 0;
}
