"""``telethermal bench unseen --as-built SD``: the unseen materials'
effusivity on pads built off their datasheet (issue 44, deliverable 6).

``pads`` pads are drawn (``[as_built] sd = SD``, seeds 0, 1, ...: every
factor of the sensing pad log-normal), as ``bench identify --as-built``
draws them. For each, the default identifier (``effusivity-fit``) is
trained on that pad's own touches of the trained materials (session
:data:`~telethermal.bench.unseen.TRAIN_SEED`: a lab trains on its own pad)
and estimates the effusivity of every touch, trained and unseen, of
``seeds`` sessions on the same pad, three ways:

- ``as_modelled``: the pad as designed (the product's model is the
  simulator's pad: ``bench unseen``'s own figures);
- ``uncalibrated``: the drawn pad's touches, the product's model the
  design's;
- ``calibrated``: the drawn pad's touches, the model calibrated from
  reference touches of that pad (``telethermal calibrate pad``, as
  :func:`~telethermal.bench.identify_as_built.calibrate_drawn`: steel,
  plexiglass and wood unless ``references`` names others, 5 touches
  each, another session).

Per row: each unseen material's median relative error at 0.5 s (the issue's
10 % target) and the pooled coverage of the 95 % intervals over the unseen
(its 90-98 % target), with the estimator's own scoring
(:func:`~telethermal.bench.unseen.material_summary`). No rendering and no
decisions: those are ``bench unseen``'s and ``bench identify --as-built``'s.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from telethermal.bench import identify_as_built as iab
from telethermal.bench import unseen as un
from telethermal.physics.as_built import draw_as_built, with_as_built
from telethermal.physics.scene import load_scene

KEY = f"{un.TARGET_WINDOW_S:g}"


def train(model_scene, built, calibration, quick: bool):
    """``effusivity-fit`` with ``model_scene``'s pad model (``calibration``
    applied, if any) trained on ``built``'s own touches of session
    :data:`~telethermal.bench.unseen.TRAIN_SEED`."""
    from telethermal.data.generate import pad_database
    from telethermal.ident.prepare import from_trials
    from telethermal.ident.registry import make

    scene = dataclasses.replace(built, pad=dataclasses.replace(
        built.pad, trials_per_material=3)) if quick else built
    contacts, _ = from_trials(pad_database(scene, np.random.default_rng(un.TRAIN_SEED)),
                              max_s=max(un.WINDOWS_S))
    return make("effusivity-fit", scene=model_scene, calibration=calibration,
                max_window_s=max(un.WINDOWS_S)).fit(contacts)


def score(model_scene, built, calibration, objects, seeds: int, quick: bool) -> dict:
    """One row: the unseen materials' median error at 0.5 s and the pooled
    coverage of their 95 % intervals (and the trained materials' beside)."""
    from telethermal.data.generate import pad_database
    from telethermal.ident.prepare import from_trials

    identifier = train(model_scene, built, calibration, quick)
    touched = un.touch_scene(built, objects)
    if quick:
        touched = dataclasses.replace(touched, pad=dataclasses.replace(
            touched.pad, trials_per_material=3))
    rows = []
    for seed in range(seeds):
        contacts, _ = from_trials(pad_database(touched, np.random.default_rng(seed)),
                                  max_s=max(un.WINDOWS_S))
        rows += un.estimates(identifier, contacts, set())
    trained = model_scene.materials
    materials = {m: un.material_summary(m, [r for r in rows if r["material"] == m], trained,
                                         touched.object_named(m))
                 for m in dict.fromkeys(r["material"] for r in rows)}
    single = {m: r for m, r in materials.items() if not r.get("layered")}
    unseen = {m: r for m, r in single.items() if not r["trained"]}
    return {"unseen_rel_error_0.5": {m: r["effusivity_rel_error"][KEY] for m, r in unseen.items()},
            "unseen_coverage_0.5": un.pooled_coverage(unseen, KEY),
            "trained_rel_error_0.5": {m: r["effusivity_rel_error"][KEY]
                                      for m, r in single.items() if r["trained"]},
            "coverage_0.5": un.pooled_coverage(single, KEY),
            "touches": len(rows)}


def run(sd: float = 0.15, pads: int = 5, seeds: int = 1, scene_name: str = "fingertip-7",
        quick: bool = False, progress=None, partial=None, references=None) -> dict:
    """The ``as_built`` section of ``bench unseen``'s report (see the
    module); ``references``: the calibrations' reference materials (None:
    the default set); ``partial(section)`` is called after each pad."""
    step = progress or (lambda _m: None)
    # The design: a scene file's own [as_built] table is not the reference.
    base = with_as_built(load_scene(scene_name), None)
    objects, _ = un.unseen_objects(base)
    references = iab.references_of(base, references)       # refused before any touch
    step("as modelled")
    out = {"sd": sd, "pads": pads, "seeds": list(range(seeds)), "scene": base.name,
           "quick": quick, "method": "effusivity-fit", "window_s": un.TARGET_WINDOW_S,
           "unseen": [o.name for o in objects],
           "targets": {"median_rel_error_max": un.TARGET_REL_ERROR,
                       "coverage": list(un.TARGET_COVERAGE)},
           "reference": iab.reference_section(base, references),
           "as_modelled": score(base, base, None, objects, seeds, quick),
           "uncalibrated": [], "calibrated": [], "calibrations": []}
    for k in range(pads):
        built = with_as_built(base, draw_as_built(sd, k, len(base.pad.layers)))
        step(f"pad {k}: uncalibrated")
        out["uncalibrated"].append(score(base, built, None, objects, seeds, quick))
        step(f"pad {k}: calibrating")
        cal, cpu_s, truth = iab.calibrate_drawn(base, built, references)
        out["calibrations"].append({"seed": k, "as_built": built.as_built.pad.to_dict(),
                                    "cpu_s": cpu_s, "chi2_per_dof": cal.chi2_per_dof,
                                    "parameters": iab.coverage(cal, truth, base),
                                    "prior_fitted": iab.coverage(cal, truth, base, True)})
        out["calibrated"].append(score(base, built, cal, objects, seeds, quick))
        out["summary"] = summary(out)
        if partial is not None:
            partial({**out, "pads_done": k + 1})
    out["summary"] = summary(out)
    return out


def summary(out: dict) -> dict:
    """Per way: the median over pads of each unseen material's error, the
    worst material's, and the coverage pooled over every pad's touches."""
    def way(rows: list[dict]) -> dict:
        if not rows:
            return {}
        names = list(rows[0]["unseen_rel_error_0.5"])
        errs = {m: float(np.median([r["unseen_rel_error_0.5"][m] for r in rows]))
                for m in names}
        hit = sum(r["unseen_coverage_0.5"]["covered"] for r in rows)
        n = sum(r["unseen_coverage_0.5"]["n"] for r in rows)
        return {"unseen_rel_error_0.5": errs, "worst_rel_error_0.5": max(errs.values()),
                "worst_material": max(errs, key=errs.get),
                "within_10pct": all(e <= un.TARGET_REL_ERROR for e in errs.values()),
                "unseen_coverage_0.5": hit / n if n else None, "n": n}
    return {"as_modelled": way([out["as_modelled"]]), "uncalibrated": way(out["uncalibrated"]),
            "calibrated": way(out["calibrated"])}


def text_lines(out: dict) -> list[str]:
    """What ``bench unseen --as-built`` prints."""
    s = out["summary"]
    done = out.get("pads_done", out["pads"])
    lines = [f"unseen materials on pads built off their datasheet: "
             + (f"{out['pads']}" if done == out["pads"] else f"{done} of {out['pads']}")
             + " drawn at sd "
             f"{out['sd']:g}, {len(out['seeds'])} session(s) each ({out['method']}, "
             f"{out['window_s']:g} s; targets: median error <= "
             f"{100 * out['targets']['median_rel_error_max']:.0f} %, coverage "
             f"{100 * out['targets']['coverage'][0]:.0f}-"
             f"{100 * out['targets']['coverage'][1]:.0f} %)",
             iab.references_line(out)]
    for key in ("as_modelled", "uncalibrated", "calibrated"):
        r = s.get(key) or {}
        if not r:
            continue
        lines.append(f"  {key:13s} worst median error {100 * r['worst_rel_error_0.5']:.1f} % "
                     f"({r['worst_material']}), coverage "
                     f"{100 * r['unseen_coverage_0.5']:.1f} % of {r['n']} touches")
    cal = out.get("calibrated") or []
    if cal:
        # The worst material's error pad by pad: one pad off, or all.
        worst = s["calibrated"]["worst_material"]
        lines.append(f"  calibrated {worst} pad by pad: " + ", ".join(
            f"{100 * r['unseen_rel_error_0.5'][worst]:.1f} %" for r in cal))
    return lines
