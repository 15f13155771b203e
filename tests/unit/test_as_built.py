"""Pads built off their datasheet (``[as_built]``): read by the simulator
only (issue 44, deliverable 1)."""

from __future__ import annotations

import copy
import logging
import tomllib
from importlib import resources

import numpy as np
import pytest

from telethermal.errors import SceneError
from telethermal.physics.as_built import (PART_KEYS, SCALAR_KEYS, draw_as_built,
                                          simulated_module, simulated_pad_scene)
from telethermal.physics.scene import ObjectSpec, parse_scene, pad_contact_model


def _data(objects=("aluminium", "plexiglass"), trials=1) -> dict:
    data = tomllib.loads(resources.files("telethermal").joinpath(
        "scenes/fingertip-7.toml").read_text())
    data["objects"] = [o for o in data["objects"] if o["material"] in objects]
    data["pad"]["trials_per_material"] = trials
    return data


def _scene(as_built=None, **kw):
    data = _data(**kw)
    if as_built is not None:
        data["as_built"] = as_built
    return parse_scene(data, "variant.toml")


def test_factors_given_are_read_and_missing_ones_are_one():
    scene = _scene({"pad": {"layer_thickness": [1.2, 1.5, 1.0], "flux_lag_s": 1.2}})
    f = scene.as_built.pad
    assert f.layer_thickness == (1.2, 1.5, 1.0) and f.flux_lag_s == 1.2
    assert f.flux_gain == 1.0 and scene.as_built.display.nominal


def test_drawn_factors_are_reproducible_and_lognormal():
    a, b = draw_as_built(0.15, 3, 3), draw_as_built(0.15, 3, 3)
    assert a == b and a != draw_as_built(0.15, 4, 3)
    # 2000 draws of ln(factor): mean 0, sd 0.15 (standard errors 0.0034 and 0.0024; 5 of them)
    logs = np.log([getattr(draw_as_built(0.15, s, 1).pad, k)
                   for s in range(250) for k in SCALAR_KEYS[:4]] +
                  [draw_as_built(0.15, s, 1).pad.layer_thickness[0] for s in range(1000)])
    assert abs(logs.mean()) < 0.017 and abs(logs.std() - 0.15) < 0.012


@pytest.mark.parametrize("raw, words", [
    ({"pad": {"layer_thickness": [1.1]}}, "3 factor(s)"),
    ({"pad": {"flux_lagg_s": 1.1}}, "unknown key(s) flux_lagg_s"),
    ({"pad": {"flux_gain": 0.0}}, "'flux_gain' = 0.0"),
    ({"sd": 0.1, "seed": 1, "pad": {}}, "not both"),
    ({"sd": 0.1}, "missing seed"),
    ({"sd": 2.0, "seed": 1}, "'sd' = 2.0"),
    ({}, "empty"),
])
def test_bad_tables_are_refused_by_name(raw, words):
    with pytest.raises(SceneError, match="variant.toml: \\[as_built") as err:
        _scene(raw)
    assert words in str(err.value)


def test_a_scene_with_them_says_so_in_the_log(caplog):
    with caplog.at_level(logging.WARNING):
        _scene({"sd": 0.15, "seed": 0})
    assert "pads built off their datasheet" in caplog.text and "sd 0.15, seed 0" in caplog.text


def test_display_factors_are_in_the_log_and_the_record(caplog):
    """A scene with ``[as_built.display]`` factors says them in the log and
    its record; ``junction_lag_s`` is the display's alone (the sensing
    pad's thermistor has no lag in the simulator)."""
    with caplog.at_level(logging.WARNING):
        scene = _scene({"display": {"flux_lag_s": 1.5, "junction_lag_s": 0.5}})
    assert "display flux_lag_s 1.5" in caplog.text or "flux_lag_s 1.5" in caplog.text
    assert scene.as_built.to_dict()["display"]["junction_lag_s"] == 0.5
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        _scene({"pad": {"flux_lag_s": 1.5}})
    assert "display as designed" in caplog.text
    with pytest.raises(SceneError, match="unknown key.*junction_lag_s"):
        _scene({"pad": {"junction_lag_s": 1.2}})


def test_the_display_draw_leaves_the_pads_draws_as_they_were():
    """``junction_lag_s`` is drawn after every other factor: the sensing
    pad's and the display's other factors of a seed are what they were
    before it existed (the same generator, the same order)."""
    ab = draw_as_built(0.15, 3, 3)
    rng = np.random.default_rng(3)
    pad = np.exp(rng.normal(0.0, 0.15, 3 + len(SCALAR_KEYS) + 3 + len(SCALAR_KEYS) + 1))
    assert ab.pad.layer_thickness == tuple(pad[:3])
    assert ab.display.flux_gain == pad[3 + len(SCALAR_KEYS) + 3 + SCALAR_KEYS.index("flux_gain")]
    assert ab.display.junction_lag_s == pad[-1]


def test_removing_the_tables_changes_no_model_the_product_builds():
    """Every model the product builds from a scene (the pad's contact
    model, the effusivity estimator's curves, its priors and noise) is the
    same, to the bit, with and without ``[as_built]``."""
    from telethermal.ident.effusivity_curves import effusivity_family
    from telethermal.ident.oracle import draw_nuisances, flux_noise_w_m2

    plain, built = _scene(), _scene({"sd": 0.3, "seed": 7})
    assert not built.as_built.pad.nominal
    obj = ObjectSpec("plexiglass", 24.0, 0.03)
    t = np.linspace(0, 0.5, 51)
    a, b = (pad_contact_model(s, obj)[0].solve(t, 34.0, 24.0, 3000.0) for s in (plain, built))
    assert np.array_equal(a.flux_sensed_w_m2, b.flux_sensed_w_m2)
    fa, fb = (effusivity_family(s, 24.0, np.linspace(-0.3, 0.3, 4), 0.06, n_e=4)
              for s in (plain, built))
    assert np.array_equal(fa.g, fb.g)
    na, nb = (draw_nuisances(s, 40, np.random.default_rng(1), n_sessions=2)
              for s in (plain, built))
    assert np.array_equal(na["u"], nb["u"]) and np.array_equal(na["tau_s"], nb["tau_s"])
    assert all(np.array_equal(na["amp"][k], nb["amp"][k]) for k in na["amp"])
    assert flux_noise_w_m2(plain) == flux_noise_w_m2(built)
    # The display's: what its controllers are built from, and the controllers.
    from telethermal.teleop.display_setup import display_model_args
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.teleop.master import MasterDisplay
    plain, built = _scene(), _scene({"sd": 0.3, "seed": 7})
    assert not built.as_built.display.nominal
    assert display_model_args(plain) == display_model_args(built)
    da, db = (MasterDisplay(DisplayConfig(), None, finger_temp_c=33.0,
                            **display_model_args(s)) for s in (plain, built))
    assert da.junction_design == db.junction_design
    assert vars(da.junction_loop.gains) == vars(db.junction_loop.gains)
    assert da.impedance.tau_s == db.impedance.tau_s == plain.sensors.flux_lag_s


def test_the_simulated_pad_is_the_scene_written_with_the_built_values():
    """Touches of a pad built with factors on its layers, contact conductance
    and lag equal those of a scene that names the built values as nominal
    (same draws: equal to rounding). The module's own cold plate, last in
    the stack, is no key of a scene file: the written scene's is set on the
    parsed scene."""
    import dataclasses

    from telethermal.data.generate import pad_database
    from telethermal.physics.layered import Layer
    factors = {"layer_thickness": [1.3, 1.5, 0.8], "flux_lag_s": 1.2,
               "contact_conductance_w_m2k": 0.85}
    built = _scene({"pad": factors})
    data = _data()
    assert len(data["pad"]["layers"]) == 2          # the plate is added on parsing
    data["pad"]["layers"] = [[m, t * f] for (m, t), f in
                             zip(data["pad"]["layers"], factors["layer_thickness"])]
    data["pad"]["contact_conductance_w_m2k"] *= 0.85
    data["sensors"]["flux_lag_s"] *= 1.2
    written = parse_scene(data, "written.toml")
    plate = written.pad.layers[-1]
    written = dataclasses.replace(written, pad=dataclasses.replace(
        written.pad, layers=written.pad.layers[:-1] + (Layer(plate.material,
                                                             plate.thickness_m * 0.8),)))
    a = pad_database(built, np.random.default_rng(0))
    b = pad_database(written, np.random.default_rng(0))
    plain = pad_database(_scene(), np.random.default_rng(0))
    for x, y, z in zip(a, b, plain):
        fx, fy = x.channels["heat_flux_W_m2"], y.channels["heat_flux_W_m2"]
        assert np.allclose(fx, fy, rtol=0, atol=1e-9)
        assert not np.allclose(fx, z.channels["heat_flux_W_m2"], atol=1.0)


def test_the_flux_gain_and_module_factors_reach_the_simulator():
    """A flux gain 5 % high reads every sample 5 % high (the same noise
    draws: the ratio of sums over 0.5-2 s is 1.05 to 1e-4, quantisation);
    the module's factors scale its derived S, R, K."""
    from telethermal.data.generate import _pad_module, pad_database
    plain, built = _scene(), _scene({"pad": {"flux_gain": 1.05}})
    for x, y in zip(pad_database(plain, np.random.default_rng(0)),
                    pad_database(built, np.random.default_rng(0))):
        m = (x.channels["t_s"] > 0.5)
        ratio = y.channels["heat_flux_W_m2"][m].sum() / x.channels["heat_flux_W_m2"][m].sum()
        assert ratio == pytest.approx(1.05, abs=1e-4)
    mod = _scene({"pad": {"module_seebeck": 1.1, "module_resistance": 0.9,
                          "module_conductance": 1.2}})
    nominal = _pad_module(mod)[0]
    got = simulated_module(mod, nominal)
    assert got.seebeck_v_k == pytest.approx(1.1 * nominal.seebeck_v_k)
    assert got.resistance_ohm == pytest.approx(0.9 * nominal.resistance_ohm)
    assert got.conductance_w_k == pytest.approx(1.2 * nominal.conductance_w_k)
    assert simulated_pad_scene(plain) is plain and set(PART_KEYS) > set(SCALAR_KEYS)


def test_generation_json_records_the_pads_as_built(tmp_path):
    from telethermal.data.generate import generate_databases
    data = _data(objects=("plexiglass",))
    data.pop("finger")
    data["as_built"] = {"sd": 0.1, "seed": 2}
    summary = generate_databases(parse_scene(copy.deepcopy(data), "v.toml"), tmp_path / "db")
    assert summary["as_built"]["sd"] == 0.1
    assert "as_built" in (tmp_path / "db" / "generation.json").read_text()


def _display_touch(scene, contact_s=0.3):
    from telethermal.sim.touch import DisplayTouch, Operator
    op = Operator(33.0, 33.0, 1.0, 1.0, 10.0, 5000.0)
    return DisplayTouch(scene, op, 500.0, contact_s, 25.0, np.random.default_rng(0))


def test_display_factors_reach_the_display_simulator_only():
    """``[as_built.display]`` builds the display's simulated pad (its
    layers, flux lag and gain, module, junction sensor's lag), the sensing
    pad's simulator stays nominal; the display's flux gain reads every
    sample that many times the nominal sensor's (the same draws: the sum's
    ratio to 1e-3, the 0.01 uV quantisation on ~100 uV)."""
    from telethermal.physics.as_built import simulated_display
    factors = {"layer_thickness": [1.3, 1.0, 0.8], "flux_lag_s": 1.3, "flux_gain": 1.05,
               "module_resistance": 1.2, "junction_lag_s": 2.0}
    plain, built = _scene(), _scene({"display": factors})
    assert simulated_pad_scene(built).pad == plain.pad
    d, p = simulated_display(built), simulated_display(plain)
    assert p.layers == tuple(plain.pad.layers) and p.flux_lag_s == plain.sensors.flux_lag_s
    assert [lay.thickness_m for lay in d.layers] == pytest.approx(
        [lay.thickness_m * k for lay, k in zip(plain.pad.layers, factors["layer_thickness"])])
    assert d.flux_lag_s == pytest.approx(1.3 * plain.sensors.flux_lag_s)
    assert d.module.resistance_ohm == pytest.approx(1.2 * p.module.resistance_ohm)
    ta, tb = _display_touch(plain), _display_touch(built)
    assert tb.junction_lag_s == pytest.approx(2.0 * ta.junction_lag_s)
    assert tb.module.resistance_ohm == pytest.approx(1.2 * ta.module.resistance_ohm)
    fa, fb = [], []
    for touch, out in ((ta, fa), (tb, fb)):
        for k in range(150):                    # 0.3 s of contact at 500 Hz
            out.append(touch.sense(k / 500.0).flux_w_m2)
            touch._drive(0.0)
    # The same pad but for its gain: the layers and lag of the plain one.
    gain_only = _display_touch(_scene({"display": {"flux_gain": 1.05}}))
    fg = []
    for k in range(150):
        fg.append(gain_only.sense(k / 500.0).flux_w_m2)
        gain_only._drive(0.0)
    assert sum(fg[50:]) / sum(fa[50:]) == pytest.approx(1.05, abs=1e-3)
    # The thicker, slower-sensed pad reads another flux altogether.
    assert abs(sum(fb[50:]) / sum(fa[50:]) - 1.05) > 0.02
