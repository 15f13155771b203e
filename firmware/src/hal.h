/* The hardware-abstraction layer: the only functions the portable firmware
 * calls. A lab implements them for its MCU (UART or USB-CDC, the CAN
 * controller, a timer, the ADCs and the Peltier's H-bridge); host/hal_host.c
 * implements them on a PC for the tests.
 *
 * A sensor board needs the time, UART and sensor functions; a Peltier
 * driver the time, CAN and Peltier functions. None is called from an
 * interrupt by the portable code. */
#ifndef TT_HAL_H
#define TT_HAL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "tt_types.h"

/* ---- time */

/* Milliseconds since the start; wraps after 49.7 days (the firmware
 * compares times by unsigned difference, so the wrap is harmless). */
uint32_t hal_millis(void);

/* Microseconds since the start; wraps after 71.6 minutes (the frame's t_us
 * wraps with it, as proto/SERIAL.md says). */
uint32_t hal_micros(void);

/* ---- sensor board */

/* Queue `len` bytes (one whole frame) for the UART. Returns 0, or -1 if the
 * frame cannot be queued whole (it is then dropped: the driver counts the
 * gap in the sequence). Must not block longer than one sample period. */
int hal_uart_write(const uint8_t *data, size_t len);

/* The next sample, if the ADCs have one (a timer at the sample rate, 1 kHz
 * for the display): fill `out` (t_us = hal_micros() at the conversion;
 * status bit clear for a channel that failed) and return 1; 0 if none is
 * ready yet; a negative value stops the board's loop (host builds only). */
int hal_sensor_read(tt_board_sample *out);

/* ---- Peltier driver (the display's, or the slave's active pad) */

/* Send one classic CAN frame, 11-bit `id`, `dlc` <= 8 bytes. Returns 0, or
 * -1 if no transmit mailbox is free (the frame is dropped and counted). */
int hal_can_send(uint16_t id, const uint8_t *data, uint8_t dlc);

/* Take one received frame, if any: return 1 with `id`, `data` (8 bytes of
 * room) and `dlc` filled, 0 if none is waiting. The lab's filter may pass
 * only TT_PELTIER_CMD_ID; others are ignored anyway. */
int hal_can_receive(uint16_t *id, uint8_t *data, uint8_t *dlc);

/* Drive the element: enabled, the H-bridge's current loop to `current_ma`
 * (mA, positive cools the pad side, already within the configured limit);
 * disabled, `current_ma` is 0: the bridge off (the module passive, no
 * current). Called on every change, from tt_peltier_init on. */
void hal_peltier_set(bool enabled, int16_t current_ma);

/* Measure the junction (the active pad: the actuator, junction or water)
 * and heat-sink temperatures, the current, and for the active pad its drive
 * (Peltier current as a fraction of full scale, or the heater's duty). */
void hal_peltier_measure(tt_peltier_measure *out);

/* The active pad only (a water pad's pump and heater; duty = raw * 0.004,
 * 250 = full): called with every change, both off whenever the pad is
 * disabled. A display driver, or a Peltier pad, may leave it empty. */
void hal_pad_water_set(bool pump_on, uint8_t heater_duty_raw);

#endif
