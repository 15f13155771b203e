#include "tt_board.h"

#include <float.h>

#include "hal.h"
#include "tt_crc16.h"

_Static_assert(sizeof(float) == 4 && FLT_MANT_DIG == 24 && FLT_MAX_EXP == 128,
               "the frame carries IEEE-754 binary32 floats");

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) {
        p[i] = (uint8_t)(v >> (8 * i));
    }
}

static void put_f32(uint8_t *p, float v)
{
    union {
        float f;
        uint32_t u;
    } bits;
    bits.f = v;
    put_u32(p, bits.u);
}

size_t tt_board_record_pack(const tt_board_record *rec, uint8_t out[TT_BOARD_RECORD_MAX])
{
    size_t at = 24;
    out[0] = rec->version;
    out[1] = rec->type;
    put_u16(out + 2, rec->seq);
    put_u32(out + 4, rec->t_us);
    put_f32(out + 8, rec->flux_uv);
    put_f32(out + 12, rec->tc_uv);
    put_f32(out + 16, rec->cj_c);
    put_f32(out + 20, rec->force_n);
    if (rec->version != TT_BOARD_VERSION) {
        put_f32(out + 24, rec->ir_object_c);
        put_f32(out + 28, rec->ir_ambient_c);
        put_f32(out + 32, rec->pad_drive);
        at = 36;
    }
    out[at] = rec->status;
    put_u16(out + at + 1, tt_crc16(out, at + 1));
    return at + 3;
}

size_t tt_board_frame(const tt_board_record *rec, uint8_t out[TT_BOARD_FRAME_MAX])
{
    uint8_t raw[TT_BOARD_RECORD_MAX];
    size_t n = tt_cobs_encode(raw, tt_board_record_pack(rec, raw), out);
    out[n] = 0x00;
    return n + 1;
}

void tt_board_encoder_init(tt_board_encoder *enc, uint8_t version)
{
    enc->version = version;
    enc->seq = 0;
}

size_t tt_board_boot_frame(tt_board_encoder *enc, uint32_t t_us, float cj_c,
                           uint8_t out[TT_BOARD_FRAME_MAX])
{
    const tt_board_record rec = {enc->version, TT_BOARD_TYPE_BOOT, 0, t_us,
                                 0.0f, 0.0f, cj_c, 0.0f, 0.0f, 0.0f, 0.0f, 0};
    enc->seq = 1;
    return tt_board_frame(&rec, out);
}

size_t tt_board_sample_frame(tt_board_encoder *enc, const tt_board_sample *s,
                             uint8_t out[TT_BOARD_FRAME_MAX])
{
    const tt_board_record rec = {enc->version, TT_BOARD_TYPE_SAMPLE, enc->seq, s->t_us,
                                 s->flux_uv, s->tc_uv, s->cj_c, s->force_n, s->ir_object_c,
                                 s->ir_ambient_c, s->pad_drive, s->status};
    enc->seq = (uint16_t)(enc->seq + 1u);
    return tt_board_frame(&rec, out);
}

static void send(tt_board_app *app, const uint8_t *frame, size_t len)
{
    if (hal_uart_write(frame, len) == 0) {
        app->frames++;
    } else {
        app->write_errors++;
    }
}

void tt_board_app_start(tt_board_app *app, uint8_t version, float cj_c)
{
    uint8_t frame[TT_BOARD_FRAME_MAX];
    app->frames = 0;
    app->write_errors = 0;
    tt_board_encoder_init(&app->enc, version);
    send(app, frame, tt_board_boot_frame(&app->enc, hal_micros(), cj_c, frame));
}

int tt_board_app_poll(tt_board_app *app)
{
    tt_board_sample s;
    int ready = hal_sensor_read(&s);
    if (ready > 0) {
        uint8_t frame[TT_BOARD_FRAME_MAX];
        send(app, frame, tt_board_sample_frame(&app->enc, &s, frame));
    }
    return ready;
}
