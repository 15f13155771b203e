/* The sensor board's serial frames, version 1 (proto/SERIAL.md).
 *
 * A frame is a 27-byte little-endian record, its CRC-16/CCITT-FALSE
 * included, COBS-encoded and ended by one 0x00:
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
 * Floats are IEEE-754 binary32, written byte by byte (little-endian
 * whatever the MCU's own byte order). */
#ifndef TT_BOARD_H
#define TT_BOARD_H

#include <stddef.h>
#include <stdint.h>

#include "tt_cobs.h"

#define TT_BOARD_VERSION 1u
#define TT_BOARD_TYPE_SAMPLE 1u
#define TT_BOARD_TYPE_BOOT 2u

#define TT_BOARD_STATUS_FLUX 0x01u
#define TT_BOARD_STATUS_TC 0x02u
#define TT_BOARD_STATUS_FORCE 0x04u
#define TT_BOARD_STATUS_ALL 0x07u

#define TT_BOARD_RECORD_BYTES 27u /* CRC included */
/* A whole frame on the wire: COBS of the record plus the 0x00 delimiter. */
#define TT_BOARD_FRAME_MAX (TT_COBS_MAX_ENCODED(TT_BOARD_RECORD_BYTES) + 1u)

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
    uint8_t status;
} tt_board_record;

/* One sample of the board's channels; a channel that could not be read
 * has its status bit clear (its value is then ignored by the driver). */
typedef struct {
    uint32_t t_us; /* the board's clock when the channels were sampled */
    float flux_uv;
    float tc_uv;
    float cj_c;
    float force_n;
    uint8_t status;
} tt_board_sample;

/* The 27 record bytes, CRC included. */
void tt_board_record_pack(const tt_board_record *rec, uint8_t out[TT_BOARD_RECORD_BYTES]);

/* A whole frame on the wire (COBS + 0x00) into `out`; returns its length
 * (at most TT_BOARD_FRAME_MAX). */
size_t tt_board_frame(const tt_board_record *rec, uint8_t out[TT_BOARD_FRAME_MAX]);

/* The board's sequence counter. */
typedef struct {
    uint16_t seq;
} tt_board_encoder;

/* After a restart: the next frame is the boot frame, seq 0. */
void tt_board_encoder_init(tt_board_encoder *enc);

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

/* Restart: sends the boot frame with the cold junction's temperature. */
void tt_board_app_start(tt_board_app *app, float cj_c);

/* If the HAL has a sample ready, frame and send it. Returns what
 * hal_sensor_read returned: 1 a frame sent (or counted as refused), 0 no
 * sample ready, < 0 the HAL asks the loop to stop (host builds only). */
int tt_board_app_poll(tt_board_app *app);

#endif
