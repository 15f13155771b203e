"""``telethermal bench devices``: sensor-to-controller and controller-to-
actuator latency through the emulated serial and CAN paths, beside the
direct simulator, in the same run (the paths stepped every 1 ms: a
per-call latency, not a rate); and a real-clock session with each, the
display loop at its default rate.

* serial: from the board emulator's ``send`` (the sample leaves the board:
  frame, COBS, pty write) to the driver returning the converted reading
  (pty read, COBS, CRC, NIST conversion);
* CAN: from the driver's ``command`` (DBC encode, bus send) to the Peltier
  emulator applying the setpoint (receive, decode), on python-can's
  ``virtual`` bus (in-process: it measures the software path, not a wire);
* direct: one ``SimDisplay.read``/``apply`` call (the physics included,
  which the emulated path also runs, so it is the floor).

The slave's side (``slave``): every scene material's touches of the
fingertip scene, each read once by the simulator's path and once through
the slave's emulated devices (version-2 board on a pty, the active pad's
driver on a virtual CAN bus) on the same trial (same seeds): identification
accuracy of each and their agreement; sensor-to-identifier latency (the
board emulator writing a sample's frame to the identifier having taken it:
pty, COBS, CRC, conversion, the slave's sample bookkeeping and the
identifier's own step), of which serial (to the driver's decoded reading);
and the pad's CAN controller-to-actuator latency (``PAD_CMD`` sent to the
pad driver applying it).

The reference firmware on QEMU's STM32F405 (``qemu``,
:mod:`telethermal.bench.firmware`): each image's flash and RAM, each
loop's worst iteration counted by the core, the Peltier driver's watchdog
over 20 trials timed by the core; the reason instead when QEMU or the
cross toolchain is missing.
"""

from __future__ import annotations

import datetime
import functools
import platform
import tempfile
import time

import numpy as np

from telethermal.bench import firmware
from telethermal.devices.display import EmulatedDisplay, SimDisplay
from telethermal.ident.anytime import members
from telethermal.jsonfile import write_json
from telethermal.physics.scene import load_scene, with_finger
from telethermal.teleop.decision import pad_decision
from telethermal.teleop.master import MasterStep, Phase
from telethermal.sim.touch import DisplayTouch, Operator

OPERATOR = Operator(finger_c=33.0, finger_ir_c=33.0, skin_k_scale=1.0, skin_heat_scale=1.0,
                    force_n=4.0, conductance_w_m2k=5000.0)


#: How long the bench waits for a CAN command to reach the emulated board;
#: one that has not arrived by then (polled once more after the wait) is
#: counted timed out (s).
CAN_WAIT_S = 0.05


def _timed_to_board(t0: float, poll, arrived) -> tuple[float, bool]:
    """Poll the emulated board until ``arrived()`` or CAN_WAIT_S since
    ``t0``, polling once more when the wait is over (a stall of this process
    is a late command, not a lost one): (seconds since ``t0``, arrived)."""
    while True:
        poll()
        if arrived() or time.perf_counter() - t0 >= CAN_WAIT_S:
            return time.perf_counter() - t0, arrived()


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
        read, apply_, serial, can, lost = [], [], [], [], 0
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
                step = MasterStep(t, Phase.CONTACT, True, float("nan"), 34.0, 34.0, False)
                t0 = time.perf_counter()
                if kind == "emulated":
                    # A current well inside the module's limits, alternating
                    # sign; timed until the board drives it (CAN_WAIT_S: timed out).
                    d.clear_applied()
                    d.hardware.peltier.command(0.5 if k % 2 else -0.5)
                    took, ok = _timed_to_board(t0, d.peltier_emulator.poll,
                                               lambda: d.applied_a is not None)
                    can.append(took)
                    lost += not ok
                    d.hardware.peltier.poll()
                t0 = time.perf_counter()
                d.apply(t, step, 1e-3, s.force_n)
                apply_.append(time.perf_counter() - t0)
        finally:
            d.close()
        out[kind] = {"read": _percentiles(read), "apply": _percentiles(apply_)}
        if kind == "emulated":
            out[kind]["serial_sensor_to_controller"] = _percentiles(serial)
            out[kind]["can_controller_to_actuator"] = {
                **_percentiles(can), "timed_out": lost}
    return out


def _sessions(scene, ident, gen, contact_s: float) -> dict:
    from telethermal.sim.inprocess import run_session
    out = {}
    for kind in ("sim", "emulated"):
        s = run_session(scene, "wood", ident, gen, contact_s=contact_s, seed=1, realtime=True,
                        devices=kind).summary
        loop = s["loop"]
        out[kind] = {"rate_hz": s["rate_hz"], "loop_period_p99_us": s["loop_period_p99_us"],
                     "busy_p99_us": loop.get("busy_p99_us"),
                     "deadline_misses": loop.get("deadline_misses"),
                     "overruns": loop.get("overruns"),
                     "steps": loop.get("steps"),
                     "flux_rms_error_rel_whole": s["flux_rms_error_rel_whole"],
                     "safety_events": s["safety_events"]}
    return out


def _stamp(stamps_s: np.ndarray, j: int) -> None:
    stamps_s[j] = time.perf_counter()


def _slave(scene, ident, trials_per_material: int, seed: int = 0) -> dict:
    """The slave's side on ``scene`` with the identifier ``ident``; ``seed``:
    its instruments' and touches' draws."""
    from telethermal.data.generate import sensor_session
    from telethermal.devices.slave_pad import EmulatedSlavePad
    from telethermal.teleop.slave import slave_rng
    from telethermal.teleop.slave import Slave

    session = sensor_session(scene, np.random.default_rng((seed, 0xBE)))
    devices = EmulatedSlavePad(scene, session.instruments, seed=seed)
    rows, to_ident, to_ident_backlog, serial = [], [], [], []
    try:
        for material in scene.materials:
            for k in range(trials_per_material):
                trial_seed = 1000 * seed + 17 * k + scene.materials.index(material)
                sim = Slave(scene, material, ident, slave_rng(trial_seed), session=session)
                sim.advance_to(float(sim.t_s[-1]) + 1.0)
                emu = Slave(scene, material, ident, slave_rng(trial_seed), session=session,
                            devices=devices)
                pushed_s = np.full(len(emu.t_s), np.nan)       # into the identifier
                emu.on_push = functools.partial(_stamp, pushed_s)
                backlog = np.zeros(len(emu.t_s), dtype=bool)
                t = float(emu.t_s[0])
                while t <= float(emu.t_s[-1]) + 0.02:            # period by period, 100 Hz
                    emu.advance_to(t)
                    t += 1.0 / scene.sample_rate_hz
                pushed = np.isfinite(pushed_s)
                if emu.detected_index is not None:
                    # The samples between the onset and its debounced detection
                    # wait for the detector, not for the devices: apart.
                    backlog[emu.onset_index:emu.detected_index] = True
                    to_ident_backlog += list((pushed_s - devices.write_s)[
                        emu.onset_index:emu.detected_index])
                    pushed[emu.onset_index:emu.detected_index] = False
                to_ident += list(pushed_s[pushed] - devices.write_s[pushed])
                got = np.isfinite(emu.received_s)
                serial += list(emu.received_s[got] - devices.write_s[got])
                # What each pad decided: the touch summary's one definition.
                d_sim, d_emu = pad_decision(sim), pad_decision(emu)
                rows.append({"material": material, "seed": trial_seed,
                             "sim": d_sim.identified, "emulated": d_emu.identified,
                             "sim_decision_s": d_sim.decision_time_s,
                             "emulated_decision_s": d_emu.decision_time_s,
                             "pad_true_c_sim": float(sim.trial.extra["T_pad_true_C"]),
                             "pad_true_c_emulated": float(emu.trial.extra["T_pad_true_C"])})
        can, lost = [], 0
        for k in range(1000):                   # the pad's CAN: command to applied
            # A current inside the module's limits, alternating sign, timed
            # until the pad's board drives it (CAN_WAIT_S: timed out).
            target = 0.5 if k % 2 else -0.5
            t0 = time.perf_counter()
            devices.pad.command(target)
            took, ok = _timed_to_board(t0, devices.pad_emulator.poll, lambda: abs(
                devices.pad_emulator.current_a - target) <= 1e-3)
            can.append(took)
            lost += not ok
            devices.pad.poll()
        counters = devices.all_counters()
    finally:
        devices.close()
    n = len(rows)

    def accuracy(path):
        return sum(r[path] == r["material"] for r in rows) / n

    def accuracy_with_pairs(path):
        return sum(r["material"] in members(r[path]) for r in rows) / n

    pad_diff = np.array([r["pad_true_c_emulated"] - r["pad_true_c_sim"] for r in rows])
    return {"scene": scene.name, "identifier": ident.method, "trials": n,
            "accuracy_sim": accuracy("sim"), "accuracy_emulated": accuracy("emulated"),
            "accuracy_difference_points": 100 * (accuracy("emulated") - accuracy("sim")),
            "accuracy_with_pairs_sim": accuracy_with_pairs("sim"),
            "accuracy_with_pairs_emulated": accuracy_with_pairs("emulated"),
            "agreement": sum(r["sim"] == r["emulated"] for r in rows) / n,
            "decision_time_difference_s_max": max(
                (abs(r["sim_decision_s"] - r["emulated_decision_s"]) for r in rows
                 if r["sim_decision_s"] is not None and r["emulated_decision_s"] is not None),
                default=None),
            "pad_temp_difference_k": {"mean": float(pad_diff.mean()),
                                      "sd": float(pad_diff.std()),
                                      "max_abs": float(np.abs(pad_diff).max())},
            "sensor_to_identifier": _percentiles(to_ident),
            "sensor_to_identifier_onset_backlog": _percentiles(to_ident_backlog),
            "serial_sensor_to_driver": _percentiles(serial),
            "can_controller_to_actuator": {
                **_percentiles(can), "timed_out": lost},
            "device_counters": counters, "touches": rows}


def run(n: int = 3000, contact_s: float = 3.0, progress=None,
        slave_trials: int = 10, models=None) -> dict:
    """The report; ``models``: a folder of ``telethermal models`` for
    fingertip-7 (:func:`telethermal.bench.models.bench_models`; None:
    trained here)."""
    import os

    from telethermal.bench.models import bench_models

    step = progress or (lambda _m: None)
    load_before = os.getloadavg()
    step("paths")
    paths = _paths(n)
    step("training" if models is None else "loading the models")
    scene = with_finger(load_scene("fingertip-7"))
    ident, gen, provenance = bench_models(scene, models)   # for both sides
    step("sessions")
    sessions = _sessions(scene, ident, gen, contact_s)
    step("slave")
    slave = _slave(scene, ident, slave_trials)
    step("qemu")
    with tempfile.TemporaryDirectory(prefix="telethermal-qemu-") as build:
        on_core = firmware.measure(build)
    return {"paths": paths, "sessions_real_clock": sessions, "slave": slave, "qemu": on_core,
            "models": provenance,
            # The machine's load (1, 5, 15 min) before and after: p99 figures
            # on a shared machine carry the other jobs' scheduling.
            "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
            "machine": f"{platform.node()} ({platform.machine()}, "
                       f"{platform.python_implementation()} {platform.python_version()})",
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def run_and_save(json_path, n: int = 3000, contact_s: float = 3.0, slave_trials: int = 10,
                 command: str = "", progress=None, models=None) -> dict:
    """Run the benchmark and write the JSON report (with ``command``);
    returns the report."""
    report = run(n=n, contact_s=contact_s, progress=progress, slave_trials=slave_trials,
                 models=models)
    report["command"] = command
    write_json(json_path, report)
    return report


