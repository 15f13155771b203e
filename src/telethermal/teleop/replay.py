"""How a recording is replayed.

The master's rendering is re-run open loop on the recorded sensor readings
and news, with the recorded models and gains or new ones; the slave's
identifier is re-run on the recorded samples. With the same models and gains
the commands come out identical, sample for sample. What is recorded is
:mod:`telethermal.record.recorder`.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from telethermal.ident.openset import touch_text
from telethermal.jsonfile import write_json
from telethermal.record.recorder import periods
from telethermal.record.recording import RecordingError, read_recording
from telethermal.teleop.decision import pad_decision, touch_decision
from telethermal.teleop.master import Phase


def _replay_pad(params: dict) -> dict:
    """The pad's layers and contact conductance a recording names (none in
    recordings older than the skin-side controllers)."""
    from telethermal.physics.layered import Layer
    from telethermal.physics.materials import get_material

    if not (params.get("pad_layers") and params.get("contact_conductance_w_m2k")):
        return {}
    return {"pad_layers": tuple(Layer(get_material(name), float(thickness))
                                for name, thickness in params["pad_layers"]),
            "contact_conductance_w_m2k": params["contact_conductance_w_m2k"]}



def _replay_module(params: dict) -> dict:
    """The module, junction sensor and dew floor the display's loop was
    given (none in recordings older than the junction sensor's loop: the
    display is rebuilt without its inner loop, as it was recorded)."""
    from telethermal.physics.thermoelectric import JunctionSensorSpec, ModuleParams, ModuleSpec

    if not params.get("module"):
        return {}
    m = dict(params["module"])
    spec = dict(m.pop("spec"))
    spec["size_mm"] = tuple(spec["size_mm"])
    return {"module": ModuleParams(spec=ModuleSpec(**spec), **m),
            "pad_area_m2": params.get("pad_area_m2"),
            "junction_sensor": JunctionSensorSpec(**params["junction_sensor"]),
            "dew_floor_c": params.get("dew_floor_c")}


def _estimate_from(x):
    """A recorded estimate (recorder._estimate's list; the effusivity and
    nearest class, x[6:10], in recordings that hold them)."""
    from telethermal.ident.anytime import Estimate
    if x is None:
        return None
    if not isinstance(x, list) or len(x) not in (6, 10) or not isinstance(x[1], list):
        raise ValueError(f"an estimate is a list of 6 or 10 fields, got {str(x)[:64]}")
    return Estimate(x[0], tuple(x[1]), x[2], x[3], x[4], x[5], *x[6:10])


def _same(e):
    """What a replayed estimate must repeat of the recorded one."""
    return (tuple(e.posteriors), str(e.label), str(e.reason), e.effusivity_w_s05_m2k,
            e.effusivity_lo_w_s05_m2k, e.effusivity_hi_w_s05_m2k, e.nearest)


def touch_count(path) -> int:
    """How many touches a recording holds (a service's: many; a session's: one)."""
    rec = read_recording(path)
    starts = rec.messages("/master/touch_start")
    if starts:
        return len(starts)
    if rec.role == "slave":
        return len({m.get("contact_id", 0) for m in rec.messages("/slave/samples")})
    return 1


#: The figures against direct contact a touch's recorded summary may hold
#: (a simulated session's: the simulator knows the truth; a lab's has none).
DIRECT_KEYS = ("flux_rms_error_rel", "flux_rms_error_rel_first_s", "temp_rms_error_c")


#: The fastest display loop a recording may claim (the services run at up
#: to a few kHz).
MAX_RATE_HZ = 1e5
#: What a well-formed recording holding wrong values raises while it is
#: replayed (a field missing, of the wrong type, of the wrong length or out
#: of range): each becomes a RecordingError naming the file.
CONTENT_ERRORS = (KeyError, TypeError, ValueError, AttributeError, IndexError,
                  ZeroDivisionError, OverflowError, FloatingPointError)


def replay(path, identifier=None, generator=None, gains=None, touch: int = 0) -> dict:
    """Re-run the master's rendering (open loop, on the recorded sensor
    readings and news) and the slave's identifier (on the recorded samples)
    of one touch of a recording. ``identifier``/``generator``: models to use
    instead of the recorded ones; ``gains``: a :class:`PidGains` instead of
    the recorded. Returns the replayed series beside the recorded ones and a
    summary. A recording whose content is not what the recorder writes is a
    :class:`RecordingError` naming the file and what was wrong; a damaged
    one (``Recording.damaged``) is replayed but never called identical."""
    from telethermal.errors import ModelFileError, TelethermalError
    try:
        return _replay(path, identifier, generator, gains, touch)
    except (RecordingError, ModelFileError):
        raise
    except TelethermalError as exc:             # a recorded value a part refused
        raise RecordingError(f"{path}: holds a value that cannot be replayed: {exc}") from exc
    except CONTENT_ERRORS as exc:
        what = f"missing field {exc}" if isinstance(exc, KeyError) else \
            f"{type(exc).__name__}: {str(exc)[:300]}"
        raise RecordingError(f"{path}: holds a value the recorder does not write, so it cannot "
                             f"be replayed ({what})") from exc


def _replay(path, identifier, generator, gains, touch: int) -> dict:
    rec = read_recording(path)
    same_models = identifier is None and generator is None
    starts = rec.messages("/master/touch_start")
    slave_touches = sorted({m.get("contact_id", 0) for m in rec.messages("/slave/samples")})
    params, cid = rec.config, 0
    if starts:                                  # a master service: one touch of many
        if not 0 <= touch < len(starts):
            raise RecordingError(f"{path}: touch {touch} asked, the recording has "
                                 f"{len(starts)} (0..{len(starts) - 1})")
        params, cid = starts[touch], starts[touch]["contact_id"]
    elif rec.role == "slave":
        if not 0 <= touch < len(slave_touches):
            raise RecordingError(f"{path}: touch {touch} asked, the recording has "
                                 f"{len(slave_touches)}")
        cid = slave_touches[touch]
    elif touch != 0:
        raise RecordingError(f"{path}: touch {touch} asked, the recording holds one touch (0)")

    def attached(name, loader):
        if name not in rec.attachments:
            cut = (f" (the recording was cut, {rec.truncated}: its attachments, written at "
                   "its end, are lost)") if rec.truncated else ""
            raise RecordingError(f"{path}: no {name} attached{cut}; pass one to replay with")
        with tempfile.TemporaryDirectory() as tmp:
            f = Path(tmp) / name
            f.write_bytes(rec.attachments[name])
            return loader(f)

    summary = {"file": str(path), "role": rec.role, "contact_id": cid,
               "truncated": rec.truncated, "notes": rec.notes, "same_models": same_models,
               "damaged": rec.damaged}
    out = recorded = None
    if "display" in params:
        out, recorded, master_summary = _replay_master(rec, params, cid, generator, gains,
                                                       attached)
        summary.update(master_summary)
    elif rec.role != "slave":
        raise RecordingError(f"{path}: no display parameters recorded (role {rec.role!r})")
    slave = _replay_slave(rec, cid, identifier, attached)
    if slave is not None:
        summary["slave"] = slave
    if summary.get("periods") == 0 and slave is None:
        raise RecordingError(f"{path}: touch {touch} holds no period to replay" + (
            f" (the recording was cut, {rec.truncated})" if rec.truncated else ""))
    if rec.damaged and summary.get("identical"):
        summary["identical"] = False            # what was skipped was not compared
    ends = [m for m in rec.messages("/master/touch") if m.get("contact_id", 0) == cid]
    trace = [m for m in rec.messages("/sim/trace") if m.get("contact_id", 0) == cid]
    pad = [m for m in rec.messages("/slave/samples") if m.get("contact_id", 0) == cid]
    session = ends[0]["summary"] if ends else None
    summary["touch"] = touch
    summary["direct"] = {k: session[k] for k in DIRECT_KEYS} \
        if session is not None and all(session.get(k) is not None for k in DIRECT_KEYS) else None
    return {"summary": summary, "replayed": out, "recorded": recorded,
            "slave_samples": pad[0] if pad else None,
            "session": session,
            "trace": trace[0]["trace"] if trace else None}


def _replay_master(rec, params, cid, generator, gains, attached):
    from telethermal.control.pid import PidGains
    from telethermal.control.preconditioning import precondition_from
    from telethermal.render.generator import load_generator
    from telethermal.devices.readings import PadSensors
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.teleop.master import MasterDisplay, SlaveNews

    if "sampled_curves" in params:
        # An in-process session: the display rendered the curves the slave's
        # session sent, sampled from the generator (the attached one, or the
        # given one sampled the same way).
        from telethermal.render.sampled import SampledGenerator, sample_curves
        if generator is None:
            generator = attached("generator.npz", load_generator)
        generator = SampledGenerator(sample_curves(generator, list(params["sampled_curves"])))
    elif generator is None:
        wire_configs = rec.messages("/wire/in/session_config")
        if "generator.npz" not in rec.attachments and wire_configs:
            # A master's recording: the curves the slave sent, and this
            # touch's trajectories, as the master rendered them.
            from telethermal.render.sampled import SampledGenerator
            generator = SampledGenerator(wire_configs[-1]["curves"])
            for m in rec.messages("/wire/in/flux_trajectory"):
                if m["contact_id"] == cid:
                    t, g = m["t_s"], m["g_w_m2k"]
                    if t and t[0] == 0:
                        t, g = t[1:], g[1:]
                    generator.set_curve(m["material"], t, g)
        else:
            generator = attached("generator.npz", load_generator)
    d = params["display"]
    if gains is not None and d.get("feedforward_model", "static") != "static":
        raise RecordingError(f"{rec.path}: this touch was rendered by the "
                             f"{d['feedforward_model']!r} controller, which does not use the "
                             "flux PID's gains; replay with other gains needs a touch "
                             "recorded with feedforward_model 'static'")
    if not 0 < float(d["rate_hz"]) <= MAX_RATE_HZ:
        raise ValueError(f"display rate_hz {d['rate_hz']} outside (0, {MAX_RATE_HZ:g}]")
    recorded_gains = PidGains(**d["gains"])
    config = DisplayConfig(rate_hz=d["rate_hz"], before=d["before"], source=d["source"],
                           gains=gains or recorded_gains, feedforward=d["feedforward"],
                           slew_k_s=d["slew_k_s"], handover_k_s=d["handover_k_s"],
                           blend_s=d["blend_s"], r_pad_belief=d["r_pad_belief"],
                           # Recordings from before the skin-side controllers: "static".
                           feedforward_model=d.get("feedforward_model", "static"),
                           impedance_horizon_s=d.get("impedance_horizon_s", 0.1),
                           # Recordings from before these were recorded: the
                           # values the display then shipped with.
                           junction_reference_s=d.get("junction_reference_s", 0.02),
                           current_slew_a_s=d.get("current_slew_a_s", 100.0),
                           flux_inverse_s=d.get("flux_inverse_s", 0.02),
                           impedance_bias_filter_s=d.get("impedance_bias_filter_s", 0.05),
                           idle=d.get("idle", "object"))
    # Not build_display (teleop/display_setup.py), on purpose: a replay's
    # inputs are the display's parameters as recorded (a recording of an
    # older version included), not a scene and a link to build them from.
    # The idle policy the display applied (recordings before it: at the object).
    fractions = params.get("idle_policy") if d.get("idle") == "policy" else None
    master = MasterDisplay(config, generator, params["pad_resistance_m2k_w"],
                           params["sensor_lag_s"], params["finger_ir_c"],
                           idle_c=params["idle_c"], **_replay_pad(params),
                           **_replay_module(params),
                           precondition=precondition_from(fractions, params["finger_ir_c"])
                           if fractions else None,
                           # Recordings before the display's gain was applied: none.
                           flux_gain=params.get("flux_gain", 1.0),
                           # (recordings before the stretch: none)
                           impedance_horizon_scale=params.get("impedance_horizon_scale", 1.0))
    rows = periods(rec, cid)
    news_at = {n["k"]: n for n in rec.messages("/master/news")
               if n.get("contact_id", 0) == cid}
    news = SlaveNews()
    out = {k: [] for k in ("t_s", "desired_flux_w_m2", "junction_applied_c", "phase")}
    for p in rows:
        n = news_at.get(p["k"])
        if n is not None:
            news = SlaveNews(n["object_temp_c"], _estimate_from(n["estimate"]),
                             tuple(n["classes"]), n["setpoint_w_m2"], n["link_ok"],
                             expected_material=n.get("expected_material"))
        step = master.step(p["t_s"], p["dt_s"],
                           PadSensors(p["flux_w_m2"], p["pad_temp_c"], p["force_n"],
                                      junction_c=p["junction_c"], heatsink_c=p["heatsink_c"]),
                           news)
        out["t_s"].append(p["t_s"])
        out["desired_flux_w_m2"].append(step.desired_flux_w_m2)
        out["junction_applied_c"].append(step.junction_applied_c)
        out["phase"].append(step.phase)
    recorded = {k: [p[k] for p in rows] for k in
                ("t_s", "desired_flux_w_m2", "junction_applied_c", "phase", "flux_w_m2",
                 "pad_temp_c")}
    a = np.array(out["junction_applied_c"], dtype=float)
    b = np.array(recorded["junction_applied_c"], dtype=float)
    qa = np.array(out["desired_flux_w_m2"], dtype=float)
    qb = np.array(recorded["desired_flux_w_m2"], dtype=float)
    same_nan = np.array_equal(np.isnan(qa), np.isnan(qb))
    both = ~np.isnan(qa) & ~np.isnan(qb)
    return out, recorded, {
        "periods": len(rows), "gains": asdict(config.gains), "flux_gain": master.flux_gain,
        "recorded_gains": asdict(recorded_gains),
        "junction_max_abs_diff_c": float(np.max(np.abs(a - b))) if len(a) else 0.0,
        "desired_max_abs_diff_w_m2": float(np.max(np.abs(qa[both] - qb[both])))
        if both.any() else 0.0,
        "identical": bool(len(a) > 0 and np.array_equal(a, b) and same_nan and
                          np.array_equal(qa[both], qb[both]))}


def _replay_slave(rec, cid, identifier, attached):
    from telethermal.ident.registry import load_model
    from telethermal.teleop.slave import Slave

    samples = [m for m in rec.messages("/slave/samples") if m.get("contact_id", 0) == cid]
    if not samples:
        return None
    s = samples[0]
    for key in ("object_ir_c", "gap_k", "pad_before_c"):
        if isinstance(s.get(key), bool) or not isinstance(s.get(key), (int, float)):
            raise ValueError(f"/slave/samples of contact {cid}: {key} is "
                             f"{str(s.get(key))[:32]}, not a number")
    identifier = identifier or attached("identifier.npz", load_model)
    channels = {k: v for k, v in s.items() if isinstance(v, list)}
    slave = Slave.from_samples(channels, identifier, s["object_ir_c"], s["gap_k"],
                               s["object_true_c"], s["pad_before_c"])
    slave.advance_to(math.inf)
    est = slave.estimate
    recorded_est = [_estimate_from(m["estimate"]) for m in rec.messages("/slave/estimates")
                    if m.get("contact_id", 0) == cid]
    last = recorded_est[-1] if recorded_est else None
    # What was decided, replayed and recorded, as every summary defines it
    # (teleop/decision.py).
    replayed = pad_decision(slave)
    recorded = touch_decision(recorded_est)
    return {"onset_s": slave.onset_s,
            "identified": replayed.identified, "decision_time_s": replayed.decision_time_s,
            "recorded_identified": recorded.identified,
            "recorded_decision_time_s": recorded.decision_time_s,
            "estimates": len(slave.events), "recorded_estimates": len(recorded_est),
            # posteriors, label, reason, and effusivity estimate and nearest class
            "same_estimates": [_same(e.estimate) for e in slave.events] ==
            [_same(e) for e in recorded_est],
            "identified_text": touch_text(est),
            "recorded_identified_text": touch_text(last),
            "posteriors_max_abs_diff": _posteriors_diff([e.estimate for e in slave.events],
                                                        recorded_est)}


def _posteriors_diff(replayed, recorded) -> float | None:
    """The largest difference of one posterior between the replayed and the
    recorded estimates, or None when they differ in number or shape."""
    if len(replayed) != len(recorded):
        return None
    diff = 0.0
    for a, b in zip(replayed, recorded):
        pa, pb = tuple(a.posteriors or ()), tuple(b.posteriors or ())
        if len(pa) != len(pb) or a.label != b.label or a.t_s != b.t_s:
            return None
        diff = max([diff, *(abs(x - y) for x, y in zip(pa, pb))])
    return diff


def plot_replay(result: dict, path: str | Path) -> Path:
    """The session from its recording (:func:`replay_figure`; a slave's
    recording: its pad's flux and temperature) into ``path``."""
    if result["recorded"] is None:
        return _plot_slave(result, path)
    return _save(replay_figure(result), path)


def replay_figure(result: dict):
    """Flux and temperature at the master's pad (recorded, and the
    simulator's truth and direct contact when the recording has them), the
    replayed setpoint beside the recorded one, the decision instant, and the
    periods the display had lost the link shaded. Flux in the project's one
    convention, as the session's plot draws it (:mod:`telethermal.teleop.plots`):
    positive out of the finger (the display's flux into it, negated)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from telethermal.teleop.plots import OUT_OF_FINGER_KW

    rec, rep, s = result["recorded"], result["replayed"], result["summary"]

    def out_of_finger_kw(values):
        return -np.asarray(values, dtype=float) / 1e3

    t = np.asarray(rec["t_s"], dtype=float)
    fig, (ax_q, ax_t) = plt.subplots(1, 2, figsize=(13, 4.6))
    tr = result.get("trace")
    if tr:
        # The simulator's truth (a lab recording has none): what reached the
        # finger, and direct contact where the session computed it.
        tt = np.asarray(tr["t_s"], dtype=float)
        for ax, key, style, label in (
                (ax_q, "direct_flux_w_m2", "k-", "direct contact (simulated truth)"),
                (ax_q, "flux_w_m2", "C3-", "rendered into the finger (simulated truth)"),
                (ax_t, "direct_skin_c", "k-", "skin, direct contact"),
                (ax_t, "skin_surface_c", "C3-", "skin, rendered")):
            if key in tr:
                values = np.asarray(tr[key], dtype=float)
                ax.plot(tt, out_of_finger_kw(values) if ax is ax_q else values, style,
                        lw=2 if style == "k-" else 1, label=label)
    # The recorded readings are the sensor's; the display read them over its
    # calibrated gain (1: none).
    ax_q.plot(t, out_of_finger_kw(np.asarray(rec["flux_w_m2"], dtype=float)
                                  / s.get("flux_gain", 1.0)), "C0-", lw=0.8,
              label="pad sensor (recorded, over its gain)")
    ax_q.plot(t, out_of_finger_kw(rec["desired_flux_w_m2"]), "C2-", lw=1.5,
              label="setpoint (recorded)")
    ax_q.plot(rep["t_s"], out_of_finger_kw(rep["desired_flux_w_m2"]), "m--",
              lw=1, label="setpoint (replayed)")
    ax_t.plot(t, np.asarray(rec["pad_temp_c"], dtype=float), "C0-", lw=0.8,
              label="display pad (recorded)")
    ax_t.plot(t, np.asarray(rec["junction_applied_c"], dtype=float), "C7-", lw=1,
              label="junction (recorded)")
    ax_t.plot(rep["t_s"], rep["junction_applied_c"], "m--", lw=1, label="junction (replayed)")
    phases = np.asarray(rec["phase"], dtype=object)
    for ax in (ax_q, ax_t):
        for bad, color in ((Phase.LINK_LOST, "C3"),):
            mask = phases == bad
            if mask.any():
                ax.fill_between(t, 0, 1, where=mask, color=color, alpha=0.15,
                                transform=ax.get_xaxis_transform(), label=bad)
        slave = s.get("slave") or {}
        if slave.get("decision_time_s") is not None and slave.get("onset_s") is not None:
            x = slave["onset_s"] + slave["decision_time_s"]
            ax.axvline(x, color="C2", lw=0.8)
            ax.annotate(f"slave: {slave['identified']}", (x, 0.02),
                        xycoords=("data", "axes fraction"), fontsize=8, color="C2")
        ax.grid(alpha=0.3)
        ax.set_xlabel("time since contact (s)")
        ax.legend(fontsize=7)
    ax_q.set_ylabel(OUT_OF_FINGER_KW)
    ax_t.set_ylabel("temperature (°C)")
    verdict = "identical to the recording" if s["identical"] else \
        f"junction differs by up to {s['junction_max_abs_diff_c']:.3g} K"
    fig.suptitle(f"replay of {Path(s['file']).name}: {s['periods']} periods, {verdict}",
                 fontsize=10)
    return fig


def _save(fig, path) -> Path:
    import matplotlib.pyplot as plt

    from telethermal.jsonfile import write_figure
    fig.tight_layout()
    try:
        return write_figure(fig, path, dpi=100, fmt="png")
    finally:
        plt.close(fig)


def _plot_slave(result: dict, path) -> Path:
    """A slave's recording: the pad's flux and temperature, the onset and
    the decision, recorded beside replayed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pad, sl = result["slave_samples"], result["summary"].get("slave") or {}
    fig, ax = plt.subplots(figsize=(9, 4.5))
    t = np.asarray(pad["t_s"], dtype=float)
    ax.plot(t, np.asarray(pad["heat_flux_W_m2"], dtype=float) / 1e3, "C0-", lw=1,
            label="sensing pad heat flux")
    ax.set_ylabel("heat flux pad -> object (kW/m$^2$),\npositive into the object")
    ax2 = ax.twinx()
    ax2.plot(t, np.asarray(pad["temperature_C"], dtype=float), "C1-", lw=1,
             label="sensing pad temperature")
    ax2.set_ylabel("temperature (°C)")
    if sl.get("onset_s") is not None:
        ax.axvline(sl["onset_s"], color="0.5", lw=0.8)
        for time_key, label_key, color, ls, y in (
                ("decision_time_s", "identified", "C2", "-", 0.02),
                ("recorded_decision_time_s", "recorded_identified", "m", "--", 0.08)):
            if sl.get(time_key) is not None:
                x = sl["onset_s"] + sl[time_key]
                ax.axvline(x, color=color, ls=ls, lw=0.9)
                who = "replayed" if label_key == "identified" else "recorded"
                ax.annotate(f"{who}: {sl[label_key]}", (x, y),
                            xycoords=("data", "axes fraction"), fontsize=8)
    ax.set_xlabel("time (s)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=7)
    fig.suptitle(f"replay of {Path(result['summary']['file']).name}, contact "
                 f"{result['summary']['contact_id']} (slave)", fontsize=10)
    return _save(fig, path)


def replay_to_folder(path, out: str | Path, identifier_path=None, generator_path=None,
                     gains_kp_ki_kd: tuple[float, float, float] | None = None,
                     touch: int = 0) -> tuple[dict, Path]:
    """:func:`replay` with models loaded from files and new PID gains (the
    recorded ones where None); writes ``out/replay.json`` (the summary) and
    the plot. Returns the summary and the plot's path."""
    from telethermal.ident.registry import load_model
    from telethermal.render.generator import load_generator
    from telethermal.teleop.display_config import DEFAULT_GAINS

    identifier = load_model(identifier_path) if identifier_path else None
    generator = load_generator(generator_path) if generator_path else None
    gains = None
    if gains_kp_ki_kd is not None:
        kp, ki, kd = gains_kp_ki_kd
        gains = replace(DEFAULT_GAINS, kp=kp, ki=ki, kd=kd)
    result = replay(path, identifier, generator, gains, touch=touch)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    png = plot_replay(result, out / "replay.png")
    write_json(out / "replay.json", result["summary"])
    return result["summary"], png
