/* The firmware's codecs as a text tool on stdio: the part of tt_host that
 * needs no HAL, so that the same code runs on the host (host/tt_host.c) and
 * on the microcontroller with stdin and stdout on a UART (stm32f4/main_codec.c,
 * the golden vectors under QEMU). Portable C11 with <stdio.h>; the modes are
 * described at the top of host/tt_host.c. */
#include "tt_codec.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../src/tt_board.h"
#include "../src/tt_cobs.h"
#include "../src/tt_crc16.h"
#include "../src/tt_pad.h"
#include "../src/tt_peltier.h"

static void print_hex(const uint8_t *data, size_t len)
{
    for (size_t i = 0; i < len; i++) {
        printf("%02x", data[i]);
    }
    putchar('\n');
}

static int nibble(char c)
{
    if (c >= '0' && c <= '9') {
        return c - '0';
    }
    if (c >= 'a' && c <= 'f') {
        return c - 'a' + 10;
    }
    if (c >= 'A' && c <= 'F') {
        return c - 'A' + 10;
    }
    return -1;
}

/* Hex digits (pairs, up to a space or the end of the line) to bytes;
 * returns the count or -1. */
int tt_codec_parse_hex(const char *s, uint8_t *out, int room)
{
    int n = 0;
    while (s[0] && s[0] != '\n' && s[0] != ' ') {
        int hi = nibble(s[0]), lo = s[1] ? nibble(s[1]) : -1;
        if (hi < 0 || lo < 0 || n == room) {
            return -1;
        }
        out[n++] = (uint8_t)(hi << 4 | lo);
        s += 2;
    }
    return n;
}

/* ------------------------------------------------------------ selftest */

static int failures, checks;

static void check(int ok, const char *what)
{
    checks++;
    if (!ok) {
        failures++;
        fprintf(stderr, "selftest: FAILED %s\n", what);
    }
}

static void check_cobs(const uint8_t *in, size_t len, const uint8_t *want, size_t want_len,
                       const char *what)
{
    uint8_t enc[600], dec[600];
    size_t n = tt_cobs_encode(in, len, enc);
    check(n == want_len && memcmp(enc, want, n) == 0, what);
    check(n <= TT_COBS_MAX_ENCODED(len), what);
    check(tt_cobs_decode(enc, n, dec) == len && memcmp(dec, in, len) == 0, what);
}

int tt_codec_selftest(void)
{
    failures = checks = 0;
    const uint8_t digits[] = "123456789";
    check(tt_crc16(digits, 9) == 0x29B1u, "CRC-16/CCITT-FALSE check value 0x29B1");
    check(tt_crc16_update(tt_crc16(digits, 4), digits + 4, 5) == 0x29B1u, "CRC in two parts");
    /* COBS reference vectors (Cheshire & Baker's examples). */
    check_cobs((const uint8_t[]){0x00}, 1, (const uint8_t[]){0x01, 0x01}, 2, "COBS 00");
    check_cobs((const uint8_t[]){0x00, 0x00}, 2, (const uint8_t[]){0x01, 0x01, 0x01}, 3,
               "COBS 00 00");
    check_cobs((const uint8_t[]){0x11, 0x22, 0x00, 0x33}, 4,
               (const uint8_t[]){0x03, 0x11, 0x22, 0x02, 0x33}, 5, "COBS 11 22 00 33");
    check_cobs((const uint8_t[]){0x11, 0x00, 0x00, 0x00}, 4,
               (const uint8_t[]){0x02, 0x11, 0x01, 0x01, 0x01}, 5, "COBS 11 00 00 00");
    uint8_t run[300], want[310];
    for (int i = 0; i < 254; i++) {
        run[i] = (uint8_t)(i + 1); /* 01..FE */
    }
    want[0] = 0xFF;
    memcpy(want + 1, run, 254);
    want[255] = 0x01;
    check_cobs(run, 254, want, 256, "COBS 254 non-zero bytes");
    run[254] = 0xFF;
    want[255] = 0x02;
    want[256] = 0xFF;
    check_cobs(run, 255, want, 257, "COBS 255 non-zero bytes");
    check(tt_cobs_decode((const uint8_t[]){0x03, 0x11, 0x00}, 3, run) == (size_t)-1,
          "COBS decode refuses a 0x00 inside");
    check(tt_cobs_decode((const uint8_t[]){0x05, 0x11}, 2, run) == (size_t)-1,
          "COBS decode refuses a short block");
    /* The boot frame restarts the sequence; samples count on and wrap. */
    tt_board_encoder enc;
    uint8_t frame[TT_BOARD_FRAME_MAX], raw[TT_BOARD_RECORD_MAX + 2];
    const tt_board_sample s = {7, 1.0f, 2.0f, 25.0f, 3.0f, 0.0f, 0.0f, 0.0f,
                               TT_BOARD_STATUS_ALL};
    tt_board_encoder_init(&enc, TT_BOARD_VERSION);
    size_t n = tt_board_boot_frame(&enc, 0, 25.0f, frame);
    check(n <= TT_BOARD_FRAME_MAX && frame[n - 1] == 0 && memchr(frame, 0, n - 1) == NULL,
          "boot frame: COBS and one delimiter");
    check(tt_cobs_decode(frame, n - 1, raw) == TT_BOARD_RECORD_BYTES && raw[1] == 2 &&
              raw[2] == 0 && raw[3] == 0,
          "boot frame: type 2, seq 0");
    n = tt_board_sample_frame(&enc, &s, frame);
    check(tt_cobs_decode(frame, n - 1, raw) == TT_BOARD_RECORD_BYTES && raw[1] == 1 &&
              raw[2] == 1 && raw[3] == 0 && tt_crc16(raw, 25) == (raw[25] | raw[26] << 8),
          "first sample: type 1, seq 1, CRC");
    enc.seq = 0xFFFF;
    tt_board_sample_frame(&enc, &s, frame);
    check(enc.seq == 0, "seq wraps at 65536");
    tt_board_encoder_init(&enc, TT_BOARD_VERSION_SLAVE);
    n = tt_board_boot_frame(&enc, 0, 25.0f, frame);
    check(tt_cobs_decode(frame, n - 1, raw) == TT_BOARD_RECORD_BYTES_V2 && raw[0] == 2 &&
              raw[1] == 2 && tt_crc16(raw, 37) == (raw[37] | raw[38] << 8),
          "version 2 boot frame: 39 bytes, CRC");
    printf("selftest: %d checks, %d failed\n", checks, failures);
    return failures ? 1 : 0;
}

/* ------------------------------------------------------------ input lines */

/* The line's whitespace-separated words, in place (each cut at its end):
 * how many, at most `room` (the rest ignored). No scanf here: picolibc's
 * tinystdio scanf pushes a character back with ungetc, whose single weak
 * compare-and-swap (LDREXH/STREXH, no retry) fails whenever an interrupt
 * comes between the two instructions (exception return clears the
 * exclusive monitor, on silicon as in QEMU); the character is then lost
 * and the line misread. The codec image on the core misread about one
 * line in ten thousand under a loaded host's interrupt timing. */
static int words(char *line, char **word, int room)
{
    int n = 0;
    char *p = line;
    while (n < room) {
        p += strspn(p, " \t\r\n");
        if (*p == '\0') {
            break;
        }
        word[n++] = p;
        p += strcspn(p, " \t\r\n");
        if (*p != '\0') {
            *p++ = '\0';
        }
    }
    return n;
}

/* A whole word as an unsigned number in `base` (16 takes an optional 0x):
 * 0, or -1 if the word is not one, is negative or does not fit. */
static int word_ulong(const char *word, int base, unsigned long *out)
{
    char *end;
    if (word[0] == '-') {
        return -1;
    }
    errno = 0;
    *out = strtoul(word, &end, base);
    return end != word && *end == '\0' && errno != ERANGE ? 0 : -1;
}

/* ------------------------------------------------------------ serial-encode */

int tt_codec_serial_encode(void)
{
    char line[512];
    int lineno = 0;
    while (fgets(line, sizeof line, stdin)) {
        unsigned long version = 0, type = 0, seq = 0, status = 0, t_us = 0;
        const char *f[7] = {"0", "0", "0", "0", "0", "0", "0"};
        char copy[sizeof line], *w[13];
        lineno++;
        strcpy(copy, line); /* the line as read, for the error */
        int n = words(copy, w, 13);
        if (n == 9 || n == 12) {
            f[0] = w[4], f[1] = w[5], f[2] = w[6], f[3] = w[7];
            if (n == 12) {
                f[4] = w[9], f[5] = w[10], f[6] = w[11];
            }
        }
        if ((n != 9 && n != 12) || word_ulong(w[0], 10, &version) || word_ulong(w[1], 10, &type) ||
            word_ulong(w[2], 10, &seq) || word_ulong(w[3], 10, &t_us) ||
            word_ulong(w[8], 10, &status) || version > 255 || type > 255 || seq > 0xFFFF ||
            t_us > 0xFFFFFFFFul || status > 255) {
            fprintf(stderr, "serial-encode: line %d: expected 'version type seq t_us flux_uv "
                            "tc_uv cj_c force_n status [ir_object_c ir_ambient_c pad_drive]', "
                            "got %s", lineno, line);
            return 2;
        }
        tt_board_record rec = {(uint8_t)version, (uint8_t)type, (uint16_t)seq,
                               (uint32_t)t_us, strtof(f[0], NULL), strtof(f[1], NULL),
                               strtof(f[2], NULL), strtof(f[3], NULL), strtof(f[4], NULL),
                               strtof(f[5], NULL), strtof(f[6], NULL), (uint8_t)status};
        uint8_t frame[TT_BOARD_FRAME_MAX];
        print_hex(frame, tt_board_frame(&rec, frame));
    }
    return 0;
}

/* ------------------------------------------------------------ can-codec */

static int can_decode(unsigned id, const uint8_t *data, int dlc)
{
    if (id == TT_PELTIER_CMD_ID) {
        tt_peltier_cmd c;
        if (tt_peltier_cmd_decode(data, (uint8_t)dlc, &c) != 0) {
            return -1;
        }
        printf("PELTIER_CMD enable=%u counter=%u current_a=%d version=%u\n", c.enable,
               c.counter, c.current_ma, c.version);
    } else if (id == TT_PELTIER_STATUS_ID) {
        tt_peltier_status s;
        if (tt_peltier_status_decode(data, (uint8_t)dlc, &s) != 0) {
            return -1;
        }
        printf("PELTIER_STATUS enabled=%u over_temp=%u over_current=%u sensor_fault=%u "
               "watchdog=%u sink_saturated=%u counter=%u junction_c=%d current_a=%d "
               "heatsink_c=%d\n",
               s.enabled, s.over_temp, s.over_current, s.sensor_fault, s.watchdog,
               s.sink_saturated, s.counter, s.junction_cc, s.current_ma, s.heatsink_cc);
    } else if (id == TT_PELTIER_HEARTBEAT_ID || id == TT_PAD_HEARTBEAT_ID) {
        tt_peltier_heartbeat h;
        if (tt_peltier_heartbeat_decode(data, (uint8_t)dlc, &h) != 0) {
            return -1;
        }
        printf("%s state=%u version=%u\n",
               id == TT_PAD_HEARTBEAT_ID ? "PAD_HEARTBEAT" : "PELTIER_HEARTBEAT", h.state,
               h.version);
    } else if (id == TT_PAD_CMD_ID) {
        tt_pad_cmd c;
        if (tt_pad_cmd_decode(data, (uint8_t)dlc, &c) != 0) {
            return -1;
        }
        printf("PAD_CMD enable=%u pump=%u counter=%u current_a=%d heater_duty=%u version=%u\n",
               c.enable, c.pump, c.counter, c.current_ma, c.heater_duty_raw, c.version);
    } else if (id == TT_PAD_STATUS_ID) {
        tt_pad_status s;
        if (tt_pad_status_decode(data, (uint8_t)dlc, &s) != 0) {
            return -1;
        }
        printf("PAD_STATUS enabled=%u over_temp=%u sensor_fault=%u watchdog=%u pump_on=%u "
               "heater_on=%u counter=%u actuator_c=%d drive=%d heatsink_c=%d\n",
               s.enabled, s.over_temp, s.sensor_fault, s.watchdog, s.pump_on, s.heater_on,
               s.counter, s.actuator_cc, s.drive_milli, s.heatsink_cc);
    } else {
        return -1;
    }
    return 0;
}

#define MAX_SIGNALS 10

static int can_encode(unsigned id, const long *v, int n)
{
    uint8_t data[8];
    if (id == TT_PELTIER_CMD_ID && n == 4) {
        const tt_peltier_cmd c = {(uint8_t)v[0], (uint8_t)v[1], (int16_t)v[2], (uint8_t)v[3]};
        tt_peltier_cmd_encode(&c, data);
        print_hex(data, TT_PELTIER_CMD_DLC);
    } else if (id == TT_PELTIER_STATUS_ID && n == 10) {
        const tt_peltier_status s = {(uint8_t)v[0], (uint8_t)v[1], (uint8_t)v[2],
                                     (uint8_t)v[3], (uint8_t)v[4], (uint8_t)v[5],
                                     (uint8_t)v[6], (int16_t)v[7], (int16_t)v[8],
                                     (int16_t)v[9]};
        tt_peltier_status_encode(&s, data);
        print_hex(data, TT_PELTIER_STATUS_DLC);
    } else if (id == TT_PAD_CMD_ID && n == 6) {
        const tt_pad_cmd c = {(uint8_t)v[0], (uint8_t)v[1], (uint8_t)v[2], (int16_t)v[3],
                              (uint8_t)v[4], (uint8_t)v[5]};
        tt_pad_cmd_encode(&c, data);
        print_hex(data, TT_PAD_CMD_DLC);
    } else if (id == TT_PAD_STATUS_ID && n == 10) {
        const tt_pad_status s = {(uint8_t)v[0], (uint8_t)v[1], (uint8_t)v[2], (uint8_t)v[3],
                                 (uint8_t)v[4], (uint8_t)v[5], (uint8_t)v[6], (int16_t)v[7],
                                 (int16_t)v[8], (int16_t)v[9]};
        tt_pad_status_encode(&s, data);
        print_hex(data, TT_PAD_STATUS_DLC);
    } else if ((id == TT_PELTIER_HEARTBEAT_ID || id == TT_PAD_HEARTBEAT_ID) && n == 2) {
        const tt_peltier_heartbeat h = {(uint8_t)v[0], (uint8_t)v[1]};
        tt_peltier_heartbeat_encode(&h, data);
        print_hex(data, TT_PELTIER_HEARTBEAT_DLC);
    } else {
        return -1;
    }
    return 0;
}

int tt_codec_can(void)
{
    char line[512];
    int lineno = 0;
    while (fgets(line, sizeof line, stdin)) {
        char copy[sizeof line], *w[2 + MAX_SIGNALS];
        unsigned long id;
        int ok = -1;
        lineno++;
        strcpy(copy, line); /* the line as read, for the error */
        int n = words(copy, w, 2 + MAX_SIGNALS);
        if (n >= 2 && word_ulong(w[1], 16, &id) == 0 && id <= 0x7FFu) {
            if (strcmp(w[0], "decode") == 0) {
                uint8_t data[8];
                int dlc = tt_codec_parse_hex(n >= 3 ? w[2] : "", data, 8);
                ok = dlc < 0 ? -1 : can_decode((unsigned)id, data, dlc);
            } else if (strcmp(w[0], "encode") == 0) {
                long v[MAX_SIGNALS];
                int k = 0;
                for (char *end; k < n - 2; k++) {
                    v[k] = strtol(w[2 + k], &end, 0);
                    if (end == w[2 + k] || *end != '\0') {
                        break;
                    }
                }
                ok = can_encode((unsigned)id, v, k);
            }
        }
        if (ok != 0) {
            fprintf(stderr, "can-codec: line %d: not 'decode <id> <hex>' or 'encode <id> "
                            "<values>' of a known message: %s", lineno, line);
            return 2;
        }
    }
    return 0;
}
