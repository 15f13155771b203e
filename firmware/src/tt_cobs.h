/* Consistent Overhead Byte Stuffing (Cheshire & Baker 1999): the encoded
 * packet holds no 0x00, so 0x00 can delimit frames on the line. */
#ifndef TT_COBS_H
#define TT_COBS_H

#include <stddef.h>
#include <stdint.h>

/* The most bytes COBS makes of `n` input bytes (no delimiter included). */
#define TT_COBS_MAX_ENCODED(n) ((n) + (n) / 254u + 1u)

/* Encode `len` bytes of `in` into `out` (room for TT_COBS_MAX_ENCODED(len)
 * bytes; `out` must not overlap `in`). Returns the encoded length. No
 * delimiter is written. */
size_t tt_cobs_encode(const uint8_t *in, size_t len, uint8_t *out);

/* Decode one packet (no delimiter) into `out` (room for `len` bytes).
 * Returns the decoded length, or (size_t)-1 if the packet is not COBS
 * (a 0x00 inside, or a code running past the end). Kept for a lab's own
 * tests and for boards that receive frames; the encoder does not use it. */
size_t tt_cobs_decode(const uint8_t *in, size_t len, uint8_t *out);

#endif
