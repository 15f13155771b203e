"""Skin temperature in the in-process session, on the simulated clock: the
impedance controller (the default) against the flux PID with its static
feed-forward, on the same touches, a metal and an insulator."""

import pytest

from telethermal.physics.scene import load_scene
from telethermal.teleop.master import DisplayConfig
from telethermal.teleop.models import train_generator, train_identifier
from telethermal.teleop.run import run_session

SCENE = load_scene("fingertip-7")
SEEDS = (1, 2)


@pytest.fixture(scope="module")
def models():
    return train_identifier(SCENE, 0), train_generator(SCENE, 0)


def skin_rms(models, material, model, seed):
    s = run_session(SCENE, material, *models, DisplayConfig(feedforward_model=model),
                    contact_s=1.5, seed=seed).summary
    assert s["safety_events"] == 0
    return s["temp_rms_error_c"]


# Aluminium: with the slave's pad going down at the master's onset (the
# session rules, issue 26) the static controller starts its flux 31 ms
# later and loses more than impedance rendering (seed 1: 1.39 against
# 1.49 K, seed 2: 1.77 against 1.83 K); with the slave touching at the
# finger's contact the two tied at the pumping limit (1.32 against 1.32 K).
@pytest.mark.parametrize("material", ["aluminium", "wood"])
def test_impedance_rendering_brings_the_skin_closer_than_tracking_the_flux(models, material):
    # Same operator, object and slave trial for both controllers: the
    # impedance controller lets the operator's own skin and contact set the
    # flux, so on every touch the skin is closer to direct contact.
    for seed in SEEDS:
        assert skin_rms(models, material, "impedance", seed) < \
            skin_rms(models, material, "static", seed)


def test_an_insulator_meets_the_skin_target(models):
    # The target, 0.3 K RMS over the contact. (Metals do not: with the
    # junction held inside the 15-43 C band and the pad at the object's
    # temperature at contact, no controller draws their first 0.3 s of flux;
    # the README's "Skin temperature" gives that floor.)
    for seed in SEEDS:
        assert skin_rms(models, "wood", "impedance", seed) <= 0.3
