/* The plant link (plant.c): the processor-in-the-loop stand-in for the
 * boards' ADCs and H-bridge. */
#ifndef TT_STM32F4_PLANT_H
#define TT_STM32F4_PLANT_H

/* Take the lines the plant sent (a measurement, a sample), stopping after a
 * sample line so that one sample is handed over per hal_sensor_read. The
 * HAL's functions call it; the main loops call it first, outside the
 * loop-time measurement: the text parsing stands for the ADC conversions,
 * which on silicon are the converters' and their interrupt's work. */
void plant_poll(void);

/* Says "ready" on the plant link: the UARTs are set up (main, after
 * board_init; bytes sent to a UART before that are lost). */
void plant_start(void);

#endif
