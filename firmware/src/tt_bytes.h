/* Little-endian byte helpers shared by the CAN codecs (tt_peltier.c,
 * tt_pad.c): one codec file, so neither codec includes the other. */
#ifndef TT_BYTES_H
#define TT_BYTES_H

#include <stdint.h>

/* int16 little-endian, two's complement, without implementation-defined
 * conversions. */
int16_t tt_get_i16(const uint8_t *p);
void tt_put_i16(uint8_t *p, int16_t v);

#endif
