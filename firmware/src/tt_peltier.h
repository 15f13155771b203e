/* The Peltier driver's side of its CAN protocol, version 2 (proto/CAN.md,
 * proto/peltier.dbc): classic CAN, 11-bit identifiers, node 1. The module
 * is driven by current.
 *
 *   0x101 PELTIER_CMD       master -> driver, 4 bytes: byte 0 bit 0 enable,
 *                           bits 4-7 counter; bytes 1-2 module current
 *                           (int16 LE, 1 mA, positive cools the pad side);
 *                           byte 3 version (2; version 1 had a junction
 *                           set point in bytes 1-2)
 *   0x181 PELTIER_STATUS    driver -> master after each command, 8 bytes:
 *                           byte 0 bits 0-5 enabled, over_temp (hot side),
 *                           over_current, sensor_fault, watchdog,
 *                           sink_saturated (a warning); byte 1 counter; bytes 2-3
 *                           junction (0.01 degC), 4-5 current (1 mA), 6-7
 *                           heat sink (0.01 degC), all int16 LE
 *   0x701 PELTIER_HEARTBEAT driver -> master every 100 ms, 2 bytes: state
 *                           (0 boot, 5 operational, 127 disabled, 128 fault),
 *                           version
 *
 * Temperatures are integers in centidegrees (cC), currents in mA: what the
 * frames carry, no floating point needed on the driver. */
#ifndef TT_PELTIER_H
#define TT_PELTIER_H

#include <stdbool.h>
#include <stdint.h>

#include "tt_types.h"

#define TT_CAN_VERSION 2u
#define TT_CAN_NODE 1u
#define TT_PELTIER_CMD_ID (0x100u + TT_CAN_NODE)
#define TT_PELTIER_STATUS_ID (0x180u + TT_CAN_NODE)
#define TT_PELTIER_HEARTBEAT_ID (0x700u + TT_CAN_NODE)
#define TT_PELTIER_CMD_DLC 4u
#define TT_PELTIER_STATUS_DLC 8u
#define TT_PELTIER_HEARTBEAT_DLC 2u

#define TT_STATE_BOOT 0u
#define TT_STATE_OPERATIONAL 5u
#define TT_STATE_DISABLED 127u
#define TT_STATE_FAULT 128u

/* Fault flags, as the status frame's byte 0 carries them. */
#define TT_FAULT_OVER_TEMP 0x02u
#define TT_FAULT_OVER_CURRENT 0x04u
#define TT_FAULT_SENSOR 0x08u
#define TT_FAULT_WATCHDOG 0x10u
/* A warning, not a fault: the heat sink is above sink_saturated_cc; the
 * driver keeps driving. */
#define TT_WARN_SINK_SATURATED 0x20u

typedef struct {
    uint8_t enable;       /* 0 or 1 */
    uint8_t counter;      /* 0..15 */
    int16_t current_ma;   /* module current, mA, positive cools the pad side */
    uint8_t version;
} tt_peltier_cmd;

typedef struct {
    uint8_t enabled, over_temp, over_current, sensor_fault, watchdog, sink_saturated;
    uint8_t counter;
    int16_t junction_cc;
    int16_t current_ma;
    int16_t heatsink_cc;
} tt_peltier_status;

typedef struct {
    uint8_t state;
    uint8_t version;
} tt_peltier_heartbeat;

/* Frame codecs. A decoder returns 0, or -1 if the data field is shorter
 * than the message (`out` untouched). */
int tt_peltier_cmd_decode(const uint8_t *data, uint8_t dlc, tt_peltier_cmd *out);
void tt_peltier_cmd_encode(const tt_peltier_cmd *cmd, uint8_t out[TT_PELTIER_CMD_DLC]);
int tt_peltier_status_decode(const uint8_t *data, uint8_t dlc, tt_peltier_status *out);
void tt_peltier_status_encode(const tt_peltier_status *st, uint8_t out[TT_PELTIER_STATUS_DLC]);
int tt_peltier_heartbeat_decode(const uint8_t *data, uint8_t dlc, tt_peltier_heartbeat *out);
void tt_peltier_heartbeat_encode(const tt_peltier_heartbeat *hb,
                                 uint8_t out[TT_PELTIER_HEARTBEAT_DLC]);

/* Limits of the element a lab builds; tt_peltier_default_config gives
 * the values the project's emulator uses. */
typedef struct {
    /* false: the display's Peltier driver (node 1, PELTIER_* frames);
     * true: the slave's active pad (node 2, PAD_* frames, tt_pad.h): the
     * same rules, plus a water pad's pump and heater (hal_pad_water_set),
     * off whenever the pad is disabled. */
    bool active_pad;
    int16_t current_limit_ma;  /* commands are clamped to +-this (8500 mA: the
                                  module's Imax) */
    int16_t over_temp_cc;      /* heat sink (hot side) above: over_temp (70.00 degC) */
    int16_t sink_saturated_cc; /* heat sink above: sink_saturated warning (60.00 degC) */
    int16_t over_current_ma;   /* measured |current| above: over_current (9350 mA,
                                  10 % above the limit; the active pad reports
                                  it as sensor_fault: PAD_STATUS has no flag) */
    uint16_t watchdog_ms;      /* no command for longer: disabled (100 ms) */
    uint16_t heartbeat_ms;     /* heartbeat period (100 ms) */
    uint8_t max_frames_per_poll; /* a flood cannot starve the watchdog (64) */
} tt_peltier_config;

void tt_peltier_default_config(tt_peltier_config *cfg);
/* The same for the slave's active pad (active_pad = true). */
void tt_pad_default_config(tt_peltier_config *cfg);

typedef struct {
    tt_peltier_config cfg;
    uint8_t state;         /* what the last heartbeat said */
    bool booted;           /* the boot heartbeat has been sent */
    bool enabled;
    uint8_t faults;        /* TT_FAULT_* */
    int16_t current_ma;    /* what the element is driven with (0 when disabled) */
    bool pump_on;          /* the active pad only */
    uint8_t heater_duty_raw; /* the active pad only, 0.004 per unit */
    uint8_t status_counter;
    bool commanded;        /* a command has arrived since the start */
    uint32_t last_cmd_ms;
    uint32_t last_heartbeat_ms;
    tt_peltier_measure measured;
    /* Counters, for a lab's debugger or its own diagnostics frame;
     * `clamped`: commands whose current or heater duty was outside the
     * limits and was applied clamped. */
    uint32_t commands, bad_commands, watchdog_trips, send_failed, clamped;
} tt_peltier_driver;

/* Start (after a restart): disabled, 0 A. */
void tt_peltier_init(tt_peltier_driver *drv, const tt_peltier_config *cfg);

/* Call at least once a millisecond: measures, handles the commands that
 * arrived (each answered by a status frame), the protections, the
 * watchdog and the heartbeat. */
void tt_peltier_poll(tt_peltier_driver *drv);

#endif
