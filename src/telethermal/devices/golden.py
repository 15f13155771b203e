"""Golden vectors of the device protocols: the sensor board's serial frames
(``proto/SERIAL.md``, versions 1 and 2) and the CAN frames of the Peltier
driver and of the slave's active pad (``proto/CAN.md``, ``peltier.dbc``),
each as its bytes beside a JSON of its fields.

``python -m telethermal.devices.golden DIR`` (re)writes
``DIR/serial/<name>.bin`` + ``.json`` (a whole frame on the wire: COBS
packet and its 0x00 delimiter; the JSON holds the fields of
:class:`~telethermal.devices.frames.BoardFrame`) and ``DIR/can/<name>.bin``
+ ``.json`` (the CAN data field; the JSON holds the message name, its
identifier, the signals as cantools decodes them and their raw integers).
The committed files in ``proto/golden/`` are what the Python codecs and the
reference firmware (``firmware/``) are tested against, both ways, so a
change of encoding on either side shows up as a failing test.

Float fields are chosen exactly representable in a 32-bit float where the
vector is about something else, so that the JSON value is the value the
bytes decode to; ``sample_inexact`` holds one that is not (the JSON then
holds the float32 value the record carries).
"""

from __future__ import annotations

import json
import struct
import sys
from pathlib import Path

from cobs import cobs

from telethermal.devices.frames import (FRAME_VERSION, FRAME_VERSION_SLAVE, STATUS_ALL,
                                        STATUS_FLUX, STATUS_FORCE, STATUS_HEATER, STATUS_IR,
                                        STATUS_PUMP, STATUS_TC, TYPE_BOOT, TYPE_SAMPLE,
                                        BoardFrame, encode)
from telethermal.devices.peltier import DB


def f32(value: float) -> float:
    """``value`` as the float32 a record carries, back as a Python float."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


#: name -> frame. Edge cases: wraps, status bits, zero bytes inside the
#: record (COBS has work), extreme floats.
SERIAL_EXAMPLES: dict[str, BoardFrame] = {
    # A display sample at contact: flux into the finger, pad near skin.
    "sample": BoardFrame(1234, 1_234_567, -4410.5, 412.25, 25.0, 2.125),
    # The board restarted: seq 0, no channel flagged ok, the cold junction only.
    "boot": BoardFrame(0, 0, 0.0, 0.0, 25.0, 0.0, 0, TYPE_BOOT),
    # Mostly zero: seq 0, t 0, every float 0.0 (long runs of 0x00 for COBS).
    "zeros": BoardFrame(0, 0, 0.0, 0.0, 0.0, 0.0, STATUS_ALL),
    # The last sequence number and clock value before they wrap.
    "wrap_last": BoardFrame(0xFFFF, 0xFFFF_FFFF, 1.0, -1.0, 24.5, 0.5),
    # ... and the first after the wrap.
    "wrap_first": BoardFrame(0, 0, 1.0, -1.0, 24.5, 0.5),
    # Each channel flagged bad on its own, and all of them.
    "status_no_flux": BoardFrame(17, 17_000, 0.0, 250.0, 25.0, 1.0,
                                 STATUS_TC | STATUS_FORCE),
    "status_no_tc": BoardFrame(18, 18_000, 126.0, 0.0, 25.0, 1.0,
                               STATUS_FLUX | STATUS_FORCE),
    "status_no_force": BoardFrame(19, 19_000, 126.0, 250.0, 25.0, 0.0,
                                  STATUS_FLUX | STATUS_TC),
    "status_none": BoardFrame(20, 20_000, 0.0, 0.0, 25.0, 0.0, 0),
    # Extreme floats: the largest and smallest normal float32, a subnormal,
    # negative zero.
    "floats_extreme": BoardFrame(300, 300_000, f32(3.4028234663852886e38),
                                 -f32(3.4028234663852886e38), f32(1.1754943508222875e-38),
                                 -0.0),
    "floats_subnormal": BoardFrame(301, 301_000, f32(1.401298464324817e-45), f32(-1e-3),
                                   f32(-40.0), f32(1e-20)),
    # A value not exact in float32: the JSON holds what the record carries.
    "sample_inexact": BoardFrame(4242, 4_242_000, f32(0.1), f32(-1234.567), f32(33.3),
                                 f32(9.81)),
    # A record whose CRC has a zero byte (COBS must code it).
    "crc_low_zero": None,          # filled below: searched, deterministic
}


def _crc_with_zero_byte() -> BoardFrame:
    """The first sample (seq from 500) whose CRC has a 0x00 byte, so the
    vectors cover a zero in the CRC field."""
    for seq in range(500, 70_000):
        frame = BoardFrame(seq & 0xFFFF, 5_000_000, 1.5, 2.5, 25.0, 3.0)
        if 0 in cobs.decode(encode(frame)[:-1])[-2:]:
            return frame
    raise AssertionError("no CRC with a zero byte found")   # pragma: no cover


SERIAL_EXAMPLES["crc_low_zero"] = _crc_with_zero_byte()


def _v2(seq, t_us, flux_uv, tc_uv, cj_c, force_n, status, ir_object_c, ir_ambient_c,
        pad_drive, kind=TYPE_SAMPLE) -> BoardFrame:
    return BoardFrame(seq, t_us, flux_uv, tc_uv, cj_c, force_n, status, kind,
                      FRAME_VERSION_SLAVE, ir_object_c, ir_ambient_c, pad_drive)


_ALL_V2 = STATUS_ALL | STATUS_IR
#: Version 2 (the slave's board). The names start with ``v2_``.
SERIAL_EXAMPLES.update({
    # Before contact: the IR thermometer on the object, the Peltier pad held
    # 10 K above it (drive a fraction of full current).
    "v2_precontact": _v2(77, 770_000, 0.375, 412.25, 24.0, 0.0, _ALL_V2, 21.5, 24.25, 0.375),
    # In contact: flux into the object, force on the pad, IR still read.
    "v2_contact": _v2(1234, 1_234_567, 2205.25, 380.5, 24.0, 4.5, _ALL_V2, 21.5, 24.25,
                      -0.125),
    # A water pad pre-conditioning: heater on at 3/4 duty, pump on.
    "v2_water_pad": _v2(9, 90_000, 0.0, 300.0, 24.0, 0.0,
                        _ALL_V2 | STATUS_HEATER | STATUS_PUMP, 30.0, 24.5, 0.75),
    # The IR channel flagged bad by the board (its values are not read).
    "v2_ir_flagged": _v2(10, 100_000, 1.0, 2.0, 24.0, 0.0, STATUS_ALL, 0.0, 0.0, 0.0),
    # An IR reading outside what the sensor reports: the driver refuses it.
    "v2_ir_out_of_range": _v2(11, 110_000, 1.0, 2.0, 24.0, 0.0, _ALL_V2, 1000.0, 24.0, 0.0),
    # The slave's board restarted.
    "v2_boot": _v2(0, 0, 0.0, 0.0, 24.0, 0.0, 0, 0.0, 0.0, 0.0, TYPE_BOOT),
    # Wraps, negative drive at its limit, every status bit.
    "v2_wrap_all_bits": _v2(0xFFFF, 0xFFFF_FFFF, -1.0, 1.0, 25.0, 0.5, 63, -70.0, -40.0, -1.0),
})


#: name -> (message name, signals in physical units, as the DBC scales them).
CAN_EXAMPLES: dict[str, tuple[str, dict]] = {
    # Protocol version 2: the module current, A (1 mA), positive cools the pad side.
    "cmd_cool": ("PELTIER_CMD", {"enable": 1, "counter": 3, "current_a": 2.5, "version": 2}),
    "cmd_heat": ("PELTIER_CMD", {"enable": 1, "counter": 15, "current_a": -1.234,
                                 "version": 2}),
    "cmd_disable": ("PELTIER_CMD", {"enable": 0, "counter": 4, "current_a": 0.0,
                                    "version": 2}),
    "cmd_max": ("PELTIER_CMD", {"enable": 1, "counter": 0, "current_a": 32.767,
                                "version": 2}),
    "cmd_min": ("PELTIER_CMD", {"enable": 1, "counter": 9, "current_a": -32.768,
                                "version": 2}),
    "cmd_one_ma": ("PELTIER_CMD", {"enable": 1, "counter": 1, "current_a": -0.001,
                                   "version": 2}),
    # A version-1 master's command (bytes 1-2 a junction set point, 40.00 C,
    # which version 2 would read as 4.000 A): a version-2 driver refuses it
    # by its version byte.
    "cmd_version1": ("PELTIER_CMD", {"enable": 1, "counter": 1, "current_a": 4.0,
                                     "version": 1}),
    "status_enabled": ("PELTIER_STATUS", {"enabled": 1, "over_temp": 0, "over_current": 0,
                                          "sensor_fault": 0, "watchdog": 0,
                                          "sink_saturated": 0, "counter": 7,
                                          "junction_c": 35.25, "current_a": -4.1,
                                          "heatsink_c": 25.0}),
    "status_watchdog": ("PELTIER_STATUS", {"enabled": 0, "over_temp": 0, "over_current": 0,
                                           "sensor_fault": 0, "watchdog": 1,
                                           "sink_saturated": 0, "counter": 255,
                                           "junction_c": 33.0, "current_a": 0.0,
                                           "heatsink_c": 25.0}),
    "status_over_current": ("PELTIER_STATUS", {"enabled": 0, "over_temp": 0,
                                               "over_current": 1, "sensor_fault": 0,
                                               "watchdog": 0, "sink_saturated": 0,
                                               "counter": 12, "junction_c": 18.5,
                                               "current_a": 9.876, "heatsink_c": 31.0}),
    "status_sink_saturated": ("PELTIER_STATUS", {"enabled": 1, "over_temp": 0,
                                                 "over_current": 0, "sensor_fault": 0,
                                                 "watchdog": 0, "sink_saturated": 1,
                                                 "counter": 40, "junction_c": 20.0,
                                                 "current_a": 8.5, "heatsink_c": 61.5}),
    "status_all_faults": ("PELTIER_STATUS", {"enabled": 0, "over_temp": 1, "over_current": 1,
                                             "sensor_fault": 1, "watchdog": 1,
                                             "sink_saturated": 1, "counter": 0,
                                             "junction_c": -50.0, "current_a": -32.768,
                                             "heatsink_c": 150.0}),
    "status_cold": ("PELTIER_STATUS", {"enabled": 1, "over_temp": 0, "over_current": 0,
                                       "sensor_fault": 0, "watchdog": 0,
                                       "sink_saturated": 0, "counter": 128,
                                       "junction_c": 12.34, "current_a": 5.2,
                                       "heatsink_c": 26.5}),
    "heartbeat_boot": ("PELTIER_HEARTBEAT", {"state": 0, "version": 2}),
    "heartbeat_operational": ("PELTIER_HEARTBEAT", {"state": 5, "version": 2}),
    "heartbeat_disabled": ("PELTIER_HEARTBEAT", {"state": 127, "version": 2}),
    "heartbeat_fault": ("PELTIER_HEARTBEAT", {"state": 128, "version": 2}),
    # A version-1 board's heartbeat: the master refuses that board.
    "heartbeat_version1": ("PELTIER_HEARTBEAT", {"state": 5, "version": 1}),
    # The slave's active pad (node 2): a Peltier pad's current, a water pad's
    # heater and pump.
    "pad_cmd_peltier": ("PAD_CMD", {"enable": 1, "pump": 0, "counter": 5, "current_a": -0.35,
                                    "heater_duty": 0.0, "version": 2}),
    "pad_cmd_water": ("PAD_CMD", {"enable": 1, "pump": 1, "counter": 15, "current_a": 0.0,
                                  "heater_duty": 0.748, "version": 2}),
    "pad_cmd_disable": ("PAD_CMD", {"enable": 0, "pump": 0, "counter": 0, "current_a": 0.0,
                                    "heater_duty": 0.0, "version": 2}),
    "pad_status_peltier": ("PAD_STATUS", {"enabled": 1, "over_temp": 0, "sensor_fault": 0,
                                          "watchdog": 0, "pump_on": 0, "heater_on": 0,
                                          "counter": 9, "actuator_c": 31.5, "drive": -0.25,
                                          "heatsink_c": 24.0}),
    "pad_status_water": ("PAD_STATUS", {"enabled": 1, "over_temp": 0, "sensor_fault": 0,
                                        "watchdog": 0, "pump_on": 1, "heater_on": 1,
                                        "counter": 200, "actuator_c": 36.12, "drive": 0.748,
                                        "heatsink_c": 24.0}),
    "pad_status_watchdog": ("PAD_STATUS", {"enabled": 0, "over_temp": 0, "sensor_fault": 0,
                                           "watchdog": 1, "pump_on": 0, "heater_on": 0,
                                           "counter": 255, "actuator_c": 33.0, "drive": 0.0,
                                           "heatsink_c": 24.0}),
    # A heater duty of raw 255 (1.02, past the DBC's 0..1): a driver applies
    # it clamped to raw 250, full duty (CAN.md), and counts it.
    "pad_cmd_heater_over_range": ("PAD_CMD", {"enable": 1, "pump": 1, "counter": 6,
                                              "current_a": 0.0, "heater_duty": 1.02,
                                              "version": 2}),
    "pad_heartbeat_operational": ("PAD_HEARTBEAT", {"state": 5, "version": 2}),
    "pad_heartbeat_boot": ("PAD_HEARTBEAT", {"state": 0, "version": 2}),
}


#: CAN vectors outside the DBC's ranges on purpose (encoded without
#: cantools' range check): what a driver must clamp.
OUT_OF_RANGE = frozenset({"pad_cmd_heater_over_range"})

#: Fields a version-1 frame does not carry (left out of its JSON).
V2_FIELDS = ("ir_object_c", "ir_ambient_c", "pad_drive")


def serial_vectors() -> dict[str, tuple[bytes, dict]]:
    """name -> (the frame on the wire, its fields)."""
    out = {}
    for name, frame in SERIAL_EXAMPLES.items():
        fields = {k: getattr(frame, k) for k in BoardFrame.__slots__
                  if frame.version != FRAME_VERSION or k not in V2_FIELDS}
        out[name] = (encode(frame), fields)
    return out


def can_vectors() -> dict[str, tuple[bytes, dict]]:
    """name -> (the CAN data field, {message, frame_id, dlc, signals, raw})."""
    out = {}
    for name, (message_name, signals) in CAN_EXAMPLES.items():
        message = DB.get_message_by_name(message_name)
        data = message.encode(signals, strict=name not in OUT_OF_RANGE)
        out[name] = (data, {
            "message": message_name, "frame_id": message.frame_id, "dlc": message.length,
            "signals": message.decode(data, decode_choices=False),
            "raw": message.decode(data, decode_choices=False, scaling=False)})
    return out


def write(folder: str | Path) -> list[Path]:
    folder = Path(folder)
    written = []
    for sub, vectors in (("serial", serial_vectors()), ("can", can_vectors())):
        (folder / sub).mkdir(parents=True, exist_ok=True)
        for name, (data, fields) in vectors.items():
            (folder / sub / f"{name}.bin").write_bytes(data)
            (folder / sub / f"{name}.json").write_text(json.dumps(fields, indent=2) + "\n")
            written.append(folder / sub / f"{name}.bin")
    return written


if __name__ == "__main__":
    for path in write(sys.argv[1] if len(sys.argv) > 1 else "proto/golden"):
        print(path)
