"""``bench render``'s sessions: one row per in-process session, a run's
totals pooled from its rows, and a sweep's job (:mod:`telethermal.bench.executor`)
that makes a row in whichever process runs it, the models loaded from their
files once per process."""

from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np

from telethermal.control.pid import PidGains
from telethermal.sim.inprocess import run_session
from telethermal.teleop.display_setup import add_limits, new_limit_totals
from telethermal.teleop.display_config import JUNCTION_REARMED, JUNCTION_STOPPED, DisplayConfig

CONTACT_S = 3.0
KEYS = ("flux_rms_error_rel", "flux_rms_error_rel_first_s", "temp_rms_error_c",
        "time_to_correct_flux_s", "safety_events", "flux_rms_error_rel_whole")
#: A session's module summary keys ``add_limits`` reads (kept in each row).
_LIMIT_KEYS = ("current_exceeded", "hot_side_exceeded", "reversals", "contact_s",
               "ripple_rms_a", "requested")


def mean_of(rows: list[dict], key: str) -> float | None:
    """The mean of ``key`` over ``rows``, its missing and non-finite values
    left out (None: none left)."""
    vals = [r[key] for r in rows if r[key] is not None and np.isfinite(r[key])]
    return float(np.mean(vals)) if vals else None


class Totals:
    """One run's pools, nothing carried to the next: every session's module
    limits, counted on the controller's request before any clamp
    (``limits_all_sessions``; ``limits`` is the shipped display's alone), and
    the pad's idle against the room's dew point (simulated-clock sessions)."""

    def __init__(self):
        self.limits = new_limit_totals()
        self.dew = {"sessions": 0, "min_idle_minus_dew_k": float("inf")}

    def add(self, row: dict) -> None:
        """One session's row."""
        add_limits(self.limits, row["module_limits"])
        # The pad's true surface with nothing on it, not the clamped command.
        idle_minus_dew_k = row["idle_surface_minus_dew_k"]
        if idle_minus_dew_k is not None:
            self.dew["sessions"] += 1
            self.dew["min_idle_minus_dew_k"] = min(self.dew["min_idle_minus_dew_k"],
                                                   idle_minus_dew_k)


def session_row(scene, material, identifier, generator, config, seed,
                expected_material=None, display_calibration=None,
                totals: Totals | None = None, contact_s: float | None = None,
                display_model: dict | None = None, idle_scene=None) -> dict:
    """One session's row; added to ``totals`` if given. ``display_model``
    and ``idle_scene``: as :func:`~telethermal.sim.inprocess.run_session`'s."""
    contact_s = CONTACT_S if contact_s is None else contact_s
    start = time.process_time()
    # The pad idles by config.idle (control/preconditioning.py): by default a
    # repeated touch (the material known from memory) is pre-conditioned for
    # it, a first touch idles at the policy's choice for an unknown object.
    s = run_session(scene, material, identifier, generator, config, contact_s=contact_s,
                    seed=seed, expected_material=expected_material, fresh_fits=True,
                    display_calibration=display_calibration, display_model=display_model,
                    idle_scene=idle_scene).summary
    cpu = time.process_time() - start
    module = s["module"]
    row = {"material": material, "seed": seed, "identified": s["identified"],
           **{k: s[k] for k in KEYS}, "decision_from_s": s["decision_from_s"],
           "display_idle_c": s["display_idle_c"], "object_ir_c": s["object_ir_c"],
           "heat_extraction_ratio_first_s": s["heat_extraction_ratio_first_s"],
           "skin_above_threshold_s": s["skin_above_threshold_s"],
           "module_max_current_a": module["max_current_a"],
           "module_saturated_periods": module["saturated_periods"],
           "module_reversals_per_s": module["reversals_per_s"],
           "module_ripple_rms_a": module["ripple_rms_a"],
           "module_largest_request_a": (module["requested"] or {}).get("largest_request_a"),
           "module_limits": {k: module[k] for k in _LIMIT_KEYS},
           "idle_surface_minus_dew_k": s["idle_surface_minus_dew_k"],
           "junction_stops": s["display_event_counts"].get(JUNCTION_STOPPED, 0),
           "junction_rearms": s["display_event_counts"].get(JUNCTION_REARMED, 0),
           "cpu_s_per_simulated_s": cpu / (contact_s + 0.4)}
    if totals is not None:
        totals.add(row)
    return row


def config_fields(config: DisplayConfig) -> dict:
    """What a bench varies of a display config, as JSON (:func:`display_config`
    reads it back); a ValueError for a config that differs elsewhere (it
    would not cross to a worker whole)."""
    fields = {"rate_hz": config.rate_hz, "gains": dataclasses.asdict(config.gains),
              "feedforward_model": str(config.feedforward_model),
              "before": str(config.before), "idle": str(config.idle),
              "r_pad_belief": config.r_pad_belief}
    if display_config(fields) != config:
        raise ValueError(f"a display config a sweep cannot carry: {config}")
    return fields


def display_config(fields: dict) -> DisplayConfig:
    return DisplayConfig(**{**fields, "gains": PidGains(**fields["gains"])})


@functools.lru_cache(maxsize=4)
def _models(scene_ref: str, identifier_path: str, generator_path: str):
    """A worker's scene and models, loaded once per process."""
    from telethermal.ident.registry import load_model
    from telethermal.physics.scene import load_scene, with_finger
    from telethermal.render.generator import load_generator

    return (with_finger(load_scene(scene_ref)), load_model(identifier_path),
            load_generator(generator_path))


#: The worlds whose untimed first session this process has run.
_WARM: set = set()


def session_job(job: dict, material: str, seed: int, config: dict,
                expected_material: str | None) -> dict:
    """A sweep's job: :func:`session_row` on the scene and model files
    ``job`` names (``config``: :func:`config_fields`). A process's first
    session on them is run once untimed before it: a fresh worker's first
    session pays its imports and caches (over twice a warm one's CPU), which
    would count in its row's ``cpu_s_per_simulated_s`` and in no other's."""
    scene, identifier, generator = _models(job["scene"], job["identifier"], job["generator"])
    key = (job["scene"], job["identifier"], job["generator"])
    if key not in _WARM:
        _WARM.add(key)
        session_row(scene, material, identifier, generator, display_config(config), seed,
                    expected_material, contact_s=job["contact_s"])
    return session_row(scene, material, identifier, generator, display_config(config), seed,
                       expected_material, contact_s=job["contact_s"])
