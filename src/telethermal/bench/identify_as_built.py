"""``telethermal bench identify --as-built SD``: the default identifier on
pads built off their datasheet (issue 44, deliverable 6).

``pads`` pads are drawn (``[as_built] sd = SD``, seeds 0, 1, ...: every
factor of the sensing pad log-normal). For each, the same touches (the
scene's pad database, one seed for every pad: only the pad differs) are
cross-validated (grouped, 5 folds) four ways:

- ``as_modelled``: the touches of the pad as designed (the product's model
  is the simulator's pad: every headline figure so far);
- ``uncalibrated``: the drawn pad's touches, the product's model the
  design's;
- ``uncalibrated_fallback``: the same, each fold's model with its
  model-free fallback (``effusivity-lda``, trained on the same touches: the
  slave's) naming the touches the pad-model check refuses;
- ``calibrated``: the drawn pad's touches, the product's model calibrated
  (``telethermal calibrate pad``) from reference touches of that pad on
  the reference materials (``references``: by default
  ``ident.calibration``'s, steel, plexiglass and wood),
  :data:`REFERENCE_TOUCHES` each (another seed: not the touches scored).

Each row: accuracy at 0.5 s and 1 s, the live decisions (named alone, pair,
unknown, wrong). The calibration's: each fitted parameter against the drawn
truth (whether its 95 % interval holds it: the coverage) and its CPU time.
"""

from __future__ import annotations

import time

import numpy as np

from telethermal.data.generate import pad_database, sensor_session
from telethermal.errors import BenchError
from telethermal.ident.calibration import (REFERENCE_TOUCHES, SD_MAX, reference_materials,
                                           reference_scene)
from telethermal.ident.crossval import cross_validate
from telethermal.physics.as_built import draw_as_built, with_as_built
from telethermal.physics.scene import load_scene

#: Seeds: the scored touches', and the reference touches' (another session).
TOUCH_SEED, REFERENCE_SEED = 0, 1000
METHOD = "effusivity-fit"
MISFIT = "pad model does not fit: recalibrate"


def _row(report: dict) -> dict:
    """The figures of one cross-validation that the issue's targets name."""
    d = report["decisions"]
    committed = d["committed"] or 0
    right = round((d["accuracy"] or 0.0) * committed)
    acc = report["accuracy_by_window_s"]
    return {"accuracy_0.5": acc.get("0.5"), "accuracy_1.0": acc.get("1"),
            "named_rate": d["named_rate"], "pair_rate": d["pair_rate"],
            "unknown_rate": d["unknown_rate"],
            "misfit_rate": (d["unknown_reasons"] or {}).get(MISFIT, 0) / d["touches"]
            if d["touches"] else None,
            "wrong_rate": (committed - right) / d["touches"] if d["touches"] else None,
            "fallback_rate": d.get("fallback_named", 0) / d["touches"] if d["touches"] else None,
            "touches": d["touches"]}


def truth_of(as_built, gain: float) -> dict:
    """Each calibration candidate's true factor on the drawn pad: a layer's
    resistance and heat capacity both scale with its thickness; the gain
    is the drawn factor times the reference session's instrument."""
    f = as_built.pad
    out = {"flux_lag_s": f.flux_lag_s, "flux_gain": f.flux_gain * gain}
    for i, k in enumerate(f.layer_thickness):
        out[f"layers[{i}].resistance"] = out[f"layers[{i}].heat_capacity"] = k
    return out


def references_of(scene, references=None) -> list[str]:
    """The reference materials of ``scene`` the calibrations touch
    (``ident.calibration.reference_materials``), a BenchError naming the
    one that is not the scene's."""
    try:
        return reference_materials(scene, references)
    except ValueError as exc:
        raise BenchError(f"--references: {exc}") from None


def reference_section(scene, references=None) -> dict:
    """A report's ``reference``: the materials and the touches of each."""
    return {"materials": references_of(scene, references), "touches_each": REFERENCE_TOUCHES}


def calibrate_drawn(scene, built, references=None) -> tuple:
    """(the calibration of ``built``'s pad from its reference touches on
    ``references`` (:func:`references_of`), CPU s, truth)."""
    from telethermal.ident.pad_calibration import calibrate_pad
    ref_scene = reference_scene(built, references_of(scene, references))
    trials = pad_database(ref_scene, np.random.default_rng(REFERENCE_SEED))
    gain = sensor_session(ref_scene, np.random.default_rng(REFERENCE_SEED)).instruments.flux_gain
    start = time.process_time()
    cal = calibrate_pad(scene, trials)
    return cal, time.process_time() - start, truth_of(built.as_built, gain)


def lumped_truth(scene, names, truth: dict) -> float:
    """The true factor of the quantity a parameter scales. One member: its
    truth. Lumped (layers' resistances together, or heat capacities
    together: ``ident/calibration.py`` lumps only one kind), the fit scales
    every member by one factor, so it scales the group's total ``sum x_i``
    (the layers in series: their resistance, their heat capacity) by it;
    the true factor of that total is ``sum x_i f_i / sum x_i``, the
    members' factors weighted by their design values ``x_i``
    (:func:`~telethermal.ident.calibration.lump_weights`: the calibration's
    intervals are for that total)."""
    from telethermal.ident.calibration import lump_weights
    return sum(w * truth[n] for w, n in zip(lump_weights(scene, names), names))


def coverage(cal, truth: dict, scene, prior_fitted: bool = False) -> list[dict]:
    """Each fitted parameter (``prior_fitted``: each part fitted under its
    design prior instead, which the coverage target does not count): its
    factor, interval, the true factor of what it scales
    (:func:`lumped_truth`; the members' own beside), held or not."""
    rows = []
    for p in (cal.prior_fitted if prior_fitted else cal.parameters):
        want = lumped_truth(scene, p.names, truth)
        rows.append({"names": list(p.names), "factor": p.factor, "lo": p.lo, "hi": p.hi,
                     "truth": want, "truths": [truth[n] for n in p.names],
                     "held": bool(p.lo <= want <= p.hi)})
    return rows


def run(sd: float = 0.15, pads: int = 5, scene_name: str = "fingertip-7", folds: int = 5,
        progress=None, partial=None, references=None) -> dict:
    """The ``as_built`` section of ``bench identify``'s report (see the
    module); ``references``: the calibrations' reference materials (None:
    the default set); ``partial(section)``: called after each pad with the section
    so far (a long run's figures kept as they come)."""
    step = progress or (lambda _m: None)
    # The design: a scene file's own [as_built] table is not the reference.
    scene = with_as_built(load_scene(scene_name), None)
    references = references_of(scene, references)          # refused before any touch
    step(f"as modelled: {folds} folds on {scene.name}")
    touches = list(pad_database(scene, np.random.default_rng(TOUCH_SEED)))
    out = {"sd": sd, "pads": pads, "scene": scene.name, "method": METHOD, "folds": folds,
           "reference": reference_section(scene, references),
           "as_modelled": _row(cross_validate(touches, METHOD, folds, scene=scene)),
           "uncalibrated": [], "uncalibrated_fallback": [], "calibrated": [],
           "calibrations": []}
    for k in range(pads):
        built = with_as_built(scene, draw_as_built(sd, k, len(scene.pad.layers)))
        drawn = list(pad_database(built, np.random.default_rng(TOUCH_SEED)))
        step(f"pad {k}: uncalibrated")
        out["uncalibrated"].append(_row(cross_validate(drawn, METHOD, folds, scene=scene)))
        step(f"pad {k}: uncalibrated, with the model-free fallback")
        out["uncalibrated_fallback"].append(_row(cross_validate(drawn, METHOD, folds,
                                                                scene=scene, fallback=True)))
        step(f"pad {k}: calibrating")
        cal, cpu_s, truth = calibrate_drawn(scene, built, references)
        out["calibrations"].append({"seed": k, "as_built": built.as_built.pad.to_dict(),
                                    "cpu_s": cpu_s, "chi2_per_dof": cal.chi2_per_dof,
                                    "parameters": coverage(cal, truth, scene),
                                    "not_identifiable": list(cal.not_identifiable),
                                    "prior_fitted": coverage(cal, truth, scene, True)})
        step(f"pad {k}: calibrated")
        out["calibrated"].append(_row(cross_validate(drawn, METHOD, folds, scene=scene,
                                                     calibration=cal)))
        out["summary"] = summary(out)
        if partial is not None:
            partial({**out, "pads_done": k + 1})
    return out


def summary(out: dict) -> dict:
    """Means over the drawn pads of each row's figures; the calibrations'
    coverage (parameters held / fitted) and CPU time."""
    def mean(rows, key):
        vals = [r[key] for r in rows if r.get(key) is not None]
        return float(np.mean(vals)) if vals else None
    keys = ("accuracy_0.5", "accuracy_1.0", "named_rate", "pair_rate", "unknown_rate",
            "misfit_rate", "wrong_rate", "fallback_rate")
    held = [p["held"] for c in out["calibrations"] for p in c["parameters"]]
    prior = [p["held"] for c in out["calibrations"] for p in c.get("prior_fitted", [])]
    return {"uncalibrated": {k: mean(out["uncalibrated"], k) for k in keys},
            "uncalibrated_fallback": {k: mean(out.get("uncalibrated_fallback", []), k)
                                      for k in keys},
            "calibrated": {k: mean(out["calibrated"], k) for k in keys},
            "as_modelled": {k: out["as_modelled"].get(k) for k in keys},
            "coverage": float(np.mean(held)) if held else None,
            "parameters_fitted": len(held),
            # The parts fitted under their design prior, apart (not the target's).
            "prior_fitted_coverage": float(np.mean(prior)) if prior else None,
            "prior_fitted": len(prior),
            "calibrate_cpu_s_max": max((c["cpu_s"] for c in out["calibrations"]), default=None)}


def references_line(out: dict) -> str:
    """An as-built report's reference touches, as its printout says them."""
    ref = out.get("reference") or {}
    return (f"  calibrated from {ref.get('touches_each', '?')} touches each of "
            f"{', '.join(ref.get('materials') or ['?'])}")


def text_lines(out: dict) -> list[str]:
    """What ``bench identify --as-built`` prints."""
    def pct(x):
        return "-" if x is None else f"{100 * x:.1f} %"
    s = out["summary"]
    done = out.get("pads_done", out["pads"])
    lines = [f"pads built off their datasheet: "
             + (f"{out['pads']}" if done == out["pads"] else f"{done} of {out['pads']}")
             + f" drawn at sd {out['sd']:g} "
             f"({out['method']}, {out['folds']} folds, mean over the pads)",
             references_line(out)]
    for key in ("as_modelled", "uncalibrated", "uncalibrated_fallback", "calibrated"):
        r = s[key]
        lines.append(f"  {key:13s} 0.5 s {pct(r['accuracy_0.5'])}, 1 s {pct(r['accuracy_1.0'])};"
                     f" named {pct(r['named_rate'])}, pair {pct(r['pair_rate'])}, unknown "
                     f"{pct(r['unknown_rate'])} (misfit {pct(r['misfit_rate'])}), wrong "
                     f"{pct(r['wrong_rate'])}, by the fallback {pct(r['fallback_rate'])}")
    # Those whose interval, what the touches cannot tell included, is still
    # within the identifiability rule's sd (the others are fitted, not known).
    from telethermal.ident.pad_calibration import interval_sd
    sharp = [p["held"] for c in out["calibrations"] for p in c["parameters"]
             if interval_sd(p["lo"], p["hi"]) <= SD_MAX]
    lines.append(f"  calibration: {pct(s['coverage'])} of {s['parameters_fitted']} fitted "
                 f"parameters within their 95 % interval ({sum(sharp)} of the {len(sharp)} "
                 f"whose interval sd is within {SD_MAX:g}); CPU up to "
                 f"{s['calibrate_cpu_s_max']:.0f} s per pad")
    # From the calibrations, not the summary: a JSON made before the
    # summary counted them has them there too.
    prior = [p["held"] for c in out["calibrations"] for p in c.get("prior_fitted", [])]
    if prior:
        lines.append(f"  fitted under their design prior (not identifiable alone): "
                     f"{sum(prior)} of {len(prior)} within their 95 % interval")
    return lines
