/* CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection,
 * no final xor. Check value: the nine bytes "123456789" give 0x29B1.
 * The sensor board's frames carry it over their record (proto/SERIAL.md). */
#ifndef TT_CRC16_H
#define TT_CRC16_H

#include <stddef.h>
#include <stdint.h>

#define TT_CRC16_INIT 0xFFFFu

/* Continue a CRC over `len` bytes: start with TT_CRC16_INIT. */
uint16_t tt_crc16_update(uint16_t crc, const uint8_t *data, size_t len);

/* The CRC of `len` bytes. */
uint16_t tt_crc16(const uint8_t *data, size_t len);

#endif
