/* The analog side of the boards, processor in the loop: what a lab's board
 * does with its ADCs and its H-bridge, here as text lines on USART2 to a
 * bridge that runs the simulated plant (telethermal's QEMU device kind).
 * A lab replaces this file by its ADC and PWM drivers (README, "Porting").
 *
 * plant -> board, one line each ('\n' ends a line; bad lines are counted):
 *   m <junction_cc> <heatsink_cc> <current_ma> <drive_milli> <sensors_ok>
 *                      the Peltier driver's measurement from now on
 *   s <flux_uv> <tc_uv> <cj_c> <force_n> <status> [<ir_object_c>
 *     <ir_ambient_c> <pad_drive>]
 *                      one sample for the sensor board, stamped with
 *                      hal_micros() when the board takes it (floats in any
 *                      strtof form, hexadecimal ones exact)
 *   k <scale_milli>    the rig runs scale_milli / 1000 times slower than
 *                      real time: the core's millisecond stretched as much
 *                      (board_time_scale); answered "k <scale_milli>"
 * board -> plant:
 *   ready                                at start, the UARTs set up
 *   set <ms> <enabled> <current_ma>      every change of the H-bridge
 *   water <ms> <pump_on> <duty_raw>      every change of pump and heater
 *
 * Until a measurement arrives, the Peltier driver measures the ideal
 * element of the host build (host/hal_host.c): the current as driven, the
 * heat sink at 25 degC, the junction 2 K per ampere below it. */
#include <stdlib.h>

#include "plant.h"

#include "../src/hal.h"
#include "board.h"

#define LINE_MAX 160u

static char line[LINE_MAX];
static unsigned line_len;
static bool line_overlong;
static int16_t driven_ma;
static bool measured;
static tt_peltier_measure measure;
static bool sample_ready;
static tt_board_sample sample;
uint32_t plant_bad_lines; /* for a debugger: lines that did not parse */

static void put_str(const char *s)
{
    size_t n = 0;
    while (s[n] != '\0') {
        n++;
    }
    board_uart_write(BOARD_PLANT, (const uint8_t *)s, n);
}

static void put_int(int32_t v)
{
    char buf[12];
    unsigned n = sizeof buf;
    uint32_t u = v < 0 ? (uint32_t)0 - (uint32_t)v : (uint32_t)v;
    do {
        buf[--n] = (char)('0' + u % 10u);
        u /= 10u;
    } while (u);
    if (v < 0) {
        buf[--n] = '-';
    }
    board_uart_write(BOARD_PLANT, (const uint8_t *)buf + n, sizeof buf - n);
}

/* A change of the H-bridge or the water loop, told to the plant: on silicon
 * a timer's compare register or a pin, written in a few instructions; here
 * a text line, left out of the loop's time as plant_poll is (plant.h). */
static void report(const char *what, int32_t a, int32_t b)
{
    uint32_t start = board_aside_begin();
    put_str(what);
    put_int((int32_t)hal_millis());
    put_str(" ");
    put_int(a);
    put_str(" ");
    put_int(b);
    put_str("\n");
    board_aside_end(start);
}

/* Integers: `n` of them from `p`; returns 0 or -1. */
static int parse_ints(const char *p, long *out, int n)
{
    for (int i = 0; i < n; i++) {
        char *end;
        out[i] = strtol(p, &end, 10);
        if (end == p || out[i] < -32768 || out[i] > 32767) {
            return -1;
        }
        p = end;
    }
    return 0;
}

static int parse_sample(const char *p, tt_board_sample *s)
{
    float *fields[4] = {&s->flux_uv, &s->tc_uv, &s->cj_c, &s->force_n};
    char *end;
    for (int i = 0; i < 4; i++) {
        *fields[i] = strtof(p, &end);
        if (end == p) {
            return -1;
        }
        p = end;
    }
    long status = strtol(p, &end, 0);
    if (end == p || status < 0 || status > 255) {
        return -1;
    }
    s->status = (uint8_t)status;
    p = end;
    float *v2[3] = {&s->ir_object_c, &s->ir_ambient_c, &s->pad_drive};
    for (int i = 0; i < 3; i++) {
        *v2[i] = strtof(p, &end);
        if (end == p) {
            if (i > 0) {
                return -1;
            }
            s->ir_object_c = s->ir_ambient_c = s->pad_drive = 0.0f;
            break;
        }
        p = end;
    }
    return 0;
}

static void handle_line(void)
{
    long v[5];
    int bad = -1;
    if (line[0] == 'm' && line[1] == ' ') {
        bad = parse_ints(line + 1, v, 5);
        if (!bad) {
            measure.junction_cc = (int16_t)v[0];
            measure.heatsink_cc = (int16_t)v[1];
            measure.current_ma = (int16_t)v[2];
            measure.drive_milli = (int16_t)v[3];
            measure.sensors_ok = v[4] != 0;
            measured = true;
        }
    } else if (line[0] == 'k' && line[1] == ' ') {
        char *end;
        long milli = strtol(line + 2, &end, 10);
        bool taken = end != line + 2 && *end == '\0' && milli > 0 &&
                     board_time_scale((uint32_t)milli);
        bad = taken ? 0 : -1;
        if (!bad) {
            put_str("k ");
            put_int((int32_t)milli);
            put_str("\n");
        }
    } else if (line[0] == 's' && line[1] == ' ' && !sample_ready) {
        bad = parse_sample(line + 1, &sample);
        sample_ready = bad == 0;
    }
    if (bad) {
        plant_bad_lines++;
    }
}

void plant_poll(void)
{
    uint32_t start = board_aside_begin(); /* not the board's work (plant.h) */
    int c;
    while (!sample_ready && (c = board_uart_getc(BOARD_PLANT)) >= 0) {
        if (c != '\n') {
            if (line_len + 1u < LINE_MAX) {
                line[line_len++] = (char)c;
            } else {
                line_overlong = true;
            }
            continue;
        }
        line[line_len] = '\0';
        if (line_overlong) {
            plant_bad_lines++;
        } else if (line_len) {
            handle_line();
        }
        line_len = 0;
        line_overlong = false;
    }
    board_aside_end(start);
}

void plant_hold(bool hold)
{
    if (board_emulated()) { /* on silicon the held line would overrun */
        board_uart_hold(BOARD_PLANT, hold);
    }
}

void plant_start(void)
{
    put_str("ready\n");
}

void hal_peltier_set(bool enabled, int16_t current_ma)
{
    driven_ma = current_ma;
    report("set ", enabled ? 1 : 0, current_ma);
}

void hal_pad_water_set(bool pump_on, uint8_t heater_duty_raw)
{
    report("water ", pump_on ? 1 : 0, heater_duty_raw);
}

void hal_peltier_measure(tt_peltier_measure *out)
{
    plant_poll();
    if (measured) {
        *out = measure;
        return;
    }
    out->current_ma = driven_ma;
    out->heatsink_cc = 2500;
    out->junction_cc = (int16_t)(2500 - driven_ma / 5);
    out->drive_milli = (int16_t)(driven_ma * 1000 / 8500);
    out->sensors_ok = true;
}

int hal_sensor_read(tt_board_sample *out)
{
    plant_poll();
    if (!sample_ready) {
        return 0;
    }
    *out = sample;
    out->t_us = hal_micros();
    sample_ready = false;
    return 1;
}

int hal_uart_write(const uint8_t *data, size_t len)
{
    /* A frame that does not fit whole is refused (HAL contract): the
     * driver counts the gap in the sequence. */
    return board_uart_try_write(BOARD_LINK, data, len) ? 0 : -1;
}
