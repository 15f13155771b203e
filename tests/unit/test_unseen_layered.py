"""Issue 30's hard case: "a thin object on a metal base (a layered object:
the estimate drifts with time)". The shipped unseen scene's layered object
(a 1 mm glass slide on an aluminium block) touched by fingertip-7's pad,
and the very same touches (the same draws: one object per scene, the same
session seed) of a plain glass slab 30 mm thick.

The physics says what to expect, with no figure of a run in it: the base is
felt once heat has crossed the layer; for a held surface the flux's
correction is ``2 (-g)^n exp(-n^2 L^2 / (alpha t))``
(``tests/unit/test_layered_closed_form.py``), with ``L^2 / alpha`` = 1.34 s
for this slide: at 0.1 s, ``2 |g| exp(-13.4)`` = 2.6e-6 of the flux, so the
slide is glass to the estimator (the two simulations differ by their grids'
spatial error, 1e-3 of the flux each, far inside the estimate's own
uncertainty); at 1 s, 2 |g| exp(-1.34) = 45 % more flux than glass's for a
held surface: the estimate must have left glass for aluminium by more than
its intervals. The tolerance "indistinguishable" is a tenth of the early
estimate's own 95 % half-width (the estimate's scale, not a run's figure).
"""

import dataclasses

import numpy as np
import pytest

from telethermal.bench import unseen, unseen_layered
from telethermal.data.generate import pad_database
from telethermal.ident.curvecache import cached_family
from telethermal.ident.effusivity import EffusivityEstimator
from telethermal.ident.prepare import from_trials
from telethermal.physics.scene import load_scene

EARLY_S, LATE_S = 0.1, 1.0
TOUCHES = 3
BASE = load_scene("fingertip-7")


def layered_object():
    objs = [o for o in unseen.scene_objects(unseen.default_unseen_scene_path(), BASE.materials)
            if o.layered]
    assert len(objs) == 1, "the shipped unseen scene holds one layered object"
    return dataclasses.replace(objs[0], temp_c=BASE.objects[0].temp_c)


def touch_scene(obj):
    """fingertip-7's pad with ``obj`` alone, :data:`TOUCHES` touches of 1 s."""
    scene = unseen.touch_scene(dataclasses.replace(BASE, objects=()), [obj])
    return dataclasses.replace(scene, pad=dataclasses.replace(
        scene.pad, trials_per_material=TOUCHES, contact_duration_s=LATE_S))


def estimates(estimator, scene, seed=5):
    contacts, _ = from_trials(pad_database(scene, np.random.default_rng(seed)), max_s=LATE_S)
    return {w: estimator.estimate_contacts(contacts, w) for w in (EARLY_S, LATE_S)}


@pytest.fixture(scope="module")
def touched():
    slide = layered_object()
    glass = unseen.package_objects(["glass"], BASE.materials, slide.temp_c, 0.03)[0]
    scene = touch_scene(slide)
    est = EffusivityEstimator.for_scene(scene, max_s=LATE_S, n_e=21, n_h=5, n_prior=300,
                                        n_sessions=5, family=cached_family)
    return slide, estimates(est, scene), estimates(est, touch_scene(glass))


def test_the_shipped_layered_object_is_a_thin_glass_on_aluminium():
    obj = layered_object()
    assert obj.name == "glass-slide-on-aluminium"
    assert [(la.material.name, la.thickness_m) for la in obj.layers()] == [
        ("glass", 1e-3), ("aluminium", 0.03)]


def test_early_the_estimate_is_the_surface_materials(touched):
    _slide, layered, glass = touched
    for lay, slab in zip(layered[EARLY_S], glass[EARLY_S]):
        half = 0.5 * np.log(lay.interval_w_s05_m2k[1] / lay.interval_w_s05_m2k[0])
        assert abs(np.log(lay.effusivity_w_s05_m2k / slab.effusivity_w_s05_m2k)) < 0.1 * half
        assert lay.fits == slab.fits


def test_by_the_last_window_it_moved_toward_the_base_beyond_the_intervals(touched):
    slide, layered, glass = touched
    aluminium = slide.layers()[1].material.effusivity
    for early, late, slab in zip(layered[EARLY_S], layered[LATE_S], glass[LATE_S]):
        assert late.interval_w_s05_m2k[0] > early.interval_w_s05_m2k[1]    # up, past both
        assert late.interval_w_s05_m2k[0] > slab.interval_w_s05_m2k[1]     # past glass's own
        assert late.effusivity_w_s05_m2k < aluminium                      # not yet the base
    rows = [{"windows": {EARLY_S: a, LATE_S: b}} for a, b in zip(layered[EARLY_S],
                                                               layered[LATE_S])]
    drift = unseen_layered.drift(rows, EARLY_S, LATE_S, aluminium)
    assert drift["toward_base_beyond_intervals"] == drift["n"] == TOUCHES
    assert drift["ratio_min"] > 1.0


# ------------------------------------------------- the bench's figures for it
def _estimate(e, half_rel=0.05, fits=True):
    from telethermal.ident.effusivity import EffusivityEstimate
    return EffusivityEstimate(e, (e * (1 - half_rel), e * (1 + half_rel)), 0.01, 0.5, 51,
                              3000.0, -0.005, 1.0, fits, False, (np.log(e), 0.0, -0.005))


def _rows(late_factors, early=1620.0):
    """Touches whose estimate is ``early`` until the last window, then
    ``early * f``."""
    return [{"windows": {w: _estimate(early * (f if w == unseen.WINDOWS_S[-1] else 1.0))
                         for w in unseen.WINDOWS_S}} for f in late_factors]


def test_the_bench_reports_a_layered_object_by_its_stack_and_drift_not_its_error():
    slide = layered_object()
    rows = _rows([1.5, 1.06, 0.8])          # beyond its intervals up; overlapping; down
    out = unseen.material_summary(slide.name, rows, BASE.materials, slide)
    assert out["layered"] and out["effusivity_w_s05_m2k"] is None
    assert [la["material"] for la in out["stack"]] == ["glass", "aluminium"]
    assert out["surface_effusivity_w_s05_m2k"] == pytest.approx(1620, rel=1e-3)
    assert out["estimate_p50_w_s05_m2k"]["0.1"] == pytest.approx(1620.0)
    assert out["estimate_p50_w_s05_m2k"]["1"] == pytest.approx(1620.0 * 1.06)
    d = out["drift"]
    assert (d["n"], d["toward_base"], d["intervals_disjoint"],
            d["toward_base_beyond_intervals"]) == (3, 2, 2, 1)
    assert out["effusivity_rel_error"].startswith("not_applicable")
    assert out["interval_coverage"].startswith("not_applicable")
    # left out of the targets and the pooled coverage, and said so
    glass = unseen.material_summary("glass", _rows([1.0] * 2), BASE.materials)
    targets = unseen._targets({slide.name: out, "glass": glass})
    assert targets["coverage_by_window"]["1"]["n"] == 2
    assert slide.name not in targets["unseen_rel_error_within_10pct_by_0.5_s"]
    assert targets["left_out_layered"]["objects"] == [slide.name]
    line = unseen_layered.section_line(slide.name, out, ["0.1", "1"])
    assert "glass 1 mm (e 1620) on aluminium 30 mm (e 20100)" in line
    assert "median estimate 1,620 / 1,717" in line
    assert "1 of 3 toward the base beyond the intervals" in line


def test_its_rendering_is_not_judged_against_an_oracle_it_has_not():
    from telethermal.bench import unseen_render as ur
    modes = {"estimate": {k: 0.02 for k in ur.KEYS}, "closed_set": {k: 0.021 for k in ur.KEYS}}
    for m in modes.values():
        m["safety_events"] = 0
    row = {"material": "x", "seed": 0, "identified": "new material", "oracle": None,
           "oracle_not_run": unseen_layered.ORACLE_NOT_RUN, **modes}
    summary = ur.summarise([row])
    assert summary["flux_rms_rel"]["oracle"] is None
    assert summary["rendered"]["oracle_not_run"].startswith("not_run")
    material = {"trained": False, "layered": True, **summary}
    verdict = ur.targets({"x": material})["unseen"]["x"]["flux_rms_rel"]
    assert verdict["not_judged"].startswith("not_run") and "met" not in verdict
