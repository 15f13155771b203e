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
#include "../src/tt_pad.h"
#include "../src/tt_peltier.h"
#include "hal_host.h"
#include "tt_codec.h"

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
            int dlc = tt_codec_parse_hex(line + used, data, 8);
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
    fprintf(stderr, "peltier: %lu commands, %lu bad, %lu watchdog trips, %lu clamped\n",
            (unsigned long)drv.commands, (unsigned long)drv.bad_commands,
            (unsigned long)drv.watchdog_trips, (unsigned long)drv.clamped);
    return 0;
}

int main(int argc, char **argv)
{
    const char *mode = argc > 1 ? argv[1] : "";
    if (strcmp(mode, "selftest") == 0) {
        return tt_codec_selftest();
    }
    if (strcmp(mode, "serial-encode") == 0) {
        return tt_codec_serial_encode();
    }
    if (strcmp(mode, "can-codec") == 0) {
        return tt_codec_can();
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
