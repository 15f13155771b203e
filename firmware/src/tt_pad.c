#include "tt_pad.h"

#include "tt_bytes.h"

int tt_pad_cmd_decode(const uint8_t *data, uint8_t dlc, tt_pad_cmd *out)
{
    if (dlc < TT_PAD_CMD_DLC) {
        return -1;
    }
    out->enable = data[0] & 0x01u;
    out->pump = (data[0] >> 1) & 0x01u;
    out->counter = (uint8_t)(data[0] >> 4);
    out->current_ma = tt_get_i16(data + 1);
    out->heater_duty_raw = data[3];
    out->version = data[4];
    return 0;
}

void tt_pad_cmd_encode(const tt_pad_cmd *cmd, uint8_t out[TT_PAD_CMD_DLC])
{
    out[0] = (uint8_t)((cmd->enable & 0x01u) | ((cmd->pump & 0x01u) << 1) |
                       ((cmd->counter & 0x0Fu) << 4));
    tt_put_i16(out + 1, cmd->current_ma);
    out[3] = cmd->heater_duty_raw;
    out[4] = cmd->version;
}

int tt_pad_status_decode(const uint8_t *data, uint8_t dlc, tt_pad_status *out)
{
    if (dlc < TT_PAD_STATUS_DLC) {
        return -1;
    }
    out->enabled = data[0] & 0x01u;
    out->over_temp = (data[0] >> 1) & 0x01u;
    out->sensor_fault = (data[0] >> 2) & 0x01u;
    out->watchdog = (data[0] >> 3) & 0x01u;
    out->pump_on = (data[0] >> 4) & 0x01u;
    out->heater_on = (data[0] >> 5) & 0x01u;
    out->counter = data[1];
    out->actuator_cc = tt_get_i16(data + 2);
    out->drive_milli = tt_get_i16(data + 4);
    out->heatsink_cc = tt_get_i16(data + 6);
    return 0;
}

void tt_pad_status_encode(const tt_pad_status *st, uint8_t out[TT_PAD_STATUS_DLC])
{
    out[0] = (uint8_t)((st->enabled & 1u) | ((st->over_temp & 1u) << 1) |
                       ((st->sensor_fault & 1u) << 2) | ((st->watchdog & 1u) << 3) |
                       ((st->pump_on & 1u) << 4) | ((st->heater_on & 1u) << 5));
    out[1] = st->counter;
    tt_put_i16(out + 2, st->actuator_cc);
    tt_put_i16(out + 4, st->drive_milli);
    tt_put_i16(out + 6, st->heatsink_cc);
}
