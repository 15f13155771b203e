/* The firmware's codecs as a text tool on stdin/stdout (host/tt_codec.c). */
#ifndef TT_CODEC_H
#define TT_CODEC_H

#include <stdint.h>

/* CRC check value, COBS reference vectors, boot frame and sequence wrap;
 * prints "selftest: N checks, M failed". Returns 0, or 1 on a failure. */
int tt_codec_selftest(void);

/* stdin "version type seq t_us flux tc cj force status [ir_object ir_ambient
 * pad_drive]" per line -> stdout the wire frame in hex. 0, or 2 on bad input. */
int tt_codec_serial_encode(void);

/* stdin "decode <id> <hex>" -> "NAME sig=raw ..."; "encode <id> <raw values
 * in DBC order>" -> hex. 0, or 2 on bad input. */
int tt_codec_can(void);

/* Hex digit pairs (up to a space or the end of the line) to bytes; returns
 * the count, or -1 (a bad digit, an odd count, more than `room`). */
int tt_codec_parse_hex(const char *s, uint8_t *out, int room);

#endif
