"""``telethermal bench devices``: sensor-to-controller and controller-to-
actuator latency through the emulated serial and CAN paths, beside the
direct simulator, in the same run; and the 1 kHz real-clock session with
each.

* serial: from the board emulator's ``send`` (the sample leaves the board:
  frame, COBS, pty write) to the driver returning the converted reading
  (pty read, COBS, CRC, NIST conversion);
* CAN: from the driver's ``command`` (DBC encode, bus send) to the Peltier
  emulator applying the setpoint (receive, decode), on python-can's
  ``virtual`` bus (in-process: it measures the software path, not a wire);
* direct: one ``SimDisplay.read``/``apply`` call (the physics included,
  which the emulated path also runs, so it is the floor).
"""

from __future__ import annotations

import datetime
import platform
import time

import numpy as np

from telethermal.devices.display import EmulatedDisplay, SimDisplay
from telethermal.physics.scene import load_scene
from telethermal.session.master import MasterStep
from telethermal.session.run import DisplayTouch, Operator, with_finger

OPERATOR = Operator(finger_c=33.0, finger_ir_c=33.0, skin_k_scale=1.0, skin_heat_scale=1.0,
                    force_n=4.0, conductance_w_m2k=5000.0)


def _percentiles(samples_s) -> dict:
    us = np.asarray(samples_s) * 1e6
    return {"n": int(len(us)), "p50_us": float(np.percentile(us, 50)),
            "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max())}


def _paths(n: int) -> dict:
    scene = with_finger(load_scene("fingertip-7"))
    out = {}
    for kind in ("sim", "emulated"):
        touch = DisplayTouch(scene, OPERATOR, 1000.0, n / 1000.0, 30.0,
                             np.random.default_rng(0))
        clock = [0.0]
        d = SimDisplay(touch) if kind == "sim" else EmulatedDisplay(touch, clock=lambda: clock[0])
        read, apply_, serial, can = [], [], [], []
        try:
            for k in range(n + 200):
                t = clock[0] = -0.2 + k * 1e-3
                if kind == "emulated":
                    s = touch.sense(t)
                    t0 = time.perf_counter()
                    d.board_emulator.send(t, s.flux_w_m2, s.pad_temp_c, s.force_n)
                    d.hardware.board.poll(wait_s=0.05)
                    serial.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                s = d.read(t)
                read.append(time.perf_counter() - t0)
                step = MasterStep(t, "contact", True, float("nan"), 34.0, 34.0, False)
                t0 = time.perf_counter()
                if kind == "emulated":
                    d.hardware.peltier.command(34.0)
                    d._applied = None
                    while d._applied is None and time.perf_counter() - t0 < 0.05:
                        d.peltier_emulator.poll()
                    can.append(time.perf_counter() - t0)
                    d.hardware.peltier.poll()
                t0 = time.perf_counter()
                d.apply(t, step, 1e-3, s.force_n)
                apply_.append(time.perf_counter() - t0)
        finally:
            d.close()
        out[kind] = {"read": _percentiles(read), "apply": _percentiles(apply_)}
        if kind == "emulated":
            out[kind]["serial_sensor_to_controller"] = _percentiles(serial)
            out[kind]["can_controller_to_actuator"] = _percentiles(can)
    return out


def _sessions(contact_s: float) -> dict:
    from telethermal.session.models import train_generator, train_identifier
    from telethermal.session.run import run_session
    scene = with_finger(load_scene("fingertip-7"))
    ident, gen = train_identifier(scene, 0), train_generator(scene, 0)
    out = {}
    for kind in ("sim", "emulated"):
        s = run_session(scene, "wood", ident, gen, contact_s=contact_s, seed=1, realtime=True,
                        devices=kind).summary
        loop = s["loop"]
        out[kind] = {"loop_period_p99_us": s["loop_period_p99_us"],
                     "busy_p99_us": loop.get("busy_p99_us"),
                     "deadline_misses": loop.get("deadline_misses"),
                     "overruns": loop.get("overruns"),
                     "steps": loop.get("steps"),
                     "flux_rms_error_rel_whole": s["flux_rms_error_rel_whole"],
                     "safety_events": s["safety_events"]}
    return out


def run(n: int = 3000, contact_s: float = 3.0, progress=None) -> dict:
    step = progress or (lambda _m: None)
    step("paths")
    paths = _paths(n)
    step("sessions")
    sessions = _sessions(contact_s)
    return {"paths": paths, "sessions_1khz_real_clock": sessions,
            "machine": f"{platform.node()} ({platform.machine()}, "
                       f"{platform.python_implementation()} {platform.python_version()})",
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
