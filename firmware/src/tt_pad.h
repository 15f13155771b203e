/* The slave's active pad on CAN, node 2 (proto/CAN.md, "The slave's active
 * pad"; proto/peltier.dbc), version 2:
 *
 *   0x102 PAD_CMD        slave -> pad driver, 5 bytes: byte 0 bit 0 enable,
 *                        bit 1 pump, bits 4-7 counter; bytes 1-2 current
 *                        (int16 LE, 1 mA: a Peltier pad's module current);
 *                        byte 3 heater duty (u8, 0.004: a water pad's heater);
 *                        byte 4 version
 *   0x182 PAD_STATUS     pad driver -> slave after each command, 8 bytes:
 *                        byte 0 bits 0-5 enabled, over_temp, sensor_fault,
 *                        watchdog, pump_on, heater_on; byte 1 counter; bytes
 *                        2-3 actuator (0.01 degC: junction or water), 4-5
 *                        drive (0.001: Peltier current fraction or heater
 *                        duty), 6-7 heat sink (0.01 degC), all int16 LE
 *   0x702 PAD_HEARTBEAT  every 100 ms, as PELTIER_HEARTBEAT
 *                        (tt_peltier_heartbeat_encode) */
#ifndef TT_PAD_H
#define TT_PAD_H

#include <stdint.h>

#define TT_PAD_NODE 2u
#define TT_PAD_CMD_ID (0x100u + TT_PAD_NODE)
#define TT_PAD_STATUS_ID (0x180u + TT_PAD_NODE)
#define TT_PAD_HEARTBEAT_ID (0x700u + TT_PAD_NODE)
#define TT_PAD_CMD_DLC 5u
#define TT_PAD_STATUS_DLC 8u
/* The heater duty's full scale: raw 250 = 1.0 (CAN.md: 0..1); a command
 * of raw 251..255 is clamped to it by the driver. */
#define TT_PAD_HEATER_FULL_RAW 250u

typedef struct {
    uint8_t enable;          /* 0 or 1 */
    uint8_t pump;            /* 0 or 1 */
    uint8_t counter;         /* 0..15 */
    int16_t current_ma;      /* 1 mA, positive cools the pad side */
    uint8_t heater_duty_raw; /* duty = raw * 0.004 (250 = 1) */
    uint8_t version;
} tt_pad_cmd;

typedef struct {
    uint8_t enabled, over_temp, sensor_fault, watchdog, pump_on, heater_on; /* 0 or 1 */
    uint8_t counter;
    int16_t actuator_cc;
    int16_t drive_milli; /* 0.001 */
    int16_t heatsink_cc;
} tt_pad_status;

/* Decoders return 0, or -1 if the data field is too short. */
int tt_pad_cmd_decode(const uint8_t *data, uint8_t dlc, tt_pad_cmd *out);
void tt_pad_cmd_encode(const tt_pad_cmd *cmd, uint8_t out[TT_PAD_CMD_DLC]);
int tt_pad_status_decode(const uint8_t *data, uint8_t dlc, tt_pad_status *out);
void tt_pad_status_encode(const tt_pad_status *st, uint8_t out[TT_PAD_STATUS_DLC]);

#endif
