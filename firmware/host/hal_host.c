/* The HAL on a PC: the board's UART is a file descriptor (a pty in the
 * tests), its ADC samples lines of text; the CAN bus and the Peltier are
 * lines of text; the clock is simulated, set by the caller. POSIX. */
#define _POSIX_C_SOURCE 200809L

#include "hal_host.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../src/hal.h"

static uint64_t now_us;

void host_set_time_us(uint64_t t_us)
{
    now_us = t_us;
}

uint32_t hal_millis(void)
{
    return (uint32_t)(now_us / 1000u);
}

uint32_t hal_micros(void)
{
    return (uint32_t)now_us;
}

/* ------------------------------------------------------------ sensor board */

static FILE *sample_in;
static int uart = -1;
static unsigned corrupt_n, written;

void host_board_setup(FILE *in, int uart_fd, unsigned corrupt_every)
{
    sample_in = in;
    uart = uart_fd;
    corrupt_n = corrupt_every;
    written = 0;
}

int hal_uart_write(const uint8_t *data, size_t len)
{
    uint8_t copy[64];
    if (len > sizeof copy) {
        return -1;
    }
    memcpy(copy, data, len);
    written++;
    if (corrupt_n && written % corrupt_n == 0 && len > 4) {
        copy[len / 2] ^= 0x10u; /* line noise: one bit, never the delimiter */
    }
    size_t done = 0;
    while (done < len) {
        ssize_t n = write(uart, copy + done, len - done);
        if (n < 0 && errno == EINTR) {
            continue;
        }
        if (n <= 0) {
            return -1;
        }
        done += (size_t)n;
    }
    return 0;
}

int hal_sensor_read(tt_board_sample *out)
{
    char line[512];
    unsigned long long t_us;
    unsigned status;
    if (!sample_in || !fgets(line, sizeof line, sample_in)) {
        return -1;
    }
    char *p = line, *end;
    t_us = strtoull(p, &end, 0);
    if (end == p) {
        return -2;
    }
    float *fields[4] = {&out->flux_uv, &out->tc_uv, &out->cj_c, &out->force_n};
    for (int i = 0; i < 4; i++) {
        p = end;
        *fields[i] = strtof(p, &end);
        if (end == p) {
            return -2;
        }
    }
    p = end;
    status = (unsigned)strtoul(p, &end, 0);
    if (end == p || status > 0xFFu) {
        return -2;
    }
    /* Version 2's channels, if the line has them. */
    float *v2[3] = {&out->ir_object_c, &out->ir_ambient_c, &out->pad_drive};
    for (int i = 0; i < 3; i++) {
        p = end;
        *v2[i] = strtof(p, &end);
        if (end == p && i > 0) {
            return -2;
        }
        if (end == p) {
            *v2[0] = *v2[1] = *v2[2] = 0.0f;
            break;
        }
    }
    out->status = (uint8_t)status;
    out->t_us = (uint32_t)t_us;
    host_set_time_us(t_us);
    return 1;
}

/* ------------------------------------------------------------ Peltier */

#define RX_QUEUE 256

static FILE *trace;
static struct {
    uint16_t id;
    uint8_t dlc;
    uint8_t data[8];
} rx[RX_QUEUE];
static unsigned rx_head, rx_count;
static bool measure_fixed;
static int16_t element_ma;
static tt_peltier_measure fixed;

void host_peltier_setup(FILE *out)
{
    trace = out;
    rx_head = rx_count = 0;
    measure_fixed = false;
}

int host_can_inject(uint16_t id, const uint8_t *data, uint8_t dlc)
{
    if (rx_count == RX_QUEUE || dlc > 8) {
        return -1;
    }
    unsigned at = (rx_head + rx_count) % RX_QUEUE;
    rx[at].id = id;
    rx[at].dlc = dlc;
    memcpy(rx[at].data, data, dlc);
    rx_count++;
    return 0;
}

void host_set_measure(int16_t junction_cc, int16_t heatsink_cc, int16_t current_ma,
                      bool sensors_ok)
{
    fixed.junction_cc = junction_cc;
    fixed.heatsink_cc = heatsink_cc;
    fixed.current_ma = current_ma;
    fixed.drive_milli = 0;
    fixed.sensors_ok = sensors_ok;
    measure_fixed = true;
}

int hal_can_send(uint16_t id, const uint8_t *data, uint8_t dlc)
{
    if (!trace) {
        return 0;
    }
    fprintf(trace, "tx %lu %03x ", (unsigned long)hal_millis(), (unsigned)id);
    for (uint8_t i = 0; i < dlc; i++) {
        fprintf(trace, "%02x", data[i]);
    }
    fputc('\n', trace);
    return 0;
}

int hal_can_receive(uint16_t *id, uint8_t *data, uint8_t *dlc)
{
    if (rx_count == 0) {
        return 0;
    }
    *id = rx[rx_head].id;
    *dlc = rx[rx_head].dlc;
    memcpy(data, rx[rx_head].data, rx[rx_head].dlc);
    rx_head = (rx_head + 1) % RX_QUEUE;
    rx_count--;
    return 1;
}

void hal_peltier_set(bool enabled, int16_t current_ma)
{
    element_ma = current_ma;
    if (trace) {
        fprintf(trace, "set %lu %d %d\n", (unsigned long)hal_millis(), enabled ? 1 : 0,
                current_ma);
    }
}

void hal_pad_water_set(bool pump_on, uint8_t heater_duty_raw)
{
    if (trace) {
        fprintf(trace, "water %lu %d %u\n", (unsigned long)hal_millis(), pump_on ? 1 : 0,
                heater_duty_raw);
    }
}

void hal_peltier_measure(tt_peltier_measure *out)
{
    if (measure_fixed) {
        *out = fixed;
        return;
    }
    /* An ideal element: the current as driven; the heat sink at 25 degC and
     * the junction 2 K per ampere below it (a module under a pad's load;
     * unloaded, the TM-31-1.4-8.5 would pull about 21 K/A). */
    out->current_ma = element_ma;
    out->heatsink_cc = 2500;
    out->junction_cc = (int16_t)(2500 - element_ma / 5);
    /* The active pad's drive as the project's emulator reports it: the
     * current as a fraction of the 8.5 A limit, 0.001. */
    out->drive_milli = (int16_t)(element_ma * 1000 / 8500);
    out->sensors_ok = true;
}
