"""What a session records: :class:`SessionRecorder`.

Every control period of the master (its sensors, what it knew of the slave
when that changed, what it commanded), the slave pad's samples and its
estimates, the models as attachments, the parameters to rebuild the display,
and at the end the session's summary and (simulation only) the simulator's
trace, which holds the truth a lab cannot measure. Replaying a recording is
:mod:`telethermal.teleop.replay` (it re-runs the master's and slave's logic).
"""

from __future__ import annotations

import tempfile
from dataclasses import asdict
from pathlib import Path

import numpy as np

from telethermal.physics.layered import pad_resistance
from telethermal.record.recording import Recorder


#: Control periods per recorded message (columns): 20 ms of them at any
#: rate (20 periods at 1 kHz, 4 at 200 Hz), the most a recording cut
#: mid-write loses.
PERIOD_BATCH_S = 0.020
PERIOD_FIELDS = ("t_s", "dt_s", "flux_w_m2", "pad_temp_c", "force_n", "phase",
                 "desired_flux_w_m2", "junction_cmd_c", "junction_applied_c", "safe",
                 "junction_c", "heatsink_c")
#: Fields a recording made before the junction sensor's loop does not hold
#: (the module's junction and heat sink as the driver reported them): nan.
LATER_PERIOD_FIELDS = ("junction_c", "heatsink_c")


def periods(rec, contact_id: int | None = None) -> list[dict]:
    """The recorded control periods, one dict each (from their batches)."""
    out = []
    for batch in rec.messages("/master/periods"):
        cid = batch.get("contact_id", 0)
        if contact_id is not None and cid != contact_id:
            continue
        n = len(batch["t_s"])
        for i in range(n):
            row = {k: batch[k][i] if k in batch or k not in LATER_PERIOD_FIELDS
                   else float("nan") for k in PERIOD_FIELDS}
            row["k"], row["contact_id"] = batch["k0"] + i, cid
            out.append(row)
    return out


def model_bytes(identifier, generator) -> dict[str, bytes]:
    from telethermal.render.generator import save_generator
    with tempfile.TemporaryDirectory() as tmp:
        out = {}
        if identifier is not None:
            out["identifier.npz"] = identifier.save(Path(tmp) / "identifier.npz").read_bytes()
        if generator is not None and hasattr(generator, "materials") and \
                not type(generator).__name__.startswith("Sampled"):
            out["generator.npz"] = save_generator(generator,
                                                  Path(tmp) / "generator.npz").read_bytes()
        return out


def _estimate(e):
    """[t_s, posteriors, label, confidence, decided, reason], and, when the
    identifier estimated the object's effusivity, [..., effusivity, its 95 %
    interval's lo and hi (W s^0.5/(m^2 K)), nearest class or None] (issue 30)."""
    if e is None:
        return None
    out = [float(e.t_s), [float(p) for p in e.posteriors], e.label, float(e.confidence),
           bool(e.decided), e.reason]
    if getattr(e, "effusivity_w_s05_m2k", None) is not None:
        out += [float(e.effusivity_w_s05_m2k), float(e.effusivity_lo_w_s05_m2k),
                float(e.effusivity_hi_w_s05_m2k), e.nearest]
    return out


def open_recorder(config, role: str, identifier=None, generator=None):
    """A service's recorder, if its config has a ``record_dir``: one file per
    run, ``<role>-<UTC time>.mcap``."""
    import datetime
    from dataclasses import asdict as as_dict

    if not getattr(config, "record_dir", ""):
        return None
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%dT%H%M%S")
    path = Path(config.record_dir) / f"{role}-{stamp}.mcap"
    return SessionRecorder(Recorder(path, role, as_dict(config),
                                    model_bytes(identifier, generator)))


def display_params(scene, config, operator, idle_c, display=None) -> dict:
    """What a replay needs to rebuild the display of one touch (the module,
    the junction sensor and the dew floor the display's loop was given:
    its models, from the scene as the product builds them; the two lags
    and the flux gain the ``display`` (a MasterDisplay) was built with,
    calibrated or not, when given)."""
    from telethermal.control.dew import idle_floor_c
    from telethermal.control.preconditioning import policy_fractions

    # The pad's layers as the display modelled them (a calibrated face layer),
    # and the idle policy it applies (its pre-conditioning's); without a
    # display, the scene's.
    layers = display.pad_layers if display is not None and display.pad_layers \
        else tuple(scene.pad.layers)
    applied = getattr(getattr(display, "precondition", None), "fractions", None)
    policy = None if config.idle != "policy" else \
        applied if applied is not None else policy_fractions(scene)

    return {"display": {"rate_hz": config.rate_hz, "before": config.before,
                        "idle": config.idle,
                        "source": config.source, "gains": asdict(config.gains),
                        "feedforward": config.feedforward, "slew_k_s": config.slew_k_s,
                        "handover_k_s": config.handover_k_s, "blend_s": config.blend_s,
                        "r_pad_belief": config.r_pad_belief,
                        "feedforward_model": config.feedforward_model,
                        "impedance_horizon_s": config.impedance_horizon_s,
                        "junction_reference_s": config.junction_reference_s,
                        "current_slew_a_s": config.current_slew_a_s,
                        "flux_inverse_s": config.flux_inverse_s,
                        "impedance_bias_filter_s": config.impedance_bias_filter_s},
            "pad_resistance_m2k_w": pad_resistance(layers),
            "pad_layers": [[layer.material.name, layer.thickness_m] for layer in layers],
            "contact_conductance_w_m2k": (scene.finger.contact_conductance_w_m2k
                                          if scene.finger is not None else None),
            "sensor_lag_s": (scene.sensors.flux_lag_s if display is None
                             else display.sensor_lag_s),
            "flux_gain": 1.0 if display is None else display.flux_gain,
            "impedance_horizon_scale": 1.0 if display is None
            else display.impedance_horizon_scale,
            "finger_ir_c": operator.finger_ir_c, "idle_c": idle_c,
            # The idle policy the display applied (fractions of finger - object).
            "idle_policy": policy,
            "operator": asdict(operator),
            "module": asdict(scene.pad.module_params()[0]), "pad_area_m2": scene.pad.area_m2,
            "junction_sensor": asdict(scene.sensors.junction_sensor_spec() if display is None
                                      else display.junction_sensor),
            "dew_floor_c": _finite_or_none(idle_floor_c(scene.room_temp_c,
                                                        scene.room_humidity_pct))}


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


class SessionRecorder:
    """What the master's loop and the slave's pad record, on one
    :class:`Recorder`: the in-process session (role ``session``, one touch)
    or a service (many touches, each opened by ``touch_start``)."""

    def __init__(self, recorder: Recorder):
        self.rec = recorder
        self._news = None
        self._k = 0
        self.contact_id = 0
        self._cols = {k: [] for k in PERIOD_FIELDS}
        #: The slave's stream: (contact_id, pad, samples logged, estimates logged).
        self._slave_at: tuple = (None, None, 0, 0)

    @classmethod
    def open(cls, path, scene, material, identifier, generator, config, operator, idle_c,
             seed, contact_s, devices, sampled: list | None = None,
             display=None) -> "SessionRecorder":
        """``sampled``: the materials whose sampled curves the display
        rendered (the in-process run renders what the slave's session
        sends, as the services do), sampled from the attached generator."""
        params = {"scene": scene.name, "material": material, "seed": seed,
                  "contact_s": contact_s, "devices": devices,
                  **display_params(scene, config, operator, idle_c, display),
                  **({"sampled_curves": sampled} if sampled is not None else {})}
        return cls(Recorder(path, "session", params, model_bytes(identifier, generator)))

    def touch_start(self, t_s: float, contact_id: int, params: dict) -> None:
        self._flush_periods()
        self.contact_id, self._news, self._k = contact_id, None, 0
        self.rec.log("/master/touch_start", t_s, {"contact_id": contact_id, **params})

    def period(self, t_s, dt_s, sensors, news, step) -> None:
        """One control period. Periods are sent to the writer in batches of
        ``PERIOD_BATCH_S`` (columns, one message), which costs the loop a few
        list appends per period and the writer one record per batch."""
        if news != self._news:
            self._news = news
            self.rec.log("/master/news", t_s, {
                "contact_id": self.contact_id, "k": self._k, "t_s": t_s,
                "object_temp_c": news.object_temp_c, "estimate": _estimate(news.estimate),
                "classes": list(news.classes), "setpoint_w_m2": news.setpoint_w_m2,
                "link_ok": news.link_ok, "expected_material": news.expected_material})
        cols = self._cols
        if not cols["t_s"]:
            self._k0, self._t0 = self._k, t_s
        for key, value in (("t_s", t_s), ("dt_s", dt_s), ("flux_w_m2", sensors.flux_w_m2),
                           ("pad_temp_c", sensors.pad_temp_c), ("force_n", sensors.force_n),
                           ("phase", step.phase), ("desired_flux_w_m2", step.desired_flux_w_m2),
                           ("junction_cmd_c", step.junction_cmd_c),
                           ("junction_applied_c", step.junction_applied_c),
                           ("safe", bool(step.safe)),
                           ("junction_c", sensors.junction_c),
                           ("heatsink_c", sensors.heatsink_c)):
            cols[key].append(value)
        self._k += 1
        if t_s + dt_s - self._t0 >= PERIOD_BATCH_S * (1.0 - 1e-6):
            self._flush_periods()

    def _flush_periods(self) -> None:
        cols = self._cols
        if cols["t_s"]:
            # The lists are handed over as they are (Python floats, str and
            # bool, which msgpack takes); new ones start for the next batch.
            self.rec.log("/master/periods", self._t0, {
                "contact_id": self.contact_id, "k0": self._k0, **cols})
        self._cols = {k: [] for k in PERIOD_FIELDS}

    def note(self, what: str, fields: dict) -> None:
        """A one-off record of the slave's instruments (e.g. its thermometer
        calibration: ``/slave/thermometer_calibration``)."""
        self.rec.log(f"/slave/{what}", 0.0, _plain(fields))

    def wire(self, t_s: float, direction: str, message: dict) -> None:
        self.rec.log(f"/wire/{direction}/{message['kind']}", t_s, _plain(message))

    def slave_stream(self, slave, contact_id: int = 0, final: bool = False) -> None:
        """The pad's samples and estimates as they come: the samples read
        since the last batch once they span ``PERIOD_BATCH_S`` (or at once,
        ``final``), each new estimate at once. A new ``contact_id`` (or a new
        pad) starts from its first sample."""
        if (contact_id, id(slave)) != self._slave_at[:2]:
            self._slave_at = (contact_id, id(slave), 0, 0)
        k0, e0 = self._slave_at[2:]
        n = slave.samples_read
        t_s = slave.channels.get("t_s")
        if n > k0 and (final or t_s is None or
                       t_s[n - 1] - t_s[k0] >= PERIOD_BATCH_S * (1.0 - 1e-6)):
            self.rec.log("/slave/sample_batch", float(t_s[k0]) if t_s is not None else 0.0, {
                **{k: [float(v) for v in np.asarray(c)[k0:n]] for k, c in slave.channels.items()},
                "contact_id": contact_id, "k0": k0, **self._slave_scalars(slave)})
            k0 = n
        for ev in slave.events[e0:]:
            self.rec.log("/slave/estimates", ev.t_s, {"contact_id": contact_id, "t_s": ev.t_s,
                                                      "estimate": _estimate(ev.estimate)})
        self._slave_at = (contact_id, id(slave), k0, len(slave.events))

    @staticmethod
    def _slave_scalars(slave) -> dict:
        return {"object_ir_c": slave.object_ir_c, "object_true_c": slave.object_true_c,
                "pad_before_c": slave.pad_before_c, "gap_k": slave.gap_k}

    def slave(self, slave, contact_id: int = 0) -> None:
        """The contact's end: what is left of its samples and estimates, and
        its final values (``/slave/contact_end``)."""
        self.slave_stream(slave, contact_id, final=True)
        self.rec.log("/slave/contact_end", 0.0, {"contact_id": contact_id,
                                                 "samples": slave.samples_read,
                                                 **self._slave_scalars(slave)})
        self._slave_at = (None, None, 0, 0)

    def touch_end(self, summary: dict, trace: dict) -> None:
        self._flush_periods()
        clean = {k: v for k, v in summary.items() if k != "recording"}
        self.rec.log("/master/touch", 0.0, {"contact_id": self.contact_id,
                                            "summary": _plain(clean)})
        self.rec.log("/sim/trace", 0.0, {"contact_id": self.contact_id,
                                         "trace": {k: [_plain(x) for x in v]
                                                   for k, v in trace.items()}})

    def close(self, summary: dict | None = None, trace: dict | None = None) -> dict:
        if summary is not None:
            self.touch_end(summary, trace or {})
        self._flush_periods()
        return self.rec.close()

    def discard(self) -> None:
        """The service did not start: close and remove the file (a recording
        of nothing must not be listed beside the sessions that ran)."""
        self.rec.discard()


def _plain(value):
    """msgpack-safe: numpy scalars to Python, NaN kept."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value
