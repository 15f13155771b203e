"""Flux generators against a closed form and on held-out persons."""

import dataclasses

import numpy as np
import pytest
from scipy.special import erfcx

from telethermal.data.dataset import Trial
from telethermal.data.generate import finger_database
from telethermal.errors import IdentificationError
from telethermal.physics.materials import get_material
from telethermal.physics.scene import load_scene
from telethermal.render.generator import ContactGenerator, NetworkGenerator, rendering_error

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
