/* The firmware on a PC, for the tests (tests/integration/test_firmware.py)
 * and for a lab checking its toolchain. One program, one mode per argument:
 *
 *   tt_host selftest         CRC check value, COBS reference vectors
 *   tt_host serial-encode    stdin "version type seq t_us flux tc cj force status
 *                            [ir_object ir_ambient pad_drive]" per line ->
 *                            stdout the wire frame in hex
 *   tt_host can-codec        stdin "decode <id> <hex>" -> "name sig=raw ...";
 *                            "encode <id> <raw values in DBC order>" -> hex
 *                            (PELTIER_* and PAD_* frames)
 *   tt_host board [--version V] [--cj C] [--corrupt-every N]
 *                            the sensor board's application: a boot frame,
 *                            then one frame per stdin sample line ("t_us flux
 *                            tc cj force status [ir_object ir_ambient
 *                            pad_drive]") to stdout
 *   tt_host peltier [--pad]  the Peltier driver's application (--pad: the
 *                            slave's active pad, PAD_* frames) on a script
 *                            from stdin: "rx <id> <hex>" queues a received
 *                            frame, "t <ms>" sets the clock and polls,
 *                            "meas <junction_cc> <heatsink_cc> <current_ma>
 *                            <sensors_ok>" fixes the measurement; stdout
 *                            gets "tx <ms> <id> <hex>", "set <ms> <en> <ma>",
 *                            "water <ms> <pump> <duty_raw>" (--pad) and
 *                            "done <ms>" after each poll
 *
 * Exit status 0, 1 on a failed check, 2 on bad input (named on stderr). */
#define _POSIX_C_SOURCE 200809L

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../src/hal.h"
#include "../src/tt_board.h"
#include "../src/tt_cobs.h"
#include "../src/tt_crc16.h"
#include "../src/tt_pad.h"
#include "../src/tt_peltier.h"
#include "hal_host.h"

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
static int parse_hex(const char *s, uint8_t *out, int room)
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

static int selftest(void)
{
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

/* ------------------------------------------------------------ serial-encode */

static int serial_encode(void)
{
    char line[512];
    int lineno = 0;
    while (fgets(line, sizeof line, stdin)) {
        unsigned version, type, seq, status;
        unsigned long t_us;
        char f[7][64] = {"0", "0", "0", "0", "0", "0", "0"};
        lineno++;
        int n = sscanf(line, "%u %u %u %lu %63s %63s %63s %63s %u %63s %63s %63s", &version,
                       &type, &seq, &t_us, f[0], f[1], f[2], f[3], &status, f[4], f[5], f[6]);
        if ((n != 9 && n != 12) || version > 255 || type > 255 || seq > 0xFFFF ||
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

static int can_codec(void)
{
    char line[512];
    int lineno = 0;
    while (fgets(line, sizeof line, stdin)) {
        char verb[16];
        unsigned id;
        int used = 0, ok = -1;
        lineno++;
        if (sscanf(line, "%15s %x %n", verb, &id, &used) >= 2 && used > 0) {
            if (strcmp(verb, "decode") == 0) {
                uint8_t data[8];
                int dlc = parse_hex(line + used, data, 8);
                ok = dlc < 0 ? -1 : can_decode(id, data, dlc);
            } else if (strcmp(verb, "encode") == 0) {
                long v[MAX_SIGNALS];
                int n = 0;
                char *p = line + used, *end;
                while (n < MAX_SIGNALS) {
                    v[n] = strtol(p, &end, 0);
                    if (end == p) {
                        break;
                    }
                    n++;
                    p = end;
                }
                ok = can_encode(id, v, n);
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

/* ------------------------------------------------------------ applications */

static int board(int argc, char **argv)
{
    float cj_c = 25.0f;
    unsigned corrupt_every = 0;
    unsigned long version = TT_BOARD_VERSION;
    for (int i = 2; i < argc; i += 2) {
        if (i + 1 == argc) {
            fprintf(stderr, "board: %s needs a value\n", argv[i]);
            return 2;
        }
        if (strcmp(argv[i], "--version") == 0) {
            version = strtoul(argv[i + 1], NULL, 0);
            if (version != TT_BOARD_VERSION && version != TT_BOARD_VERSION_SLAVE) {
                fprintf(stderr, "board: --version is 1 or 2, not %s\n", argv[i + 1]);
                return 2;
            }
        } else if (strcmp(argv[i], "--cj") == 0) {
            cj_c = strtof(argv[i + 1], NULL);
        } else if (strcmp(argv[i], "--corrupt-every") == 0) {
            corrupt_every = (unsigned)strtoul(argv[i + 1], NULL, 0);
        } else {
            fprintf(stderr, "board: unknown option %s\n", argv[i]);
            return 2;
        }
    }
    host_board_setup(stdin, 1, corrupt_every);
    host_set_time_us(0);
    tt_board_app app;
    tt_board_app_start(&app, (uint8_t)version, cj_c);
    int r;
    while ((r = tt_board_app_poll(&app)) > 0) {
    }
    fprintf(stderr, "board: %lu frames written, %lu refused\n", (unsigned long)app.frames,
            (unsigned long)app.write_errors);
    if (r == -2) {
        fprintf(stderr, "board: a sample line is not 't_us flux tc cj force status'\n");
        return 2;
    }
    return app.write_errors ? 1 : 0;
}

static int peltier(int argc, char **argv)
{
    bool pad = argc > 2 && strcmp(argv[2], "--pad") == 0;
    if (argc > (pad ? 3 : 2)) {
        fprintf(stderr, "peltier: the only option is --pad\n");
        return 2;
    }
    char line[256];
    int lineno = 0;
    tt_peltier_driver drv;
    tt_peltier_config cfg;
    setvbuf(stdout, NULL, _IOLBF, 0);
    host_peltier_setup(stdout);
    host_set_time_us(0);
    if (pad) {
        tt_pad_default_config(&cfg);
    } else {
        tt_peltier_default_config(&cfg);
    }
    tt_peltier_init(&drv, &cfg);
    while (fgets(line, sizeof line, stdin)) {
        unsigned long ms;
        unsigned id;
        int used = 0, j, h, c, ok_flag;
        lineno++;
        if (sscanf(line, "t %lu", &ms) == 1) {
            host_set_time_us((uint64_t)ms * 1000u);
            tt_peltier_poll(&drv);
            printf("done %lu\n", ms); /* a driving process can wait for this */
        } else if (sscanf(line, "rx %x %n", &id, &used) == 1 && used > 0) {
            uint8_t data[8];
            int dlc = parse_hex(line + used, data, 8);
            if (dlc < 0 || host_can_inject((uint16_t)id, data, (uint8_t)dlc) != 0) {
                fprintf(stderr, "peltier: line %d: bad frame or queue full: %s", lineno, line);
                return 2;
            }
        } else if (sscanf(line, "meas %d %d %d %d", &j, &h, &c, &ok_flag) == 4) {
            host_set_measure((int16_t)j, (int16_t)h, (int16_t)c, ok_flag != 0);
        } else if (line[0] != '\n' && line[0] != '#') {
            fprintf(stderr, "peltier: line %d: not 't', 'rx' or 'meas': %s", lineno, line);
            return 2;
        }
    }
    fprintf(stderr, "peltier: %lu commands, %lu bad, %lu watchdog trips\n",
            (unsigned long)drv.commands, (unsigned long)drv.bad_commands,
            (unsigned long)drv.watchdog_trips);
    return 0;
}

int main(int argc, char **argv)
{
    const char *mode = argc > 1 ? argv[1] : "";
    if (strcmp(mode, "selftest") == 0) {
        return selftest();
    }
    if (strcmp(mode, "serial-encode") == 0) {
        return serial_encode();
    }
    if (strcmp(mode, "can-codec") == 0) {
        return can_codec();
    }
    if (strcmp(mode, "board") == 0) {
        return board(argc, argv);
    }
    if (strcmp(mode, "peltier") == 0) {
        return peltier(argc, argv);
    }
    fprintf(stderr, "usage: tt_host selftest | serial-encode | can-codec | "
                    "board [--version V] [--cj C] [--corrupt-every N] | peltier [--pad]\n");
    return 2;
}
