"""The sensing pad's model calibrated from reference touches (issue 44,
deliverable 2): the hard cases."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from telethermal.errors import CalibrationError
from telethermal.physics.as_built import AsBuilt, BuiltFactors, with_as_built
from telethermal.physics.scene import load_scene

WINDOW_S = 0.5


def _scene(materials=("steel", "wood"), trials=3):
    s = load_scene("fingertip-7")
    return dataclasses.replace(
        s, finger=None, pad=dataclasses.replace(s.pad, trials_per_material=trials),
        objects=tuple(o for o in s.objects if o.material in materials))


@pytest.fixture(scope="module")
def off_pad():
    """A pad 30 % off on every factor but its flux gain, 5 % off, touched
    3 times on each of two reference materials; (scene, trials, truth)."""
    from telethermal.data.generate import pad_database, sensor_session
    scene = _scene()
    f = 1.3
    built = with_as_built(scene, AsBuilt(BuiltFactors(
        (f, f, f), flux_lag_s=f, contact_conductance_w_m2k=f, flux_gain=1.05,
        module_seebeck=f, module_resistance=f, module_conductance=f), BuiltFactors((1, 1, 1))))
    trials = pad_database(built, np.random.default_rng(0))
    gain = 1.05 * sensor_session(scene, np.random.default_rng(0)).instruments.flux_gain
    truth = {"flux_gain": gain, "flux_lag_s": f,
             **{f"layers[{i}].{k}": f for i in range(3) for k in ("resistance", "heat_capacity")}}
    return scene, trials, truth


@pytest.fixture(scope="module")
def calibrated(off_pad):
    from telethermal.ident.pad_calibration import calibrate_pad
    scene, trials, _ = off_pad
    return calibrate_pad(scene, trials, WINDOW_S)


def test_a_pad_30_percent_off_from_two_materials_is_recovered_within_its_intervals(
        off_pad, calibrated):
    """Every parameter fitted (the lag, the gain 5 % off, the layers'
    resistances and heat capacities, lumped where the Jacobian cannot tell
    them apart) holds its true factor within its 95 % interval, and the
    lag and the gain are among them; the module's factors are not
    candidates (the loop holds the junction) and the fit still holds."""
    from telethermal.bench.identify_as_built import lumped_truth
    scene, _, truth = off_pad
    names = {n for p in calibrated.parameters for n in p.names}
    assert {"flux_gain", "flux_lag_s"} <= names
    for p in calibrated.parameters:
        want = lumped_truth(scene, p.names, truth)       # the bench's own rule
        assert p.lo <= want <= p.hi, (p, want)
        assert p.hi / p.lo < 1.5                 # a confident parameter, not a shrug
    assert calibrated.chi2_per_dof < 2.0
    # The contact conductance is the touches' own (true 1.3 x 3000 at 10 +- 1.5 N).
    assert calibrated.contact_conductance_w_m2k == pytest.approx(3900, rel=0.1)
    # Thickness and conductivity are never two parameters: resistance and
    # heat capacity per layer (the module's docstring).
    assert not any("thickness" in n or "conductivity" in n for n in names)
    # What the touches cannot tell alone is fitted under its design prior
    # (log sd design_sd): named, in the model, its interval no wider than
    # the prior's own (the posterior's, chi2 under 1 here).
    from telethermal.ident.openset import Z95
    from telethermal.ident.pad_calibration import interval_sd
    assert [p.label for p in calibrated.prior_fitted] == list(calibrated.not_identifiable)
    assert calibrated.prior_fitted                         # this pad has some
    sds = [interval_sd(p.lo, p.hi) for p in calibrated.prior_fitted]
    # About the prior's width: a part the touches barely see keeps it (a
    # lumped member's spread can add a little), and none is sharpened to
    # nothing by a missing or misweighted prior row.
    assert max(sds) <= calibrated.design_sd * 1.05 and max(sds) >= 0.9 * calibrated.design_sd
    assert Z95 * min(sds) > 0.05
    for p in calibrated.prior_fitted:
        assert all(calibrated.factors()[n] == p.factor for n in p.names)


@pytest.mark.slow          # two calibrations, about a minute here
def test_a_part_the_touches_see_weakly_is_fitted_under_its_prior_not_pinned():
    """A cold plate 30 % thick, everything else as designed, touched on the
    default references: its resistance (identified or fitted under its
    design prior) holds 1.3 within its interval and moves most of the way
    there; with no prior (design_sd = 0) a part the touches cannot tell
    is held at its design value instead, and named."""
    from telethermal.data.generate import pad_database
    from telethermal.ident.calibration import REFERENCE_MATERIALS
    from telethermal.ident.pad_calibration import calibrate_pad
    scene = _scene(REFERENCE_MATERIALS, trials=5)
    built = with_as_built(scene, AsBuilt(BuiltFactors((1.0, 1.0, 1.3)), BuiltFactors((1, 1, 1))))
    trials = pad_database(built, np.random.default_rng(1))
    cal = calibrate_pad(scene, trials)
    plate = next(p for p in cal.prior_fitted if "layers[2].resistance" in p.names)
    assert plate.lo <= 1.3 <= plate.hi and plate.factor > 1.15, plate
    held = calibrate_pad(scene, trials, design_sd=0.0)
    assert held.prior_fitted == () and "layers[2].resistance" not in held.factors()
    assert plate.label in held.not_identifiable
    assert any("design value kept" in line and plate.label in line
               for line in held.describe())


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_a_reference_material_whose_table_value_is_wrong_is_named():
    """Its touches' amplitudes all stand out one way (10 % of effusivity
    against the thermometers' ~1 % per touch), named among three materials.
    (With two, the pad's free parameters can take the error up: measured,
    10 % on wood against steel was not flagged; docs/calibration.md says
    to calibrate on three.)"""
    from telethermal.data.generate import pad_database
    from telethermal.ident.calibration import ReferenceTouches
    from telethermal.ident.pad_calibration import calibrate_touches
    scene = _scene(("steel", "plexiglass", "wood"))
    touches = ReferenceTouches.from_trials(pad_database(scene, np.random.default_rng(3)),
                                           WINDOW_S)
    wood = np.array([label == "wood" for label in touches.labels])
    touches.effusivity = np.where(wood, touches.effusivity * 1.1, touches.effusivity)
    with pytest.raises(CalibrationError, match="the touches of wood do not fit its table"):
        calibrate_touches(scene, touches)


def test_too_few_touches_or_materials_are_refused(off_pad):
    from telethermal.ident.pad_calibration import calibrate_pad
    scene, trials, _ = off_pad
    with pytest.raises(CalibrationError, match="at least 3 touches.*steel: 3"):
        calibrate_pad(scene, [t for t in trials if t.material == "steel"], WINDOW_S)
    two_each = [t for t in trials if not t.trial_id.endswith("-02")]
    with pytest.raises(CalibrationError, match="steel: 2, wood: 2"):
        calibrate_pad(scene, two_each, WINDOW_S)


def test_the_file_round_trips_and_another_scenes_is_refused(calibrated, tmp_path):
    from telethermal.ident.pad_calibration import read_calibration, write_calibration
    path = write_calibration(calibrated, tmp_path / "cal.toml")
    back = read_calibration(path)
    assert back.to_dict() == calibrated.to_dict() and back.source == str(path)
    back.check(_scene())
    with pytest.raises(CalibrationError, match="calibrates scene 'fingertip-7'.*gripper"):
        back.apply(load_scene("gripper-case-II"))
    other = dataclasses.replace(_scene(), sensors=dataclasses.replace(
        _scene().sensors, flux_lag_s=0.2))
    with pytest.raises(CalibrationError, match="another pad"):
        back.apply(other)
    (tmp_path / "bad.toml").write_text('format = "something else"\n')
    with pytest.raises(CalibrationError, match="bad.toml"):
        read_calibration(tmp_path / "bad.toml")


def test_the_calibrated_model_and_a_model_file_record_it(calibrated, tmp_path):
    """The product's pad model takes the calibrated factors; the amplitude
    prior takes the calibrated gain (not the scene's instruments); a model
    file keeps the calibration it was trained with."""
    from telethermal.ident.fitted import EffusivityFit
    from telethermal.ident.oracle import draw_nuisances
    scene = _scene()
    applied = calibrated.apply(scene)
    lag = next(p.factor for p in calibrated.parameters if p.names == ("flux_lag_s",))
    assert applied.sensors.flux_lag_s == pytest.approx(scene.sensors.flux_lag_s * lag)
    draws = draw_nuisances(scene, 200, np.random.default_rng(0), n_sessions=4,
                           flux_gain=(calibrated.flux_gain, calibrated.flux_gain_sd))
    mean_amp = np.mean(np.concatenate(list(draws["amp"].values())))
    assert mean_amp == pytest.approx(calibrated.flux_gain, rel=0.01)
    model = EffusivityFit(scene="fingertip-7", calibration=calibrated)
    again = EffusivityFit(**model.hyper())
    assert again.calibration.to_dict() == calibrated.to_dict()


def test_a_service_refuses_a_model_trained_with_another_calibration(tmp_path):
    """The slave's ``pad_calibration`` and its identifier's must agree (a
    model file records the calibration it was trained with); a method that
    fits no pad model is not asked."""
    from telethermal.errors import ModelFileError
    from telethermal.ident.fitted import EffusivityFit
    from telethermal.ident.methods import EffusivityLda
    from telethermal.ident.pad_calibration import (CalibratedParameter, PadCalibration,
                                                   check_model_calibration, pad_calibration,
                                                   pad_digest, write_calibration)
    scene = load_scene("fingertip-7")
    cal = PadCalibration("fingertip-7", pad_digest(scene), (CalibratedParameter(
        ("flux_lag_s",), "flux sensor lag", 1.1, 1.05, 1.15),), (), 3000.0, 1.0, 0.01, 0.1,
        15, ("steel", "wood"))
    path = write_calibration(cal, tmp_path / "cal.toml")
    assert pad_calibration("", scene) is None
    mine = pad_calibration(str(path), scene)
    check_model_calibration(EffusivityFit(scene="fingertip-7", calibration=mine), mine, "m")
    check_model_calibration(EffusivityLda(), mine, "lda")
    with pytest.raises(ModelFileError, match="trained with no pad calibration"):
        check_model_calibration(EffusivityFit(scene="fingertip-7"), mine, "m.npz")
    with pytest.raises(CalibrationError, match="gripper-case-II"):
        pad_calibration(str(path), load_scene("gripper-case-II"))


def _hand_made(scene):
    """A calibration written by hand for ``scene`` (no fit: the file's checks)."""
    from telethermal.ident.pad_calibration import (CalibratedParameter, PadCalibration,
                                                   pad_digest)
    return PadCalibration(
        scene.name, pad_digest(scene),
        (CalibratedParameter(("flux_gain",), "flux sensor gain", 1.02, 1.0, 1.04),
         CalibratedParameter(("flux_lag_s",), "flux sensor lag", 1.1, 1.0, 1.2)),
        (), 3000.0, 1.02, 0.01, 0.03, 6, ("steel", "wood"))


@pytest.mark.parametrize("edit, field", [
    (("factor = 1.1", "factor = nan"), r"parameters\[1\].factor: nan"),
    (("factor = 1.1", "factor = inf"), r"parameters\[1\].factor: inf"),
    (("flux_gain = 1.02", "flux_gain = -1.02"), "flux_gain: -1.02; must be a finite number > 0"),
    (("contact_conductance_w_m2k = 3000.0", "contact_conductance_w_m2k = 0"),
     "contact_conductance_w_m2k: 0"),
    (("flux_gain_sd = 0.01", "flux_gain_sd = -0.01"), "flux_gain_sd: -0.01; .* >= 0"),
    (('names = ["flux_lag_s"]', 'names = "flux_lag_s"'),
     r"parameters\[1\].names: expected list, got 'flux_lag_s'"),
    (('names = ["flux_lag_s"]', 'names = [1]'), r"parameters\[1\].names: expected a list of str"),
    (('names = ["flux_lag_s"]', 'names = []'), r"parameters\[1\].names: empty"),
    (("touches = 6", 'touches = "6"'), "touches: expected int"),
    (("touches = 6", "touches = 0"), "touches: 0"),
    (('materials = ["steel", "wood"]', 'materials = "steel"'), "materials: expected list"),
    (("factor = 1.1", "factor = 1.5"), r"parameters\[1\]: factor 1.5 outside"),
    (("flux_gain = 1.02\n", ""), "flux_gain: missing"),
])
def test_a_calibration_file_with_a_bad_field_is_refused_naming_it(tmp_path, edit, field):
    """Every number finite and > 0 (a standard deviation >= 0), the lists
    lists of strings (a string alone is not split into letters): refused
    with the file and the field named (issue 47's contract)."""
    import re

    from telethermal.ident.pad_calibration import read_calibration
    text = _hand_made(_scene()).to_toml()
    old, new = edit
    assert text.count(old) == 1
    path = tmp_path / "cal.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(CalibrationError) as err:
        read_calibration(path)
    assert str(path) in str(err.value) and re.search(field, str(err.value)), err.value


def test_a_calibration_naming_no_parameter_of_the_scene_is_refused(tmp_path):
    """A name the pad's model does not have would be ignored by the scaled
    scene: refused against the scene, naming it and the known ones."""
    from telethermal.ident.pad_calibration import read_calibration
    scene = _scene()
    path = tmp_path / "cal.toml"
    path.write_text(_hand_made(scene).to_toml().replace('"flux_lag_s"', '"flux_lag"'))
    cal = read_calibration(path)
    with pytest.raises(CalibrationError, match=r"cal.toml: parameters\[1\].names: 'flux_lag' "
                                               r"is not a parameter.*flux_lag_s"):
        cal.apply(scene)
    path.write_text(_hand_made(scene).to_toml())
    read_calibration(path).apply(scene)          # the file as written is taken


def test_a_calibration_file_past_the_readers_limits_is_refused_by_the_cli(tmp_path):
    """Read through the TOML reader's limits (size, UTF-8, dotted keys);
    the command exits 2 with the file named."""
    from telethermal.cli import main
    from telethermal.tomltables import MAX_KEY_PARTS, MAX_TOML_BYTES
    bad = {"big.toml": b"#" * (MAX_TOML_BYTES + 1), "latin.toml": b'scene = "\xe9"\n',
           "dotted.toml": ".".join(["a"] * (MAX_KEY_PARTS + 1)).encode() + b" = 1\n"}
    for name, data in bad.items():
        (tmp_path / name).write_bytes(data)
        assert main(["models", "--out", str(tmp_path / "out"), "--calibration",
                     str(tmp_path / name)]) == 2, name
    from telethermal.ident.pad_calibration import read_calibration
    for name, why in (("big.toml", "byte limit"), ("latin.toml", "not UTF-8"),
                      ("dotted.toml", "dotted parts")):
        with pytest.raises(CalibrationError, match=f"{name}: .*{why}"):
            read_calibration(tmp_path / name)


def test_the_pad_digest_follows_the_figures_not_the_descriptions(monkeypatch):
    """A layer material's source text or role, or the database's size, leave
    a calibration valid; a layer's thickness or the module's resistance
    make it another pad's."""
    import dataclasses

    from telethermal.ident.pad_calibration import pad_digest
    from telethermal.physics import thermoelectric as te
    from telethermal.physics.scene import load_scene

    scene = load_scene("fingertip-7")
    base = pad_digest(scene)
    pad = scene.pad
    layer = pad.layers[0]
    renamed = dataclasses.replace(layer, material=dataclasses.replace(
        layer.material, source="another handbook", role="film"))
    same = [dataclasses.replace(pad, layers=(renamed, *pad.layers[1:])),
            dataclasses.replace(pad, trials_per_material=pad.trials_per_material + 7,
                                contact_duration_s=pad.contact_duration_s * 2)]
    for p in same:
        assert pad_digest(dataclasses.replace(scene, pad=p)) == base
    thicker = dataclasses.replace(layer, thickness_m=layer.thickness_m * 1.1)
    assert pad_digest(dataclasses.replace(scene, pad=dataclasses.replace(
        pad, layers=(thicker, *pad.layers[1:])))) != base
    spec = te.get_module(pad.module)
    monkeypatch.setattr(te, "get_module", lambda name: dataclasses.replace(
        spec, resistance_ohm=spec.resistance_ohm * 1.05))
    assert pad_digest(scene) != base


def test_prior_fitted_parts_round_trip_and_a_version_1_file_holds_them_at_the_design(
        tmp_path):
    """Format 2 keeps the prior-fitted parts (checked as the parameters are,
    named when bad); a version-1 file reads with none (its parts at their
    design, as it was made); another version is refused naming it."""
    from telethermal.ident.pad_calibration import (CalibratedParameter, read_calibration,
                                                   write_calibration)
    scene = _scene()
    cal = dataclasses.replace(_hand_made(scene), not_identifiable=("alumina resistance",),
                              prior_fitted=(CalibratedParameter(
                                  ("layers[2].resistance",), "alumina resistance",
                                  1.2, 0.85, 1.7),), design_sd=0.2)
    path = write_calibration(cal, tmp_path / "cal.toml")
    back = read_calibration(path)
    assert back.prior_fitted == cal.prior_fitted
    assert back.apply(scene) == cal.apply(scene)
    assert back.factors()["layers[2].resistance"] == 1.2
    assert any("alumina resistance: x1.200" in line for line in back.describe())
    text = path.read_text()
    for old, new, why in (("factor = 1.2\n", "factor = 0.5\n", r"prior_fitted\[0\]: factor 0.5"),
                          ('names = ["layers[2].resistance"]', 'names = "x"',
                           r"prior_fitted\[0\].names: expected list")):
        path.write_text(text.replace(old, new))
        with pytest.raises(CalibrationError, match=why):
            read_calibration(path)
    path.write_text(text.replace(' layers[2].resistance"]', ' layers[9].resistance"]')
                    .replace('"layers[2].resistance"', '"layers[9].resistance"'))
    with pytest.raises(CalibrationError, match=r"prior_fitted\[0\].names: 'layers\[9\]"):
        read_calibration(path).apply(scene)
    path.write_text(text.replace("format_version = 2", "format_version = 1"))
    old = read_calibration(path)
    assert old.prior_fitted == () and "layers[2].resistance" not in old.factors()
    for version in ("3", "true", "2.0"):
        path.write_text(text.replace("format_version = 2", f"format_version = {version}"))
        with pytest.raises(CalibrationError, match=f"version {version.capitalize()}"):
            read_calibration(path)
    # A file that contradicts itself: a prior-fitted part the file does not
    # name as unidentifiable, or one with no prior.
    path.write_text(text.replace('not_identifiable = ["alumina resistance"]',
                                 "not_identifiable = []"))
    with pytest.raises(CalibrationError, match=r"prior_fitted\[0\]: 'alumina resistance' is "
                                               "not named in not_identifiable"):
        read_calibration(path)
    path.write_text(text.replace("design_sd = 0.2", "design_sd = 0.0"))
    with pytest.raises(CalibrationError, match="design_sd = 0"):
        read_calibration(path)
    path.write_text(text.replace('names = ["layers[2].resistance"]', 'names = ["flux_gain"]'))
    with pytest.raises(CalibrationError, match=r"prior_fitted\[0\]: the flux gain is never"):
        read_calibration(path)
    # A version-1 file's held parts: said held, their spread carried.
    lines = read_calibration(write_calibration(dataclasses.replace(
        cal, prior_fitted=()), tmp_path / "held.toml")).describe()
    assert any("design value kept): alumina resistance" in line for line in lines)
    assert any("each part held at its design off it by a log sd of 0.2" in line
               for line in lines)
    # A parameter fitted twice (identified and prior-fitted) is refused
    # where it would be applied; a file with no table of either kind reads.
    path.write_text(text.replace('"layers[2].resistance"', '"flux_lag_s"'))
    with pytest.raises(CalibrationError, match=r"prior_fitted\[0\].names: 'flux_lag_s' is "
                                               "fitted twice"):
        read_calibration(path).apply(scene)
    bare = dataclasses.replace(cal, parameters=(), prior_fitted=(), not_identifiable=())
    assert read_calibration(write_calibration(bare, tmp_path / "bare.toml")).parameters == ()


def test_names_with_quotes_and_backslashes_round_trip(tmp_path):
    """A scene, material or label holding a quote, a backslash or a newline
    is written as TOML escapes it and reads back as it was (it was written
    between bare quotes: an unreadable file, or another name)."""
    from telethermal.ident.pad_calibration import read_calibration, write_calibration

    cal = _hand_made(_scene())
    odd = dataclasses.replace(cal, scene='lab "A"\\pad\n2', materials=('st"eel', "wo\\od"),
                              parameters=(dataclasses.replace(cal.parameters[0],
                                                              label='gain "x"\\'),
                                          *cal.parameters[1:]))
    back = read_calibration(write_calibration(odd, tmp_path / "cal.toml"))
    assert back.scene == odd.scene and back.materials == odd.materials
    assert back.parameters[0].label == 'gain "x"\\'
