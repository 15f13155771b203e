/* The data the hardware-abstraction layer (hal.h) fills for the portable
 * firmware: apart from the codecs and drivers, so that hal.h needs only
 * these and no driver header (the drivers include hal.h: no circle). */
#ifndef TT_TYPES_H
#define TT_TYPES_H

#include <stdbool.h>
#include <stdint.h>

/* One sample of the board's channels; a channel that could not be read
 * has its status bit clear (its value is then ignored by the driver). */
typedef struct {
    uint32_t t_us; /* the board's clock when the channels were sampled */
    float flux_uv;
    float tc_uv;
    float cj_c;
    float force_n;
    float ir_object_c;  /* version 2 only */
    float ir_ambient_c; /* version 2 only */
    float pad_drive;    /* version 2 only */
    uint8_t status;
} tt_board_sample;

/* What the driver measures each poll (filled by hal_peltier_measure). */
typedef struct {
    int16_t junction_cc; /* the active pad: the actuator (junction or water) */
    int16_t heatsink_cc;
    int16_t current_ma;
    int16_t drive_milli; /* the active pad only: current fraction or heater duty, 0.001 */
    bool sensors_ok;     /* false: a temperature sensor is open or shorted */
} tt_peltier_measure;

#endif
