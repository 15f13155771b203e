#include "tt_bytes.h"

int16_t tt_get_i16(const uint8_t *p)
{
    uint16_t u = (uint16_t)(p[0] | (p[1] << 8));
    /* Two's complement without implementation-defined conversions. */
    return u < 0x8000u ? (int16_t)u : (int16_t)(-(int32_t)(0x10000u - u));
}

void tt_put_i16(uint8_t *p, int16_t v)
{
    uint16_t u = (uint16_t)v; /* modulo 2^16: well defined */
    p[0] = (uint8_t)(u & 0xFFu);
    p[1] = (uint8_t)(u >> 8);
}
