#include "tt_peltier.h"

#include "hal.h"
#include "tt_bytes.h"
#include "tt_pad.h"

int tt_peltier_cmd_decode(const uint8_t *data, uint8_t dlc, tt_peltier_cmd *out)
{
    if (dlc < TT_PELTIER_CMD_DLC) {
        return -1;
    }
    out->enable = data[0] & 0x01u;
    out->counter = (uint8_t)(data[0] >> 4);
    out->current_ma = tt_get_i16(data + 1);
    out->version = data[3];
    return 0;
}

void tt_peltier_cmd_encode(const tt_peltier_cmd *cmd, uint8_t out[TT_PELTIER_CMD_DLC])
{
    out[0] = (uint8_t)((cmd->enable & 0x01u) | ((cmd->counter & 0x0Fu) << 4));
    tt_put_i16(out + 1, cmd->current_ma);
    out[3] = cmd->version;
}

int tt_peltier_status_decode(const uint8_t *data, uint8_t dlc, tt_peltier_status *out)
{
    if (dlc < TT_PELTIER_STATUS_DLC) {
        return -1;
    }
    out->enabled = data[0] & 0x01u;
    out->over_temp = (data[0] >> 1) & 0x01u;
    out->over_current = (data[0] >> 2) & 0x01u;
    out->sensor_fault = (data[0] >> 3) & 0x01u;
    out->watchdog = (data[0] >> 4) & 0x01u;
    out->sink_saturated = (data[0] >> 5) & 0x01u;
    out->counter = data[1];
    out->junction_cc = tt_get_i16(data + 2);
    out->current_ma = tt_get_i16(data + 4);
    out->heatsink_cc = tt_get_i16(data + 6);
    return 0;
}

void tt_peltier_status_encode(const tt_peltier_status *st, uint8_t out[TT_PELTIER_STATUS_DLC])
{
    out[0] = (uint8_t)((st->enabled & 1u) | ((st->over_temp & 1u) << 1) |
                       ((st->over_current & 1u) << 2) | ((st->sensor_fault & 1u) << 3) |
                       ((st->watchdog & 1u) << 4) | ((st->sink_saturated & 1u) << 5));
    out[1] = st->counter;
    tt_put_i16(out + 2, st->junction_cc);
    tt_put_i16(out + 4, st->current_ma);
    tt_put_i16(out + 6, st->heatsink_cc);
}

int tt_peltier_heartbeat_decode(const uint8_t *data, uint8_t dlc, tt_peltier_heartbeat *out)
{
    if (dlc < TT_PELTIER_HEARTBEAT_DLC) {
        return -1;
    }
    out->state = data[0];
    out->version = data[1];
    return 0;
}

void tt_peltier_heartbeat_encode(const tt_peltier_heartbeat *hb,
                                 uint8_t out[TT_PELTIER_HEARTBEAT_DLC])
{
    out[0] = hb->state;
    out[1] = hb->version;
}

/* ------------------------------------------------------------------ driver */

void tt_peltier_default_config(tt_peltier_config *cfg)
{
    cfg->active_pad = false;
    cfg->current_limit_ma = 8500;
    cfg->over_temp_cc = 7000;
    cfg->sink_saturated_cc = 6000;
    cfg->over_current_ma = 9350;
    cfg->watchdog_ms = 100;
    cfg->heartbeat_ms = 100;
    cfg->max_frames_per_poll = 64;
}

void tt_pad_default_config(tt_peltier_config *cfg)
{
    tt_peltier_default_config(cfg);
    cfg->active_pad = true;
}

static void apply(tt_peltier_driver *drv, bool enabled, int16_t current_ma, bool pump,
                  uint8_t heater_duty_raw)
{
    drv->enabled = enabled;
    drv->current_ma = current_ma;
    hal_peltier_set(enabled, current_ma);
    if (drv->cfg.active_pad) {
        drv->pump_on = enabled && pump;
        drv->heater_duty_raw = enabled ? heater_duty_raw : 0u;
        hal_pad_water_set(drv->pump_on, drv->heater_duty_raw);
    }
}

static void disable(tt_peltier_driver *drv)
{
    apply(drv, false, 0, false, 0); /* the safe state: no current */
}

static void send(tt_peltier_driver *drv, uint16_t id, const uint8_t *data, uint8_t dlc)
{
    if (hal_can_send(id, data, dlc) != 0) {
        drv->send_failed++;
    }
}

static void send_pad_status(tt_peltier_driver *drv)
{
    const tt_pad_status st = {
        drv->enabled ? 1u : 0u,
        (drv->faults & TT_FAULT_OVER_TEMP) ? 1u : 0u,
        (drv->faults & (TT_FAULT_SENSOR | TT_FAULT_OVER_CURRENT)) ? 1u : 0u,
        (drv->faults & TT_FAULT_WATCHDOG) ? 1u : 0u,
        drv->pump_on ? 1u : 0u,
        drv->heater_duty_raw > 0 ? 1u : 0u,
        drv->status_counter,
        drv->measured.junction_cc,
        drv->measured.drive_milli,
        drv->measured.heatsink_cc,
    };
    uint8_t data[TT_PAD_STATUS_DLC];
    tt_pad_status_encode(&st, data);
    drv->status_counter = (uint8_t)(drv->status_counter + 1u);
    send(drv, TT_PAD_STATUS_ID, data, TT_PAD_STATUS_DLC);
}

static void send_status(tt_peltier_driver *drv)
{
    hal_peltier_measure(&drv->measured); /* what it measures now, after the change */
    if (drv->cfg.active_pad) {
        send_pad_status(drv);
        return;
    }
    const tt_peltier_status st = {
        drv->enabled ? 1u : 0u,
        (drv->faults & TT_FAULT_OVER_TEMP) ? 1u : 0u,
        (drv->faults & TT_FAULT_OVER_CURRENT) ? 1u : 0u,
        (drv->faults & TT_FAULT_SENSOR) ? 1u : 0u,
        (drv->faults & TT_FAULT_WATCHDOG) ? 1u : 0u,
        drv->measured.heatsink_cc > drv->cfg.sink_saturated_cc ? 1u : 0u,
        drv->status_counter,
        drv->measured.junction_cc,
        drv->measured.current_ma,
        drv->measured.heatsink_cc,
    };
    uint8_t data[TT_PELTIER_STATUS_DLC];
    tt_peltier_status_encode(&st, data);
    drv->status_counter = (uint8_t)(drv->status_counter + 1u);
    send(drv, TT_PELTIER_STATUS_ID, data, TT_PELTIER_STATUS_DLC);
}

static void send_heartbeat(tt_peltier_driver *drv, uint8_t state)
{
    const tt_peltier_heartbeat hb = {state, TT_CAN_VERSION};
    uint8_t data[TT_PELTIER_HEARTBEAT_DLC];
    tt_peltier_heartbeat_encode(&hb, data);
    drv->state = state;
    send(drv, drv->cfg.active_pad ? TT_PAD_HEARTBEAT_ID : TT_PELTIER_HEARTBEAT_ID, data,
         TT_PELTIER_HEARTBEAT_DLC);
}

void tt_peltier_init(tt_peltier_driver *drv, const tt_peltier_config *cfg)
{
    drv->cfg = *cfg;
    drv->state = TT_STATE_BOOT;
    drv->booted = false;
    drv->faults = 0;
    drv->status_counter = 0;
    drv->commanded = false;
    drv->last_cmd_ms = 0;
    drv->last_heartbeat_ms = 0;
    drv->measured.junction_cc = 2500;
    drv->measured.heatsink_cc = 2500;
    drv->measured.current_ma = 0;
    drv->measured.drive_milli = 0;
    drv->measured.sensors_ok = true;
    drv->pump_on = false;
    drv->heater_duty_raw = 0;
    drv->commands = drv->bad_commands = drv->watchdog_trips = drv->send_failed = 0;
    drv->clamped = 0;
    disable(drv);
}

/* The driver's own protections: latched until the master sends a command
 * with enable = 0 while the cause has gone (see handle_command). */
static uint8_t protection_faults(const tt_peltier_driver *drv)
{
    const tt_peltier_measure *m = &drv->measured;
    int32_t current_ma = m->current_ma;
    uint8_t f = 0;
    if (!m->sensors_ok) {
        f |= TT_FAULT_SENSOR;
    }
    if (m->heatsink_cc > drv->cfg.over_temp_cc) {
        f |= TT_FAULT_OVER_TEMP; /* the hot side */
    }
    if (current_ma > drv->cfg.over_current_ma || -current_ma > drv->cfg.over_current_ma) {
        f |= TT_FAULT_OVER_CURRENT;
    }
    return f;
}

static int16_t clamp(int16_t v, int16_t lo, int16_t hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

/* A command of either kind, decoded. */
typedef struct {
    uint8_t enable, pump, heater_duty_raw, version;
    int16_t current_ma;
} command;

static int decode_command(const tt_peltier_driver *drv, const uint8_t *data, uint8_t dlc,
                          command *out)
{
    if (drv->cfg.active_pad) {
        tt_pad_cmd c;
        if (tt_pad_cmd_decode(data, dlc, &c) != 0) {
            return -1;
        }
        out->enable = c.enable;
        out->pump = c.pump;
        out->heater_duty_raw = c.heater_duty_raw;
        out->version = c.version;
        out->current_ma = c.current_ma;
        return 0;
    }
    tt_peltier_cmd c;
    if (tt_peltier_cmd_decode(data, dlc, &c) != 0) {
        return -1;
    }
    out->enable = c.enable;
    out->pump = 0;
    out->heater_duty_raw = 0;
    out->version = c.version;
    out->current_ma = c.current_ma;
    return 0;
}

static void handle_command(tt_peltier_driver *drv, const uint8_t *data, uint8_t dlc,
                           uint32_t now_ms)
{
    command cmd;
    if (decode_command(drv, data, dlc, &cmd) != 0) {
        drv->bad_commands++;
        return;
    }
    drv->commands++;
    drv->commanded = true;
    drv->last_cmd_ms = now_ms;
    drv->faults &= (uint8_t)~TT_FAULT_WATCHDOG; /* commands have resumed */
    if (cmd.version != TT_CAN_VERSION) {
        drv->bad_commands++; /* another protocol: ignored, not answered */
        return;
    }
    if (!cmd.enable) {
        /* The master acknowledges: latched protections whose cause has
         * gone are cleared. */
        drv->faults &= (uint8_t)(TT_FAULT_WATCHDOG | protection_faults(drv));
    }
    if (cmd.enable && drv->faults == 0) {
        int16_t current_ma = clamp(cmd.current_ma, (int16_t)-drv->cfg.current_limit_ma,
                                   drv->cfg.current_limit_ma);
        /* The heater's duty is 0..1 (CAN.md): raw 251..255 would be 100.4..102 %. */
        uint8_t duty_raw = cmd.heater_duty_raw > TT_PAD_HEATER_FULL_RAW
                               ? (uint8_t)TT_PAD_HEATER_FULL_RAW : cmd.heater_duty_raw;
        if (current_ma != cmd.current_ma || duty_raw != cmd.heater_duty_raw) {
            drv->clamped++;
        }
        apply(drv, true, current_ma, cmd.pump != 0, duty_raw);
    } else if (drv->enabled || !cmd.enable) {
        disable(drv);
    }
    send_status(drv);
}

void tt_peltier_poll(tt_peltier_driver *drv)
{
    uint32_t now = hal_millis();
    if (!drv->booted) {
        drv->booted = true;
        drv->last_heartbeat_ms = now;
        send_heartbeat(drv, TT_STATE_BOOT); /* once after a restart */
        drv->state = TT_STATE_DISABLED;
    }
    hal_peltier_measure(&drv->measured);
    uint8_t tripped = protection_faults(drv);
    if (tripped & (uint8_t)~drv->faults) {
        drv->faults |= tripped;
        disable(drv);
        send_status(drv);
    }
    for (unsigned i = 0; i < drv->cfg.max_frames_per_poll; i++) {
        uint16_t id;
        uint8_t data[8], dlc;
        if (hal_can_receive(&id, data, &dlc) <= 0) {
            break;
        }
        if (id == (drv->cfg.active_pad ? TT_PAD_CMD_ID : TT_PELTIER_CMD_ID)) {
            handle_command(drv, data, dlc, now);
        }
    }
    /* Unsigned subtraction: right across the 49-day wrap of the clock. */
    if (drv->enabled && drv->commanded &&
        (uint32_t)(now - drv->last_cmd_ms) > drv->cfg.watchdog_ms) {
        drv->watchdog_trips++;
        drv->faults |= TT_FAULT_WATCHDOG;
        disable(drv);
        send_status(drv);
    }
    if ((uint32_t)(now - drv->last_heartbeat_ms) >= drv->cfg.heartbeat_ms) {
        drv->last_heartbeat_ms = now;
        send_heartbeat(drv, drv->faults ? TT_STATE_FAULT
                            : drv->enabled ? TT_STATE_OPERATIONAL : TT_STATE_DISABLED);
    }
}
