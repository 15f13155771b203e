"""The slave service's devices and object thermometer: which devices the
config names (none: the simulator alone; "emulated"; "hardware"), the
thermometer's self-calibration through them or on the simulator, and what
the devices counted over one touch (the touch report's ``devices``).
"""

from __future__ import annotations

import logging

from telethermal.devices.kinds import DeviceKind
from telethermal.errors import CalibrationError

# The service's one log, named as before this part was split out of it.
log = logging.getLogger("telethermal.slave")


def _emulated(config, scene, instruments, seed, rate_hz):
    from telethermal.devices.slave_pad import EmulatedSlavePad
    return EmulatedSlavePad(scene, instruments, seed=seed)


def _hardware(config, scene, instruments, seed, rate_hz):
    from telethermal.devices.board import Calibration
    from telethermal.devices.pad_drivers import SlavePadDrivers
    calibration = Calibration.load(config.calibration) if config.calibration else \
        Calibration()
    # Each period waits (up to two sample periods) for the board's next
    # frame: the pad's loop runs at the board's own rate.
    return SlavePadDrivers(config.board_url, config.can_bus, rate_hz, calibration,
                           wait_s=2.0 / rate_hz)


def _qemu(config, scene, instruments, seed, rate_hz):
    from telethermal.control.loop import RealClock
    from telethermal.devices.qemu_slave_pad import QemuSlavePad

    # The cores keep the service's time (time_scale): so do their drivers.
    return QemuSlavePad(scene, instruments, seed=seed, build_dir=config.firmware_build,
                        time_scale=config.time_scale,
                        clock=RealClock(scale=config.time_scale).monotonic)


#: The sensing pad's devices by kind (the simulator alone has none):
#: ``factory(config, scene, instruments, seed, rate_hz)``.
SLAVE_PADS = {DeviceKind.EMULATED: _emulated, DeviceKind.HARDWARE: _hardware,
              DeviceKind.QEMU: _qemu}


def open_devices(config, scene, instruments, seed: int, rate_hz: float):
    """The sensing pad's devices ``config.devices`` names (validated by the
    config), or None (the simulator alone)."""
    factory = SLAVE_PADS.get(config.devices)
    devices = None if factory is None else factory(config, scene, instruments, seed, rate_hz)
    if devices is not None:
        log.info("sensing pad on %s devices: board %s (frame version 2), active pad "
                 "driver on %s", devices.kind, devices.board.url, devices.pad.spec)
    return devices


def calibrate(devices, sensors, scene, rng, drift_k_per_reading: float = 0.0):
    """The object thermometer's calibration against the pad at three pad
    temperatures: through ``devices`` if there are, else on the simulator
    (``sensors``' instruments, noise from ``rng``). CalibrationError if it
    cannot be trusted."""
    from telethermal.control.thermometer_calibration import calibrate_simulated

    if devices is None:
        return calibrate_simulated(sensors.instruments, scene.room_temp_c, rng,
                                   scene.sensors.thermocouple_noise_uv,
                                   drift_k_per_reading=drift_k_per_reading)
    from telethermal.devices.slave_pad import calibrate_on_devices
    if drift_k_per_reading:
        raise CalibrationError("a drifting pad is a simulator-only hard case "
                               "(devices = 'sim')")
    emulated = devices.kind in (DeviceKind.EMULATED, DeviceKind.QEMU)
    if emulated:
        devices.aim_at_pad(rng)
    # On hardware the lab aims the thermometer at the pad for this.
    try:
        return calibrate_on_devices(devices, scene.room_temp_c)
    finally:
        if emulated:
            devices.show_object(float("nan"))


def flat_counters(counters: dict, prefix: str = "") -> dict:
    """Nested counters as one level, ``"board.crc"``: numbers only."""
    out = {}
    for k, v in counters.items():
        if isinstance(v, dict):
            out.update(flat_counters(v, f"{prefix}{k}."))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out[f"{prefix}{k}"] = v
    return out


def device_report(devices, before: dict) -> dict:
    """The devices' counters over one touch: now less ``before`` (their
    :func:`flat_counters` when the touch was placed: its object
    measurement, pre-conditioning and contact)."""
    now = flat_counters(devices.all_counters())
    d = {k: v - before.get(k, 0) for k, v in now.items()}
    return {"kind": devices.kind, "frames": d["board.frames"],
            "crc_errors": d["board.crc"], "gaps": d["board.seq_gaps"],
            "lost_frames": d["board.lost_frames"], "garbage": d["board.garbage"],
            "stale_readings": d["stale_readings"], "held_samples": d["held_samples"],
            "boards_lost": d["boards_lost"], "ir_refused": d["ir_refused"],
            "ir_out_of_range": d["board.ir_out_of_range"],
            "pad_commands": d["pad.sent"], "pad_statuses": d["pad.statuses"],
            "pad_faults_reported": d["pad.faults_reported"],
            "precondition": dict(devices.last_precondition), "counters": d}
