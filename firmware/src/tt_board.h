/* The sensor boards' serial frames, versions 1 and 2 (proto/SERIAL.md).
 *
 * A frame is a little-endian record, its CRC-16/CCITT-FALSE included,
 * COBS-encoded and ended by one 0x00. Version 1 (the display's board), 27
 * bytes:
 *
 *    0  u8   version   1
 *    1  u8   type      1 sample, 2 boot (after a restart; seq from 0)
 *    2  u16  seq       +1 per frame, wraps at 65536
 *    4  u32  t_us      the board's clock, microseconds, wraps
 *    8  f32  flux_uv   heat-flux sensor output, microvolts
 *   12  f32  tc_uv     type-T thermocouple output, microvolts
 *   16  f32  cj_c      cold-junction temperature, degC
 *   20  f32  force_n   force on the pad, N
 *   24  u8   status    bit 0 flux ADC ok, bit 1 thermocouple ok, bit 2 force ok
 *   25  u16  crc       over bytes 0..24
 *
 * Version 2 (the slave's board: an IR thermometer and an active pad), 39
 * bytes: bytes 0..23 as version 1, then
 *
 *   24  f32  ir_object_c   the IR thermometer's object temperature, degC
 *   28  f32  ir_ambient_c  the IR sensor's own temperature, degC
 *   32  f32  pad_drive     Peltier current fraction (-1..1) or heater duty (0..1)
 *   36  u8   status        bits 0-2 as version 1; bit 3 IR ok; bit 4 heater
 *                          on; bit 5 pump on
 *   37  u16  crc           over bytes 0..36
 *
 * A board sends one version only. Floats are IEEE-754 binary32, written byte by byte (little-endian
 * whatever the MCU's own byte order). */
#ifndef TT_BOARD_H
#define TT_BOARD_H

#include <stddef.h>
#include <stdint.h>

#include "tt_cobs.h"
#include "tt_types.h"

#define TT_BOARD_VERSION 1u       /* the display's board */
#define TT_BOARD_VERSION_SLAVE 2u /* the slave's board */
#define TT_BOARD_TYPE_SAMPLE 1u
#define TT_BOARD_TYPE_BOOT 2u

#define TT_BOARD_STATUS_FLUX 0x01u
#define TT_BOARD_STATUS_TC 0x02u
#define TT_BOARD_STATUS_FORCE 0x04u
#define TT_BOARD_STATUS_ALL 0x07u
#define TT_BOARD_STATUS_IR 0x08u     /* version 2 */
#define TT_BOARD_STATUS_HEATER 0x10u /* version 2 */
#define TT_BOARD_STATUS_PUMP 0x20u   /* version 2 */

#define TT_BOARD_RECORD_BYTES 27u    /* version 1, CRC included */
#define TT_BOARD_RECORD_BYTES_V2 39u /* version 2, CRC included */
#define TT_BOARD_RECORD_MAX TT_BOARD_RECORD_BYTES_V2
/* A whole frame on the wire: COBS of the record plus the 0x00 delimiter. */
#define TT_BOARD_FRAME_MAX (TT_COBS_MAX_ENCODED(TT_BOARD_RECORD_MAX) + 1u)

/* Every field of a record, as on the wire. */
typedef struct {
    uint8_t version;
    uint8_t type;
    uint16_t seq;
    uint32_t t_us;
    float flux_uv;
    float tc_uv;
    float cj_c;
    float force_n;
    float ir_object_c;  /* version 2 only */
    float ir_ambient_c; /* version 2 only */
    float pad_drive;    /* version 2 only */
    uint8_t status;
} tt_board_record;

/* The record's bytes, CRC included: version 1's layout (27 bytes) for
 * version 1, version 2's (39 bytes) for any other, as the Python codec
 * does. Returns the length. */
size_t tt_board_record_pack(const tt_board_record *rec, uint8_t out[TT_BOARD_RECORD_MAX]);

/* A whole frame on the wire (COBS + 0x00) into `out`; returns its length
 * (at most TT_BOARD_FRAME_MAX). */
size_t tt_board_frame(const tt_board_record *rec, uint8_t out[TT_BOARD_FRAME_MAX]);

/* The board's frame version and sequence counter. */
typedef struct {
    uint8_t version;
    uint16_t seq;
} tt_board_encoder;

/* After a restart: frames of `version` (TT_BOARD_VERSION for the
 * display's board, TT_BOARD_VERSION_SLAVE for the slave's); the next frame
 * is the boot frame, seq 0. */
void tt_board_encoder_init(tt_board_encoder *enc, uint8_t version);

/* The boot frame (seq restarts at 0; no channel flagged ok; the cold
 * junction's temperature only). The next sample gets seq 1. */
size_t tt_board_boot_frame(tt_board_encoder *enc, uint32_t t_us, float cj_c,
                           uint8_t out[TT_BOARD_FRAME_MAX]);

/* A sample frame with the next sequence number (wrapping at 65536). */
size_t tt_board_sample_frame(tt_board_encoder *enc, const tt_board_sample *s,
                             uint8_t out[TT_BOARD_FRAME_MAX]);

/* ------------------------------------------------------------------------
 * The board's application: a boot frame at start, then one frame per
 * sample the HAL hands over (hal_sensor_read), written with hal_uart_write. */
typedef struct {
    tt_board_encoder enc;
    uint32_t frames;       /* frames written */
    uint32_t write_errors; /* frames the UART refused (dropped; the driver sees a seq gap) */
} tt_board_app;

/* Restart: frames of `version` from now on; sends the boot frame with the
 * cold junction's temperature. */
void tt_board_app_start(tt_board_app *app, uint8_t version, float cj_c);

/* If the HAL has a sample ready, frame and send it. Returns what
 * hal_sensor_read returned: 1 a frame sent (or counted as refused), 0 no
 * sample ready, < 0 the HAL asks the loop to stop (host builds only). */
int tt_board_app_poll(tt_board_app *app);

#endif
