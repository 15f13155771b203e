/* The host HAL's controls, for host/tt_host.c (not part of the firmware). */
#ifndef TT_HAL_HOST_H
#define TT_HAL_HOST_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

/* The simulated clock: hal_millis() and hal_micros() return what was set. */
void host_set_time_us(uint64_t t_us);

/* Sensor board: samples come from `in`, one line each:
 * "t_us flux_uv tc_uv cj_c force_n status [ir_object_c ir_ambient_c pad_drive]"
 * (floats in any strtod form, hexadecimal ones exact; the last three for
 * version 2); frames go to file descriptor `uart_fd`.
 * `corrupt_every` > 0 flips one bit in every n-th frame written (to show
 * that the round trip test can fail). */
void host_board_setup(FILE *in, int uart_fd, unsigned corrupt_every);

/* Peltier driver: received frames are queued by host_can_inject; sent
 * frames and the element's settings are printed to `out` as lines
 * "tx <ms> <id> <hex>", "set <ms> <enabled> <current_ma>" and (the active
 * pad) "water <ms> <pump_on> <heater_duty_raw>". The
 * measurement is the ideal element (the current as driven, heat sink at
 * 25 degC, junction 2 K per ampere below it) unless host_set_measure overrides it. */
void host_peltier_setup(FILE *out);
int host_can_inject(uint16_t id, const uint8_t *data, uint8_t dlc);
void host_set_measure(int16_t junction_cc, int16_t heatsink_cc, int16_t current_ma,
                      bool sensors_ok);

#endif
