"""Flux generators against a closed form and on held-out persons."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import erfcx

from telethermal.data.dataset import Trial
from telethermal.data.generate import finger_database
from telethermal.errors import IdentificationError
from telethermal.physics.materials import get_material
from telethermal.physics.scene import load_scene
from telethermal.errors import ModelFileError
from telethermal.render.generator import (ContactGenerator, NetworkGenerator, display_flux,
                                          load_generator, mixture, rendering_error,
                                          save_generator)

E_SKIN = get_material("skin").effusivity


def closed_form_trials(h=4000.0, e_m=2000.0, gaps=(8.0, 10.0, 12.0)):
    t = np.arange(0, 6001) / 100.0
    q = h * erfcx(h * (1 / E_SKIN + 1 / e_m) * np.sqrt(t))
    return [Trial(f"m-{i}", "marble", f"m-{i}.csv", 100.0, 24.0, 24.0 + g, 24.0, "person-0",
                  channels={"t_s": t, "heat_flux_W_m2": q * g}) for i, g in enumerate(gaps)]


def test_contact_generator_recovers_the_closed_form_parameters():
    gen = ContactGenerator().fit(closed_form_trials())
    h, e_m, _ = gen.params_["marble"]
    assert h == pytest.approx(4000.0, rel=1e-4) and e_m == pytest.approx(2000.0, rel=1e-4)


def test_network_generator_fits_the_closed_form_curve():
    trials = closed_form_trials()
    gen = NetworkGenerator().fit(trials)
    # A 1-input, 8-sigmoid network on log t: within 1 % RMS of the peak.
    assert rendering_error(gen, trials) < 0.01
    assert np.all(gen.normalised("marble", np.array([-1.0, 0.0])) == 0.0)


def test_on_held_out_persons_the_network_renders_within_three_percent():
    scene = load_scene("fingertip-7")
    scene = dataclasses.replace(scene, objects=scene.objects[::3], finger=dataclasses.replace(
        scene.finger, persons=3, trials_per_person=3, contact_duration_s=20.0))
    trials = finger_database(scene, np.random.default_rng(4))
    train = [t for t in trials if t.group != "person-2"]
    test = [t for t in trials if t.group == "person-2"]
    assert rendering_error(NetworkGenerator().fit(train), test) < 0.03


def test_unknown_material_is_refused():
    with pytest.raises(IdentificationError):
        NetworkGenerator().fit(closed_form_trials()).normalised("wood", np.array([1.0]))


@pytest.mark.parametrize("kind", [NetworkGenerator, ContactGenerator])
def test_generator_files_round_trip_and_refuse_damage(tmp_path, kind):
    gen = kind().fit(closed_form_trials())
    path = save_generator(gen, tmp_path / "gen.npz")
    back = load_generator(path)
    t = np.geomspace(1e-3, 60, 50)
    np.testing.assert_array_equal(back.normalised("marble", t), gen.normalised("marble", t))
    path.write_bytes(path.read_bytes()[:100])                     # cut short
    with pytest.raises(ModelFileError, match="gen.npz"):
        load_generator(path)
    with pytest.raises(ModelFileError, match="no such"):
        load_generator(tmp_path / "missing.npz")
    assert not list(tmp_path.glob(".*tmp"))                       # no temporary left


def test_network_below_the_first_fitted_time_ramps_from_zero():
    gen = NetworkGenerator().fit(closed_form_trials())
    t_first = gen.t_range_s_[0]
    at = gen.normalised("marble", np.array([0.0, t_first / 2, t_first]))
    assert at[0] == 0.0 and at[1] == pytest.approx(at[2] / 2, rel=1e-12)
    # Continuous at the first fitted time.
    assert gen.normalised("marble", t_first * (1 - 1e-9))[0] == pytest.approx(at[2], rel=1e-6)


def test_batched_evaluation_matches_one_by_one():
    trials = closed_form_trials() + [dataclasses.replace(t, material="wood", channels={
        "t_s": t.channels["t_s"], "heat_flux_W_m2": 0.5 * t.channels["heat_flux_W_m2"]})
        for t in closed_form_trials()]
    gen = NetworkGenerator().fit(trials)
    t = np.array([0.0, 0.003, 0.02, 0.5, 7.0])
    many = gen.normalised_many(["wood", "marble"], t)
    np.testing.assert_allclose(many[0], gen.normalised("wood", t), rtol=1e-12)
    np.testing.assert_allclose(many[1], gen.normalised("marble", t), rtol=1e-12)
    g, dg = mixture(gen, ["wood", "marble"], [0.25, 0.75], 0.5)
    assert g == pytest.approx(0.25 * many[0, 3] + 0.75 * many[1, 3], rel=1e-12)
    h = 1e-3
    slope = (mixture(gen, ["wood", "marble"], [0.25, 0.75], 0.5 + h)[0]
             - mixture(gen, ["wood", "marble"], [0.25, 0.75], 0.5 - h)[0]) / (2 * h)
    assert dg == pytest.approx(slope, rel=1e-3)


def test_display_flux_sign():
    # A finger warmer than the object loses heat to it, so the display pad
    # must take heat from the finger: pad -> finger flux is negative.
    gen = ContactGenerator().fit(closed_form_trials())
    assert np.all(display_flux(gen, "marble", np.array([0.1, 1.0]), 33.0, 24.0) < 0)
    assert np.all(display_flux(gen, "marble", np.array([0.1, 1.0]), 30.0, 40.0) > 0)


def test_a_sampled_generator_reproduces_the_network():
    from telethermal.render.sampled import SampledGenerator, sample_curves
    gen = NetworkGenerator().fit(closed_form_trials())
    wire = SampledGenerator(sample_curves(gen))
    t = np.concatenate([[0.0, 0.004], np.geomspace(0.01, 60, 500)])
    peak = np.abs(gen.normalised("marble", t)).max()
    assert np.max(np.abs(wire.normalised("marble", t) - gen.normalised("marble", t))) < 1e-4 * peak
    with pytest.raises(IdentificationError, match="ascending"):
        SampledGenerator({"x": {"t_s": [1.0, 1.0], "g_w_m2k": [1.0, 2.0]}})


def test_sampled_batched_evaluation_matches_one_by_one():
    from telethermal.render.sampled import SampledGenerator, sample_curves
    trials = closed_form_trials() + [dataclasses.replace(t, material="wood", channels={
        "t_s": t.channels["t_s"], "heat_flux_W_m2": 0.5 * t.channels["heat_flux_W_m2"]})
        for t in closed_form_trials()]
    wire = SampledGenerator(sample_curves(NetworkGenerator().fit(trials)))
    t = np.array([0.0, 0.003, 0.02, 0.5, 7.0, 100.0])
    many = wire.normalised_many(["wood", "marble"], t)
    np.testing.assert_allclose(many[0], wire.normalised("wood", t), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(many[1], wire.normalised("marble", t), rtol=1e-12, atol=1e-12)


_CURVE_T = np.geomspace(2e-3, 60.0, 64)
_CURVES = {f"m{k}": {"t_s": _CURVE_T.tolist(),
                     "g_w_m2k": (np.random.default_rng(k).normal(size=64) * 1e3).tolist()}
           for k in range(7)}


@settings(max_examples=300, deadline=None)
@given(names=st.lists(st.sampled_from(sorted(_CURVES)), min_size=1, max_size=7, unique=True),
       raw=st.lists(st.floats(0.01, 1.0), min_size=7, max_size=7),
       t_s=st.one_of(st.just(0.0), st.just(1e-4), st.floats(0.0, 3e-3), st.floats(0.0, 100.0),
                     st.sampled_from([1e-4, 2e-3, 60.0, 120.0])))
def test_the_display_mixture_gives_the_bits_of_the_batched_sum(names, raw, t_s):
    # The display's period evaluates the mixture in floats (weighted_sum); a
    # replay must give the same bits as the numpy form it replaced, so every
    # operation is the same in the same order. Exact equality, no tolerance.
    from telethermal.render.sampled import SampledGenerator
    wire = SampledGenerator(_CURVES)
    weights = [w / sum(raw[:len(names)]) for w in raw[:len(names)]]
    lo, hi = max(t_s - 1e-4, 0.0), t_s + 1e-4
    batched = np.sum(np.asarray(weights)[:, None] *
                     wire.normalised_many(names, np.array([t_s, lo, hi])), axis=0)
    # Bytes, not ==: 0.0 == -0.0, and a replay compares bits.
    fast = np.asarray(wire.weighted_sum(names, weights, (t_s, lo, hi)), dtype=np.float64)
    assert fast.tobytes() == batched.tobytes()
    g, dg = mixture(wire, names, weights, t_s)
    assert np.array([g, dg]).tobytes() == np.array(
        [batched[0], (batched[2] - batched[1]) / (hi - lo)]).tobytes()


def test_curves_that_do_not_share_knots_fall_back_to_the_batched_form():
    from telethermal.render.sampled import SampledGenerator
    odd = dict(_CURVES, odd={"t_s": np.geomspace(1e-3, 50.0, 10).tolist(),
                             "g_w_m2k": np.linspace(-1.0, -5.0, 10).tolist()})
    wire = SampledGenerator(odd)
    assert wire.weighted_sum(["m0", "odd"], [0.5, 0.5], (0.1, 0.2, 0.3)) is None
    g, _ = mixture(wire, ["m0", "odd"], [0.5, 0.5], 0.2)
    assert g == pytest.approx(0.5 * wire.normalised("m0", 0.2)[0] +
                              0.5 * wire.normalised("odd", 0.2)[0], rel=1e-12)
