"""``telethermal bench render``: rendering error against control rate, the
display controller (impedance rendering against the flux PID with its static
feed-forward, every material), PID gains, the before-identification strategy
and the flux generator, and the display loop's timing on the real clock.

Every session is the in-process session of ``telethermal session`` on
``fingertip-7`` or ``--scene`` (identifier and generator trained once on its
databases, seed 0), 3 s contacts, operators and slave trials drawn from the
session seeds, so that every configuration sees the very same touches.
Errors are those of the session JSON: ``flux_rms_error_rel`` (after the
identification decision), ``flux_rms_error_rel_first_s`` and
``temp_rms_error_c`` (skin surface, the whole contact), against the same
operator's finger touching the object directly. The rate and controller
sections run 5 seeds per material; the gain section varies the flux PID, so
it runs the "static" controller, the one that uses it.
"""

from __future__ import annotations

import datetime
import json
import platform
import time
from pathlib import Path
from typing import Callable

import numpy as np

from telethermal.bench.models import bench_models
from telethermal.bench.real_clock import REAL_CLOCK_PERIODS, REAL_CLOCK_RATES_HZ, real_clock_row
from telethermal.bench.render_floor import (decision_floor_at_the_slaves_times, decision_floors,
                                            decision_times)
from telethermal.bench.render_limits import dew_report, limits_of, shipped_limits
from telethermal.control.loop import DEFAULT_RATE_HZ, DEPLOYED_PRIORITY, FixedRateLoop, RealClock
from telethermal.control.pid import PidGains
from telethermal.data.generate import finger_database
from telethermal.jsonfile import write_json
from telethermal.physics.scene import load_scene, with_finger
from telethermal.render.generator import ContactGenerator, NetworkGenerator, rendering_error
from telethermal.teleop.display_config import DEFAULT_GAINS, DisplayConfig
from telethermal.teleop.display_setup import limits_report
from telethermal.bench.render_sessions import (CONTACT_S, KEYS, Totals, config_fields,
                                               session_job)
from telethermal.bench.render_sessions import mean_of as _mean

RATES_HZ = (50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0)
SEEDS = (1, 2)
SEEDS_5 = (1, 2, 3, 4, 5)
FEEDFORWARD_MODELS = ("static", "impedance")
_SAT = dict(output_min=-25.0, output_max=25.0)
GAIN_SETS = {
    "feed-forward only": PidGains(0.0, 0.0, 0.0, **_SAT),
    "P 1e-4": PidGains(1e-4, 0.0, 0.0, **_SAT),
    "PI 1e-4/1e-3": PidGains(1e-4, 1e-3, 0.0, **_SAT),
    "PID 3e-4/2e-3/2e-5": PidGains(3e-4, 2e-3, 2e-5, **_SAT),
    "PI 1e-3/3e-3 (default)": PidGains(1e-3, 3e-3, 0.0, **_SAT),
    "PI 1e-3/1e-2": PidGains(1e-3, 1e-2, 0.0, **_SAT),
    "PI 1e-3/3e-2": PidGains(1e-3, 3e-2, 0.0, **_SAT),
}
#: The gain study with --quick: no feedback beside the shipped gains.
QUICK_GAIN_SETS = ("feed-forward only", "PI 1e-3/3e-3 (default)")
#: The real-clock rows' periods and touches with --quick: at the default
#: rate a touch of 0.5 s (450 periods with its approach and lift) covers the
#: 340 periods in one session, where the sweep's 3 s touch ran 1,700.
QUICK_CLOCK_PERIODS, QUICK_CLOCK_CONTACT_S = 340, 0.5


def junction_sensor_report(scene) -> dict:
    """The display's junction sensor as configured: name, stated lag as
    mounted, source (physics/modules.toml)."""
    from telethermal.teleop.display_setup import display_model_args
    js = display_model_args(scene)["junction_sensor"]
    return {"name": js.name, "tau_s": js.tau_s, "source": js.source}


def _aggregate(rows):
    out = {f"mean_{k}": _mean(rows, k) for k in KEYS[:3]}
    out["max_flux_rms_error_rel"] = float(max(r["flux_rms_error_rel"] for r in rows))
    out["max_temp_rms_error_c"] = float(max(r["temp_rms_error_c"] for r in rows))
    out["safety_events"] = int(sum(r["safety_events"] for r in rows))
    out["junction_stops"] = int(sum(r.get("junction_stops", 0) for r in rows))
    out["mean_cpu_s_per_simulated_s"] = _mean(rows, "cpu_s_per_simulated_s")
    out["limits"] = limits_of(rows)
    return out


def _per_material(rows) -> dict:
    """Mean and worst over seeds, per material, of the flux and skin errors."""
    out = {}
    for material in dict.fromkeys(r["material"] for r in rows):
        mine = [r for r in rows if r["material"] == material]
        out[material] = {f"{how}_{key}": float(fn([r[key] for r in mine]))
                         for key in ("flux_rms_error_rel", "temp_rms_error_c")
                         for how, fn in (("mean", np.mean), ("max", np.max))}
        out[material]["safety_events"] = int(sum(r["safety_events"] for r in mine))
    return out


def _materials(first: list[dict], repeat: list[dict], at_object: list[dict]) -> dict:
    """Per material, the default display's mean over seeds: a first touch
    (the idle policy's pad for an unknown object), a repeated one (the
    pad pre-conditioned for the material object memory announces) and, for
    comparison, a first touch with the pad idling at the object. Flux
    errors from the slave's first decision and over the first second, as
    fractions of the direct-contact peak; skin RMS over the whole contact."""
    out = {}
    for material in dict.fromkeys(r["material"] for r in first):
        mine = [r for r in first if r["material"] == material]
        again = [r for r in repeat if r["material"] == material]
        plain = [r for r in at_object if r["material"] == material]
        out[material] = {
            "skin_rms_k": _mean(mine, "temp_rms_error_c"),
            "skin_rms_max_k": float(max(r["temp_rms_error_c"] for r in mine)),
            "skin_rms_repeat_k": _mean(again, "temp_rms_error_c"),
            # Perceptual units (teleop/perception.py): the first second's heat
            # extraction against direct contact (discriminated beyond 1 +- 0.43)
            # and the seconds the skin is off by more than a fingertip detects.
            "heat_extraction_ratio_first_s": _mean(mine, "heat_extraction_ratio_first_s"),
            "skin_above_threshold_s": _mean(mine, "skin_above_threshold_s"),
            "heat_extraction_ratio_first_s_repeat": _mean(again, "heat_extraction_ratio_first_s"),
            "skin_above_threshold_s_repeat": _mean(again, "skin_above_threshold_s"),
            "flux_rms_from_decision_rel": _mean(mine, "flux_rms_error_rel"),
            "flux_rms_first_second_rel": _mean(mine, "flux_rms_error_rel_first_s"),
            "flux_rms_whole_rel": _mean(mine, "flux_rms_error_rel_whole"),
            "flux_rms_from_decision_repeat_rel": _mean(again, "flux_rms_error_rel"),
            "skin_rms_idle_at_object_k": _mean(plain, "temp_rms_error_c"),
            "flux_rms_from_decision_idle_at_object_rel": _mean(plain, "flux_rms_error_rel"),
            "display_idle_minus_object_k": _mean(
                [{"d": r["display_idle_c"] - r["object_ir_c"]} for r in mine], "d"),
            "display_idle_minus_object_repeat_k": _mean(
                [{"d": r["display_idle_c"] - r["object_ir_c"]} for r in again], "d"),
            "safety_events": int(sum(r["safety_events"] for r in mine + again + plain)),
            "seeds": len(mine)}
    return out


def _safety_counts(report: dict, more_rows: list[dict]) -> dict:
    """Safety events, the product's apart from the gain study's.

    ``safety_events`` counts every session run with the product's gains:
    every rate, both feed-forward models, both ``before`` modes, first and
    repeated touches, the pad idling at the object, and the gain study's
    default-gains rows (pad model right and 30 % off). The gain study's
    other rows try gains the product does not ship, one of them
    deliberately past stability: the supervisor limiting those is it doing
    its work, counted per row in ``safety_events_gain_study``."""
    product = [r for sec in ("rate", "controller", "before")
               for row in report[sec] for r in row["rows"]] + list(more_rows)
    study = {}
    for row in report["gains"]:
        n = int(sum(r["safety_events"] for r in row["rows"]))
        if (row["kp"], row["ki"], row["kd"]) == (DEFAULT_GAINS.kp, DEFAULT_GAINS.ki,
                                                 DEFAULT_GAINS.kd):
            product += row["rows"]
        else:
            study[f"{row['gains']}, pad model x{row['pad_resistance_belief']:g}"] = n
    return {"safety_events": int(sum(r["safety_events"] for r in product)),
            "safety_events_sessions": len(product),
            # The junction loop's stops on an implausible sensor (the module
            # at 0 A) and its re-arms at idle, in the same sessions.
            "junction_stops": int(sum(r.get("junction_stops", 0) for r in product)),
            "junction_rearms": int(sum(r.get("junction_rearms", 0) for r in product)),
            "safety_events_gain_study": study}


def generator_comparison(scene) -> dict:
    """Network against fitted closed form, leave one person out of database 2."""
    trials = finger_database(scene, np.random.default_rng(1000))
    persons = sorted({t.group for t in trials})
    scores = {"network": [], "contact": []}
    for person in persons:
        train = [t for t in trials if t.group != person]
        test = [t for t in trials if t.group == person]
        scores["network"].append(rendering_error(NetworkGenerator().fit(train), test))
        scores["contact"].append(rendering_error(ContactGenerator().fit(train), test))
    return {"held_out": persons, "rms_error_rel_of_peak": {k: float(np.mean(v))
                                                          for k, v in scores.items()},
            "per_person": scores}


def run(progress: Callable[[str], None] | None = None, quick: bool = False,
        scene_name: str = "fingertip-7", executor=None, models=None) -> dict:
    """The report (see the module); its sessions swept on ``executor``
    (:mod:`telethermal.bench.executor`; None: one worker process a CPU);
    ``models``: a folder of ``telethermal models`` for the scene
    (:func:`telethermal.bench.models.bench_models`; None: trained here)."""
    from telethermal.bench.executor import describe, open_executor, work_folder

    own = executor is None
    executor = open_executor("process") if own else executor
    try:
        ran_on = describe(executor)
        with work_folder(executor) as tmp:
            report = _run(progress, quick, scene_name, executor, Path(tmp), models)
        report["executor"] = ran_on
        return report
    finally:
        if own:
            executor.shutdown(cancel_futures=True)


def _run(progress, quick: bool, scene_name: str, executor, tmp: Path, models) -> dict:
    from telethermal.bench.executor import call_json, function_name, sweep
    from telethermal.render.generator import save_generator

    step = progress or (lambda _msg: None)
    scene = with_finger(load_scene(scene_name))
    materials = scene.materials[::3] if quick else scene.materials
    seeds = SEEDS[:1] if quick else SEEDS
    rates = (100.0, DEFAULT_RATE_HZ, 1000.0) if quick else RATES_HZ
    step("training" if models is None else "loading the models")
    t0 = time.perf_counter()
    identifier, generator, provenance = bench_models(scene, models)
    training_s = time.perf_counter() - t0 if provenance["trained"] else None
    job = {"scene": scene.ref or scene.name, "contact_s": CONTACT_S,
           "identifier": str(identifier.save(tmp / "identifier.npz")),
           "generator": str(save_generator(generator, tmp / "generator.npz"))}

    totals = Totals()

    def rows_of(config, mats=materials, sds=seeds, expected=False, pool=True):
        """Every material and seed's session on ``config``, in that order;
        each added to the run's totals (``pool``; else by the caller)."""
        rows = sweep(executor, session_job, [(job, m, s, config_fields(config),
                                              m if expected else None)
                                             for m in mats for s in sds])
        for row in rows if pool else ():
            totals.add(row)
        return rows

    report = {"scene": scene.name, "contact_s": CONTACT_S, "seeds": list(seeds),
              "materials": {m: {} for m in materials}, "training_s": training_s,
              "models": provenance}
    seeds5 = SEEDS_5[:1] if quick else SEEDS_5
    report["seeds_rate_and_controller"] = list(seeds5)
    report["rate"], report["controller"] = [], []
    step("controllers")
    by_model = {model: rows_of(DisplayConfig(feedforward_model=model), sds=seeds5, pool=False)
                for model in FEEDFORWARD_MODELS}
    first = by_model[DisplayConfig().feedforward_model]
    # The floor at the slave's decision times (from the shipped display's
    # first touches): a job on the sweep's executor, beside the sessions
    # below (it needs none of them).
    times = decision_times(first, materials)
    floors = executor.submit(call_json, function_name(decision_floors),
                             json.dumps([job["scene"], times])) if times else None
    try:                # a failed or interrupted sweep leaves no floor job running
        step("control rate")
        for rate in rates:
            rows = rows_of(DisplayConfig(rate_hz=rate), sds=seeds5)
            report["rate"].append({"rate_hz": rate, **_aggregate(rows), "rows": rows})
        for model, rows in by_model.items():         # pooled after the rates, as always
            for row in rows:
                totals.add(row)
            report["controller"].append({"feedforward_model": model, **_aggregate(rows),
                                         "per_material": _per_material(rows), "rows": rows})
        step("repeated touches (pre-conditioned from memory)")
        repeat = rows_of(DisplayConfig(), sds=seeds5, expected=True)
        step("first touches with the pad idling at the object (the policy's comparison)")
        at_object = rows_of(DisplayConfig(idle="object"), sds=seeds5)
        report["materials"] = _materials(first, repeat, at_object)
        report["decision_floor"] = None         # its place in the report: filled below
        step("PID gains")
        report["gains"] = []
        for name, gains in GAIN_SETS.items():
            if quick and name not in QUICK_GAIN_SETS:
                continue
            for belief in (1.0, 1.3):
                rows = rows_of(DisplayConfig(gains=gains, r_pad_belief=belief,
                                             feedforward_model="static"))
                report["gains"].append({"gains": name, "kp": gains.kp, "ki": gains.ki,
                                        "kd": gains.kd, "pad_resistance_belief": belief,
                                        **_aggregate(rows), "rows": rows})
        step("before identification")
        report["before"] = []
        for before in ("hold", "prior"):
            rows = rows_of(DisplayConfig(before=before))
            report["before"].append({"before": before, **_aggregate(rows), "rows": rows})
    except BaseException:
        if floors is not None:
            floors.cancel()
        raise
    step("the floor at the slave's decision times")
    report["decision_floor"] = decision_floor_at_the_slaves_times(
        first, materials, times, json.loads(floors.result()) if floors is not None else {})
    step("generators")
    report["generator"] = generator_comparison(scene) if not quick else None
    step("real clock")
    # The master's loop on the real clock, the simulated world (the slave,
    # its pad, the display's plant and sensors: other hardware in a lab)
    # not charged to it; and, for comparison, everything on its thread.
    # The machine's own floor first: the same loop doing nothing (its misses
    # are this machine's stalls and sleep overshoot alone).
    period_s = 1.0 / DEFAULT_RATE_HZ
    empty = FixedRateLoop(period_s, RealClock.for_period(period_s)).run(
        lambda t, dt: None, QUICK_CLOCK_PERIODS if quick else REAL_CLOCK_PERIODS).summary()
    report["real_clock_empty_loop"] = {"rate_hz": DEFAULT_RATE_HZ, **empty}
    report["real_clock"], report["real_clock_world_on_thread"] = [], []
    report["default_rate_hz"] = DEFAULT_RATE_HZ
    # And the master's loop at the default rate as the shipped deployments
    # run it: its thread at SCHED_FIFO (where the bench may set it).
    report["real_clock_deployed"] = []
    for key, mode, rates, priority in (
            ("real_clock", "master", (DEFAULT_RATE_HZ,) if quick else REAL_CLOCK_RATES_HZ, 0),
            ("real_clock_world_on_thread", True, (DEFAULT_RATE_HZ,), 0),
            ("real_clock_deployed", "master", (DEFAULT_RATE_HZ,), DEPLOYED_PRIORITY)):
        for rate in rates:
            report[key].append(real_clock_row(
                scene, identifier, generator, rate, mode,
                QUICK_CLOCK_CONTACT_S if quick else CONTACT_S, totals.limits,
                periods=QUICK_CLOCK_PERIODS if quick else REAL_CLOCK_PERIODS,
                priority=priority))
    report["limits"] = shipped_limits(report)
    report["limits_repeat"] = limits_of(repeat)
    report["limits_all_sessions"] = limits_report(totals.limits)
    report["junction_sensor"] = junction_sensor_report(scene)
    report["dew"] = dew_report(scene, totals.dew)
    report.update(_safety_counts(report, repeat + at_object))
    report["default_gains"] = {"kp": DEFAULT_GAINS.kp, "ki": DEFAULT_GAINS.ki,
                               "kd": DEFAULT_GAINS.kd}
    report["machine"] = (f"{platform.node()} ({platform.machine()}, "
                         f"{platform.python_implementation()} {platform.python_version()})")
    report["date"] = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    return report


def _plot_skin(ax, report: dict) -> None:
    """Skin temperature RMS per material of a first touch for each controller
    (bars: mean over seeds, triangles: worst), the default controller's
    repeated touch and first touch idling at the object (markers), and the
    mean over materials against the loop rate (inset)."""
    materials = report["materials"]
    x = np.arange(len(materials))
    controllers = report.get("controller") or []
    for i, c in enumerate(controllers):
        pm = c["per_material"]
        off = (i - (len(controllers) - 1) / 2) * 0.38
        ax.bar(x + off, [pm[m]["mean_temp_rms_error_c"] for m in materials], 0.38,
               color=f"C{i}", label=f"{c['feedforward_model']} (mean)")
        ax.plot(x + off, [pm[m]["max_temp_rms_error_c"] for m in materials], "v", color="k",
                ms=4, label="worst seed" if i == 0 else None)
    if all(materials[m].get("skin_rms_repeat_k") is not None for m in materials):
        ax.plot(x, [materials[m]["skin_rms_repeat_k"] for m in materials], "_", color="k",
                ms=18, mew=2, label="repeated touch, pre-conditioned (impedance)")
    if all(materials[m].get("skin_rms_idle_at_object_k") is not None for m in materials):
        ax.plot(x, [materials[m]["skin_rms_idle_at_object_k"] for m in materials], "x",
                color="C2", ms=6, label="first touch idling at the object (impedance)")
    ax.axhline(0.3, color="r", lw=0.8, ls=":", label="target 0.3 K (repeated touch)")
    ax.set_xticks(x, materials, rotation=20, fontsize=8)
    ax.set_ylabel(f"skin temperature RMS error (K), "
                  f"{report.get('default_rate_hz', 1000.0):g} Hz")
    ax.set_title("display controller, per material", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(alpha=0.3, axis="y")
    inset = ax.inset_axes([0.3, 0.55, 0.26, 0.3])
    inset.plot([r["rate_hz"] for r in report["rate"]],
               [r["mean_temp_rms_error_c"] for r in report["rate"]], "o-", ms=3, color="C3")
    inset.set_xscale("log")
    inset.set_xlabel("loop rate (Hz)", fontsize=7)
    inset.set_ylabel("mean skin RMS (K)", fontsize=7)
    inset.tick_params(labelsize=6)


def plot(report: dict, out_png: str | Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(14, 9.5))
    axes = axes.ravel()
    ax = axes[0]
    rates = [r["rate_hz"] for r in report["rate"]]
    for material in report["materials"]:
        err = [np.mean([x["flux_rms_error_rel"] for x in r["rows"] if x["material"] == material])
               for r in report["rate"]]
        ax.plot(rates, np.array(err) * 100, "o-", ms=3, lw=1, label=material)
    ax.set_xscale("log")
    ax.set_xlabel("display loop rate (Hz)")
    ax.set_ylabel("flux RMS error after identification (% of peak)")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")
    ax2 = ax.twinx()
    ax2.plot(rates, [r["mean_cpu_s_per_simulated_s"] for r in report["rate"]], "k--", lw=1)
    ax2.set_ylabel("CPU s per simulated s (dashed)")
    _plot_skin(axes[1], report)
    ax = axes[2]
    labels, nominal, wrong = [], [], []
    for r in report["gains"]:
        if r["pad_resistance_belief"] == 1.0:
            labels.append(r["gains"])
            nominal.append(100 * r["mean_flux_rms_error_rel"])
        else:
            wrong.append(100 * r["mean_flux_rms_error_rel"])
    x = np.arange(len(labels))
    ax.bar(x - 0.2, nominal, 0.4, label="model right")
    ax.bar(x + 0.2, wrong, 0.4, label="pad resistance believed 30 % high")
    ax.set_xticks(x, labels, rotation=20, fontsize=7, ha="right")
    ax.set_ylabel("mean flux RMS error after identification (%)")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, axis="y")
    ax.set_title("flux PID gains (static controller)", fontsize=9)
    ax = axes[3]
    for i, r in enumerate(report["before"]):
        ax.bar(i - 0.2, 100 * r["mean_flux_rms_error_rel_first_s"], 0.4, color="C0",
               label="flux, first second (%)" if i == 0 else None)
        ax.bar(i + 0.2, r["mean_temp_rms_error_c"], 0.4, color="C3",
               label="skin temperature RMS (K)" if i == 0 else None)
    ax.set_xticks(range(len(report["before"])), [r["before"] for r in report["before"]])
    ax.set_title("before identification", fontsize=9)
    ax.legend(fontsize=7)
    fig.suptitle(f"telethermal bench render - {report['date']} - {report['machine']}\n"
                 f"{report['scene']}, {report['contact_s']:g} s contacts, seeds "
                 f"{report.get('seeds_rate_and_controller', report['seeds'])} (rate, "
                 f"controller), {report['seeds']} (gains, before)", fontsize=9)
    fig.tight_layout()
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    from telethermal.jsonfile import write_figure
    write_figure(fig, out_png, dpi=110)
    plt.close(fig)
    return out_png


def run_and_save(json_path: str | Path, png_path: str | Path, quick: bool = False,
                 command: str = "", progress: Callable[[str], None] | None = None,
                 scene: str = "fingertip-7", executor=None, models=None) -> dict:
    """Run the benchmark on ``scene`` (a shipped name or a scene file), plot
    it to ``png_path`` and write the JSON report; returns the report."""
    report = run(progress=progress, quick=quick, scene_name=scene, executor=executor,
                 models=models)
    report["command"] = command
    report["png"] = str(plot(report, png_path))
    write_json(json_path, report)
    return report
