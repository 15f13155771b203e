"""bench identify --as-built: the truth a calibration is scored against,
the coverage and the summary (the run itself is the bench's)."""

from __future__ import annotations

import pytest

from telethermal.bench.identify_as_built import coverage, summary, text_lines, truth_of
from telethermal.ident.pad_calibration import CalibratedParameter, PadCalibration
from telethermal.physics.as_built import draw_as_built


def test_the_truth_of_a_drawn_pad():
    ab = draw_as_built(0.15, 3, 3)
    truth = truth_of(ab, 1.01)
    # A layer's thickness scales its resistance and its heat capacity alike
    # (its conductivity and volumetric heat unchanged).
    assert truth["layers[1].resistance"] == truth["layers[1].heat_capacity"] == \
        ab.pad.layer_thickness[1]
    assert truth["flux_gain"] == pytest.approx(ab.pad.flux_gain * 1.01)
    assert truth["flux_lag_s"] == ab.pad.flux_lag_s


def _cal(params):
    return PadCalibration("s", "d", tuple(CalibratedParameter(*p) for p in params), (),
                          3000.0, 1.0, 0.01, 0.1, 15, ("steel", "wood"))


def test_coverage_scores_a_lumped_parameter_against_its_groups_total():
    """A lumped parameter scales its members' total by its factor: scored
    against the true factor of that total (the members' factors weighted by
    their design values), not its first member's. fingertip-7's film and
    alumina: the factors 1.2 and 1.5 on their heat capacities C0, C2 make
    the total (1.2 C0 + 1.5 C2) / (C0 + C2) times its design value."""
    from telethermal.physics.scene import load_scene
    scene = load_scene("fingertip-7")
    c = [lay.thickness_m * lay.material.volumetric_heat_j_m3k for lay in scene.pad.layers]
    total = (1.2 * c[0] + 1.5 * c[2]) / (c[0] + c[2])
    assert 1.21 < total < 1.49                   # strictly between the members' 1.2 and 1.5
    truth = {"flux_lag_s": 1.1, "layers[0].heat_capacity": 1.2, "layers[2].heat_capacity": 1.5}
    lumped = ("layers[0].heat_capacity", "layers[2].heat_capacity")
    rows = coverage(_cal([(("flux_lag_s",), "lag", 1.09, 1.05, 1.12),
                          (lumped, "R", total, total - 0.005, total + 0.005)]), truth, scene)
    assert [r["held"] for r in rows] == [True, True] and rows[1]["truths"] == [1.2, 1.5]
    assert rows[1]["truth"] == pytest.approx(total, rel=1e-12)
    # An interval round the first member's truth alone does not hold it.
    rows = coverage(_cal([(lumped, "R", 1.2, 1.19, 1.21)]), truth, scene)
    assert rows[0]["held"] is (1.19 <= total <= 1.21) is False
    rows = coverage(_cal([(("flux_lag_s",), "lag", 1.2, 1.15, 1.25)]), truth, scene)
    assert rows[0]["held"] is False


def test_summary_means_over_the_pads_and_prints_them():
    row = {"accuracy_0.5": 1.0, "accuracy_1.0": 1.0, "named_rate": 0.9, "pair_rate": 0.0,
           "unknown_rate": 0.1, "misfit_rate": 0.05, "wrong_rate": 0.0, "touches": 70}
    other = {**row, "named_rate": 0.7, "unknown_rate": 0.3}
    out = {"sd": 0.15, "pads": 2, "method": "effusivity-fit", "folds": 5, "as_modelled": row,
           "uncalibrated": [row, other], "calibrated": [row, row],
           "calibrations": [{"cpu_s": 20.0, "parameters": [
               {"held": True, "lo": 0.98, "hi": 1.02}, {"held": False, "lo": 0.9, "hi": 1.1}]},
               {"cpu_s": 30.0, "parameters": [{"held": True, "lo": 0.7, "hi": 1.4}]}]}
    s = summary(out)
    assert s["uncalibrated"]["named_rate"] == pytest.approx(0.8)
    assert s["coverage"] == pytest.approx(2 / 3) and s["calibrate_cpu_s_max"] == 30.0
    out["summary"] = s
    text = "\n".join(text_lines(out))
    assert "uncalibrated" in text and "named 80.0 %" in text and "66.7 % of 3" in text
    # [0.7, 1.4] is an sd of 0.18 in ln factor: past the identifiability rule's 0.1.
    assert "(1 of the 2 whose interval sd is within 0.1)" in text
    assert "design prior" not in text and s["prior_fitted"] == 0
    # The parts fitted under their design prior are counted apart, never in
    # the identified parameters' coverage.
    out["calibrations"][0]["prior_fitted"] = [{"held": True, "lo": 0.7, "hi": 1.5},
                                              {"held": False, "lo": 0.7, "hi": 1.5}]
    s = summary(out)
    assert s["coverage"] == pytest.approx(2 / 3) and s["parameters_fitted"] == 3
    assert s["prior_fitted"] == 2 and s["prior_fitted_coverage"] == pytest.approx(0.5)
    out["summary"] = s
    assert "fitted under their design prior (not identifiable alone): 1 of 2 within" in \
        "\n".join(text_lines(out))


def _unseen_row(errors: dict, covered: int, n: int) -> dict:
    return {"unseen_rel_error_0.5": errors, "unseen_coverage_0.5": {"covered": covered, "n": n}}


def test_unseen_as_built_summary_takes_each_materials_median_over_pads_and_pools_coverage():
    from telethermal.bench import unseen_as_built as ua

    out = {"sd": 0.15, "pads": 3, "seeds": [0], "method": "effusivity-fit", "window_s": 0.5,
           "targets": {"median_rel_error_max": 0.10, "coverage": [0.9, 0.98]},
           "as_modelled": _unseen_row({"copper": 0.05, "glass": 0.02}, 19, 20),
           "uncalibrated": [_unseen_row({"copper": 0.5, "glass": 0.1}, 10, 20),
                            _unseen_row({"copper": 0.3, "glass": 0.2}, 12, 20),
                            _unseen_row({"copper": 0.4, "glass": 0.05}, 14, 20)],
           "calibrated": [_unseen_row({"copper": 0.06, "glass": 0.12}, 18, 20),
                          _unseen_row({"copper": 0.08, "glass": 0.01}, 19, 20),
                          _unseen_row({"copper": 0.04, "glass": 0.03}, 20, 20)]}
    s = ua.summary(out)
    # Medians over the pads: copper (0.5, 0.3, 0.4) -> 0.4, glass -> 0.1.
    assert s["uncalibrated"]["unseen_rel_error_0.5"] == {"copper": 0.4, "glass": 0.1}
    assert s["uncalibrated"]["worst_material"] == "copper"
    assert not s["uncalibrated"]["within_10pct"]
    # Calibrated: copper 0.06, glass 0.03 (one pad's 12 % is not the median).
    assert s["calibrated"]["worst_rel_error_0.5"] == pytest.approx(0.06)
    assert s["calibrated"]["within_10pct"]
    assert s["calibrated"]["unseen_coverage_0.5"] == pytest.approx(57 / 60)
    assert s["as_modelled"]["unseen_coverage_0.5"] == pytest.approx(0.95)
    out["summary"] = s
    text = "\n".join(ua.text_lines(out))
    assert "uncalibrated  worst median error 40.0 % (copper), coverage 60.0 % of 60" in text


def test_unseen_as_built_refuses_a_custom_unseen_set(capsys):
    from telethermal.cli import main

    assert main(["bench", "unseen", "--as-built", "0.15", "--unseen", "copper",
                 "--json", "x.json"]) != 0
    assert "--unseen and --unseen-scene are for the pad as modelled" in capsys.readouterr().err


def _render_pad(seed: int, skins: dict, identified: dict | None = None,
                over_imax: int = 0) -> dict:
    """One drawn pad's first touches: ``skins[material]`` the seeds' skin
    errors; ``over_imax`` periods requested over Imax in each session."""
    from telethermal.bench.render_as_built import _per_material
    limits = {"current_exceeded": 0, "hot_side_exceeded": 0, "reversals": 3, "contact_s": 3.0,
              "ripple_rms_a": 0.2, "requested": {"requested_over_imax_periods": over_imax,
                                                 "largest_request_a": 7.0 + over_imax}}
    rows = [{"material": m, "seed": s, "temp_rms_error_c": v, "flux_rms_error_rel": 0.02,
             "identified": (identified or {}).get(m, m), "safety_events": 0,
             "module_limits": limits}
            for m, vals in skins.items() for s, v in enumerate(vals)]
    return {"seed": seed, "rows": rows, "per_material": _per_material(rows)}


def test_render_as_built_summary_sets_each_materials_calibrated_mean_against_as_modelled():
    from telethermal.bench import render_as_built as ra

    modelled = _render_pad(0, {"aluminium": [0.6, 0.8], "wood": [0.7, 0.9]})
    out = {"sd": 0.15, "pads": 2, "seeds": [1, 2],
           "as_modelled": {"rows": modelled["rows"], "per_material": modelled["per_material"]},
           "uncalibrated": [_render_pad(0, {"aluminium": [1.0, 1.2], "wood": [0.8, 1.0]},
                                        {"wood": "plexiglass"}),
                            _render_pad(1, {"aluminium": [0.9, 0.9], "wood": [0.8, 0.8]},
                                        over_imax=5)],
           "calibrated": [_render_pad(0, {"aluminium": [0.7, 0.8], "wood": [0.9, 1.1]}),
                          _render_pad(1, {"aluminium": [0.7, 0.7], "wood": [0.9, 0.9]})],
           "calibrations": []}
    s = ra.summary(out)
    al, wood = s["per_material"]["aluminium"], s["per_material"]["wood"]
    # Aluminium: as modelled 0.7 K; calibrated (0.75 + 0.7) / 2 = 0.725 K: 1.036x.
    assert al["calibrated_ratio"] == pytest.approx(0.725 / 0.7) and al["met"]
    # Wood: as modelled 0.8 K; calibrated (1.0 + 0.9) / 2 = 0.95 K: 1.1875x, over 1.15.
    assert wood["calibrated_ratio"] == pytest.approx(0.95 / 0.8) and not wood["met"]
    assert wood["calibrated_skin_rms_max_k"] == pytest.approx(1.1)
    assert s["worst_material"] == "wood" and not s["met"]
    # The first pad named wood as plexiglass on both uncalibrated seeds.
    assert wood["uncalibrated_identified_right"] == 2 and wood["calibrated_identified_right"] == 4
    # Limits pooled over the pads: the second uncalibrated pad's 4 sessions
    # asked past Imax for 5 periods each.
    lim = s["limits"]["uncalibrated"]
    assert lim["current_requested_over_imax_periods"] == 20 and lim["largest_request_a"] == 12.0
    assert s["limits"]["calibrated"]["current_requested_over_imax_periods"] == 0
    assert lim["reversals_per_s"] == pytest.approx(1.0)     # 3 in each 3 s contact
    # Each pad's own mean: wood's first pad 1.0 K, 1.25x as modelled.
    assert wood["calibrated_worst_pad_ratio"] == pytest.approx(1.25)
    out["summary"] = s
    text = "\n".join(ra.text_lines(out))
    assert "worst: wood 1.19x" in text and "target missed" in text
    assert "(over the target)" in text and "(worst pad 1.25x)" in text


def test_render_as_built_is_missed_on_a_safety_event_and_says_a_refused_calibration():
    from telethermal.bench import render_as_built as ra

    modelled = _render_pad(0, {"aluminium": [0.7, 0.7]})
    fine = _render_pad(0, {"aluminium": [0.7, 0.72]})
    out = {"sd": 0.15, "pads": 2, "seeds": [1, 2],
           "as_modelled": {"rows": modelled["rows"], "per_material": modelled["per_material"]},
           "uncalibrated": [fine, fine], "calibrated": [fine],
           "calibrations": [{"seed": 0}, {"seed": 1, "refused": "chi2/dof 9 past 2"}]}
    s = ra.summary(out)
    assert s["met"] and s["calibration_refused_pads"] == [1]
    assert s["sessions"] == {"as_modelled": 2, "uncalibrated": 4, "calibrated": 2,
                             "display_exact": 0}
    out["summary"] = s
    assert "calibration refused on pads 1" in "\n".join(ra.text_lines(out))
    fine["rows"][0]["safety_events"] = 1          # the ratio holds, a safety event does not
    assert not ra.summary(out)["met"]


def test_render_as_built_hands_the_calibrations_to_the_calibrated_row_alone(monkeypatch):
    """The run's wiring, its sessions and fits stubbed: the as-modelled row
    on the design (no [as_built]), the uncalibrated on the drawn pads with
    neither calibration, the calibrated with both; the exact display's with
    the sensing pad's calibration and the drawn display's own model and
    idle scene in place of the display's calibration."""
    from telethermal.bench import render_as_built as ra

    calls = []

    def session(scene, material, identifier, generator, config, seed,
                display_calibration=None, display_model=None, idle_scene=None):
        assert (display_model is None) == (idle_scene is None)
        calls.append((scene.as_built is not None, (identifier[0], id(identifier[1])),
                      display_calibration, None if display_model is None
                      else display_model["flux_gain"]))
        return {"material": material, "seed": seed, "temp_rms_error_c": 0.5,
                "flux_rms_error_rel": 0.02, "identified": material, "safety_events": 0,
                "module_limits": _render_pad(0, {"x": [0]})["rows"][0]["module_limits"]}

    monkeypatch.setattr(ra, "session_row", session)
    monkeypatch.setattr(ra, "train_generator", lambda scene, seed: "generator")
    monkeypatch.setattr(ra, "train_identifier", lambda scene, seed, calibration=None:
                        ("identifier", calibration))
    from types import SimpleNamespace
    pad_cal = SimpleNamespace(chi2_per_dof=1.0)
    monkeypatch.setattr(ra.iab, "calibrate_drawn",
                        lambda scene, built, references: (pad_cal, 1.0, {}))
    import telethermal.sim.display_rig as rig

    class DisplayCal:
        flux_lag_s, flux_lag_s_lo, flux_lag_s_hi, flux_gain = 0.15, 0.14, 0.16, 1.0
        face_layer_thickness, face_layer_thickness_lo, face_layer_thickness_hi = 1.1, 1.09, 1.11
    monkeypatch.setattr(rig, "calibrate_simulated", lambda scene, seed: DisplayCal)
    out = ra.run(0.15, pads=1, quick=True)
    n = len(out["as_modelled"]["rows"])
    assert n == 3 * len(ra.SEEDS) and len(calls) == 4 * n
    assert {c for c in calls[:n]} == {(False, ("identifier", id(None)), None, None)}
    assert {c for c in calls[n:2 * n]} == {(True, ("identifier", id(None)), None, None)}
    assert {c for c in calls[2 * n:3 * n]} == {(True, ("identifier", id(pad_cal)), DisplayCal,
                                                None)}
    gain = draw_as_built(0.15, 0, 3).display.flux_gain         # pad 0's drawn display
    assert {c for c in calls[3 * n:]} == {(True, ("identifier", id(pad_cal)), None, gain)}
    assert out["summary"]["sessions"]["display_exact"] == n
    display = out["calibrations"][0]["display"]
    assert out["summary"]["met"] and display["flux_lag_s"] == 0.15
    assert display["face_layer_thickness"] == 1.1 and display["face_layer_thickness_true"] > 0


def test_the_exact_display_is_the_simulators_display_and_the_design_is_the_configured_one():
    """bench render --as-built's oracle row: on a pad drawn at sd 0 the
    master's exact model is the configured one, key for key, and its idle
    scene has the design's policy; on a drawn pad each part is the one the
    simulator's display under the finger has (its DisplayTouch: layers,
    flux sensor lag, gain, module, junction lag, contact factor; to 1e-12
    relative, the same products), the stack's resistance as summed by hand,
    the horizon stretched by the product's rule for the lumped face factor,
    and the idle scene the drawn layers with the design's finger."""
    import dataclasses

    from telethermal.bench import render_as_built as ra
    from telethermal.control.preconditioning import policy_key
    from telethermal.physics.as_built import with_as_built
    from telethermal.physics.scene import load_scene, with_finger
    from telethermal.sim.touch import MasterWorld
    from telethermal.teleop.display_setup import display_model_args

    scene = with_finger(with_as_built(load_scene("fingertip-7"), None))
    n = len(scene.pad.layers)
    design = display_model_args(scene)
    model, idle = ra.exact_display(scene, with_as_built(scene, draw_as_built(0.0, 0, n)))
    assert model == design and policy_key(idle) == policy_key(scene)
    built = with_as_built(scene, draw_as_built(0.15, 3, n))
    model, idle = ra.exact_display(scene, built)
    touch = MasterWorld(built, 0).display(500.0, 1.0, 24.0)
    assert model["pad_layers"] == touch.layers != scene.pad.layers
    resistance = sum(la.thickness_m / la.material.conductivity_w_mk for la in touch.layers)
    assert model["pad_resistance_m2k_w"] == pytest.approx(resistance, rel=1e-12)
    assert model["sensor_lag_s"] == touch.flux_sensor.lag_s != design["sensor_lag_s"]
    assert model["flux_gain"] == touch.built.flux_gain != 1.0
    assert model["module"] == touch.module != design["module"]
    assert model["junction_sensor"].tau_s == pytest.approx(touch.junction_lag_s, rel=1e-12)
    assert model["contact_conductance_w_m2k"] == pytest.approx(
        design["contact_conductance_w_m2k"] * touch.built.contact_factor, rel=1e-12)
    assert touch.built.contact_factor != 1.0 and model["pad_area_m2"] == touch.area_m2
    # The horizon: the rule the master applies to a calibrated face factor
    # (display_setup.horizon_scale: its square, never under 1), here on the
    # drawn pad's lumped one, 1.65 times the design's.
    face = ra.lumped_face_true(scene, built.as_built.display.layer_thickness)
    assert face > 1.5 and model["impedance_horizon_scale"] == pytest.approx(face ** 2)
    thin = with_as_built(scene, draw_as_built(0.15, 0, n))      # its face layer x0.83
    assert ra.lumped_face_true(scene, thin.as_built.display.layer_thickness) < 1.0
    assert ra.exact_display(scene, thin)[0]["impedance_horizon_scale"] == 1.0
    # The idle policy's scene: the drawn layers, no [as_built], the design's
    # finger (the search's one conductance is also its finger-object target).
    assert idle.as_built is None and idle.pad.layers == touch.layers
    assert dataclasses.replace(idle, pad=scene.pad) == scene
    assert policy_key(idle) != policy_key(scene)


def test_the_exact_model_reaches_the_master_and_the_configured_one_changes_nothing(
        trained_models):
    """run_session's ``display_model`` replaces the master's model: the
    configured model handed in explicitly renders the touch bit for bit as
    none given; the same with another flux gain does not."""
    import numpy as np

    from telethermal.physics.scene import load_scene, with_finger
    from telethermal.sim.inprocess import run_session
    from telethermal.teleop.display_setup import display_model_args

    scene = with_finger(load_scene("fingertip-7"))
    models = trained_models.pair(scene, 0)
    args = display_model_args(scene)

    def current(model):
        return run_session(scene, "steel", *models, contact_s=0.4, seed=3,
                           display_model=model).trace["current_a"]

    plain = current(None)
    assert np.isfinite(plain).sum() > 100
    np.testing.assert_array_equal(current(dict(args)), plain)
    assert not np.allclose(current({**args, "flux_gain": 0.8}), plain, equal_nan=True)
    # The idle scene handed in is the policy the display idles by: the
    # design's scene named explicitly idles where none given does.
    idle = run_session(scene, "steel", *models, contact_s=0.4, seed=3, display_model=args,
                       idle_scene=scene).summary["display_idle_c"]
    assert idle == run_session(scene, "steel", *models, contact_s=0.4,
                               seed=3).summary["display_idle_c"]


def test_a_model_given_in_place_of_the_configured_one_takes_no_calibration():
    from types import SimpleNamespace

    from telethermal.errors import ControlError
    from telethermal.physics.scene import load_scene, with_finger
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.teleop.display_setup import build_display, display_model_args

    scene = with_finger(load_scene("fingertip-7"))
    with pytest.raises(ControlError, match="takes no calibration"):
        build_display(scene, DisplayConfig(), 33.0, SimpleNamespace(), calibration=object(),
                      model=display_model_args(scene))


def test_an_old_render_as_built_file_prints_no_exact_display_row():
    """A report written before the exact display's row (its summary without
    the key) prints its three rows and no line of the fourth."""
    from telethermal.bench import render_as_built as ra

    modelled = _render_pad(0, {"aluminium": [0.7, 0.7]})
    pad = _render_pad(0, {"aluminium": [0.7, 0.75]})
    out = {"sd": 0.15, "pads": 1, "seeds": [1, 2],
           "as_modelled": {"rows": modelled["rows"], "per_material": modelled["per_material"]},
           "uncalibrated": [pad], "calibrated": [pad], "calibrations": [{"seed": 0}]}
    s = ra.summary(out)
    for key in ("sessions", "safety_events", "limits"):
        del s[key]["display_exact"]
    out["summary"] = s
    text = "\n".join(ra.text_lines(out))
    assert "display_exact" not in text and "(exact display:" not in text
    assert "module limits, calibrated" in text and "calibrated 0 in 2" in text
    out["display_exact"] = [_render_pad(0, {"aluminium": [0.7, 0.71]})]
    out["summary"] = ra.summary(out)
    text = "\n".join(ra.text_lines(out))
    assert "module limits, display_exact" in text and "(exact display:" in text
    assert "0.705 K  1.01x" in text


def test_bench_render_as_built_refuses_an_sd_out_of_range(capsys):
    from telethermal.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(["bench", "render", "--as-built", "-0.1", "--json", "x.json"])
    assert exit_.value.code == 2
    assert "--as-built: '-0.1' must be an sd in [0.0, 1.0]" in capsys.readouterr().err


def test_the_reference_materials_are_the_scenes_and_two_at_least():
    from telethermal.ident.calibration import REFERENCE_MATERIALS, reference_materials
    from telethermal.physics.scene import load_scene

    scene = load_scene("fingertip-7")
    assert reference_materials(scene) == list(REFERENCE_MATERIALS)
    assert reference_materials(scene, ("aluminium", "steel", "wood", "steel")) == \
        ["aluminium", "steel", "wood"]
    with pytest.raises(ValueError, match="'copper' is not one of scene fingertip-7's: "
                                         "aluminium, steel"):
        reference_materials(scene, ("steel", "copper"))
    with pytest.raises(ValueError, match="at least 2 reference materials"):
        reference_materials(scene, ("steel", "steel"))
    # One of the default blocks only: the scene's first three instead.
    import dataclasses
    metals = dataclasses.replace(scene, objects=tuple(
        o for o in scene.objects if o.material in ("aluminium", "steel", "marble", "graphite")))
    assert reference_materials(metals) == ["aluminium", "steel", "marble"]


@pytest.mark.parametrize("argv, said", [
    (["bench", "unseen", "--references", "steel,wood"], "--references is for --as-built"),
    (["bench", "identify", "--as-built", "0.15", "--references", "steel,copper"],
     "--references: reference material 'copper' is not one of scene fingertip-7's"),
    (["bench", "render", "--as-built", "0.15", "--references", "wood"],
     "--references: a calibration needs at least 2 reference materials"),
    (["bench", "unseen", "--as-built", "0.15", "--references", "glass,wood"],
     "--references: reference material 'glass' is not one of scene fingertip-7's"),
])
def test_reference_materials_a_bench_cannot_use_are_refused_before_it_runs(
        tmp_path, capsys, argv, said):
    from telethermal.cli import main

    out = tmp_path / "x.json"
    assert main([*argv, "--json", str(out)]) != 0
    assert said in capsys.readouterr().err
    assert not out.exists()


def test_an_as_built_printout_names_its_references_and_the_worst_pad_by_pad():
    from telethermal.bench import unseen_as_built as ua

    out = {"sd": 0.15, "pads": 2, "seeds": [0], "method": "effusivity-fit", "window_s": 0.5,
           "targets": {"median_rel_error_max": 0.10, "coverage": [0.9, 0.98]},
           "reference": {"materials": ["aluminium", "steel", "wood"], "touches_each": 5},
           "as_modelled": _unseen_row({"copper": 0.05}, 19, 20),
           "uncalibrated": [_unseen_row({"copper": 0.5}, 10, 20)] * 2,
           "calibrated": [_unseen_row({"copper": 0.06}, 18, 20),
                          _unseen_row({"copper": 0.324}, 19, 20)]}
    out["summary"] = ua.summary(out)
    text = "\n".join(ua.text_lines(out))
    assert "calibrated from 5 touches each of aluminium, steel, wood" in text
    assert "calibrated copper pad by pad: 6.0 %, 32.4 %" in text
