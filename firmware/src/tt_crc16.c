#include "tt_crc16.h"

/* Bitwise: 8 shifts per byte, no table (a 25-byte record costs ~200 shifts
 * at 1 kHz, nothing for any MCU; a lab short of cycles can swap in a
 * 512-byte table without changing the result). */
uint16_t tt_crc16_update(uint16_t crc, const uint8_t *data, size_t len)
{
    for (size_t i = 0; i < len; i++) {
        crc ^= (uint16_t)((uint16_t)data[i] << 8);
        for (int bit = 0; bit < 8; bit++) {
            if (crc & 0x8000u) {
                crc = (uint16_t)((crc << 1) ^ 0x1021u);
            } else {
                crc = (uint16_t)(crc << 1);
            }
        }
    }
    return crc;
}

uint16_t tt_crc16(const uint8_t *data, size_t len)
{
    return tt_crc16_update(TT_CRC16_INIT, data, len);
}
