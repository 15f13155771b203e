/* The plant link (plant.c): the processor-in-the-loop stand-in for the
 * boards' ADCs and H-bridge. */
#ifndef TT_STM32F4_PLANT_H
#define TT_STM32F4_PLANT_H

#include <stdbool.h>

/* Take the lines the plant sent (a measurement, a sample), stopping after a
 * sample line so that one sample is handed over per hal_sensor_read. The
 * HAL's functions call it, and the main loops first. Its time is left out
 * of the loop-time measurement wherever it runs (board_aside_*): the text
 * parsing stands for the ADC conversions, which on silicon are the
 * converters' and their interrupt's work. So are the lines that tell the
 * plant of a change of the H-bridge or the water loop (on silicon a compare
 * register or a pin). What the HAL functions do besides (the sample copied
 * and stamped, the measurement copied) stays counted. */
void plant_poll(void);

/* Under QEMU (board_emulated), hold the plant link's interrupt (true)
 * while the main loop's measured iteration runs, and release it (false)
 * after: its bytes are the stand-in's traffic, which a lab's board does not
 * have, and QEMU hands a line the bridge wrote at once as a burst of
 * interrupts into whatever runs. QEMU keeps the received bytes in the UART
 * meanwhile (nothing is lost) and a line told to the plant is sent by
 * polling. On silicon (a stand-in bridged to a real board) it does
 * nothing: the line runs at 460800 baud and a held byte would overrun; the
 * stand-in's interrupts are then in the iteration, counted apart as any
 * interrupt. */
void plant_hold(bool hold);

/* Says "ready" on the plant link: the UARTs are set up (main, after
 * board_init; bytes sent to a UART before that are lost). */
void plant_start(void);

#endif
