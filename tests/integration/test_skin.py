"""Skin temperature in the in-process session, on the simulated clock: the
impedance controller (the default) against the flux PID with its static
feed-forward, on the same touches, a metal and an insulator."""

import pytest

from telethermal.physics.scene import load_scene
from telethermal.teleop.display_config import DisplayConfig
from telethermal.sim.inprocess import run_session

SCENE = load_scene("fingertip-7")
SEEDS = (1, 2)


@pytest.fixture(scope="module")
def models(trained_models):
    return trained_models.pair(SCENE, 0)


#: Each session's summary by its arguments: the same touch is asked for by
#: more than one test (wood and aluminium under impedance rendering, idling
#: at the object); the session is seeded on the simulated clock, so it is
#: run once and each test reads its summary.
_SUMMARIES = {}


def skin_rms(models, material, model, seed, idle="object", expected=None):
    # The controllers are compared from the same start: the pad idling at
    # the object (the idle policy's own effect is tested below).
    key = (id(models), material, model, seed, idle, expected)
    if key not in _SUMMARIES:
        _SUMMARIES[key] = _session(models, material, model, seed, idle, expected)
    s = _SUMMARIES[key]
    assert s["safety_events"] == 0
    return s["temp_rms_error_c"]


def _session(models, material, model, seed, idle, expected):
    return run_session(SCENE, material, *models, DisplayConfig(feedforward_model=model, idle=idle),
                       contact_s=1.5, seed=seed, expected_material=expected).summary


#: Why the wood first-touch assertion below is expected to fail (an earlier
#: issue's skin target, 0.3 K; issue 43's are on the policy's idle): idling
#: at the object, wood's first touch misses 0.3 K with either
#: controller (docs/display-loop.md, "Not done here"): the pad's own layers
#: draw a metal's flux in the first instants, before the slave has named
#: anything, and the junction loop (current slewed at 100 A/s, the
#: impedance horizon 0.2 s) takes tens of milliseconds to lift the pad.
#: Strict: a loop that meets it makes this fail, to be turned back into a
#: plain assertion.
WOOD_FIRST_TOUCH = pytest.mark.xfail(strict=True, reason=(
    "issue 43: idling at the object, wood's first touch misses 0.3 K on the "
    "bonded-sensor junction loop"))


# Aluminium: idling at the object, both controllers pump at the module's
# limit for much of the first touch, so the two are close (the margin is a
# few hundredths of a kelvin or less: docs/display-loop.md).
def test_impedance_rendering_brings_the_skin_closer_than_tracking_the_flux_on_a_metal(models):
    # Same operator, object and slave trial for both controllers: the
    # impedance controller lets the operator's own skin and contact set the
    # flux, so on every touch the skin is closer to direct contact.
    for seed in SEEDS:
        assert skin_rms(models, "aluminium", "impedance", seed) < \
            skin_rms(models, "aluminium", "static", seed)


def test_impedance_rendering_on_an_insulator_pre_conditioned_beats_tracking_the_flux(models):
    # A repeated touch (object memory): closer on every seed.
    for seed in SEEDS:
        assert skin_rms(models, "wood", "impedance", seed, "policy", "wood") < \
            skin_rms(models, "wood", "static", seed, "policy", "wood")


def test_impedance_rendering_on_an_insulators_first_touch_beats_tracking_the_flux(models):
    # Idling at the object (the pad behaves as a conductor at first), each
    # controller hands over from the held pad to rendering when the first
    # posterior comes; the impedance controller is closer on every seed.
    for seed in SEEDS:
        assert skin_rms(models, "wood", "impedance", seed) < \
            skin_rms(models, "wood", "static", seed)


def test_an_insulator_meets_the_skin_target_when_pre_conditioned(models):
    # The target, 0.3 K RMS over the contact, on wood pre-conditioned
    # for it (a repeated touch, object memory).
    for seed in SEEDS:
        assert skin_rms(models, "wood", "impedance", seed, "policy", "wood") <= 0.3


@WOOD_FIRST_TOUCH
def test_an_insulator_meets_the_skin_target_on_its_first_touch(models):
    for seed in SEEDS:
        assert skin_rms(models, "wood", "impedance", seed) <= 0.3


def test_the_idle_policy_buys_the_worst_material_its_first_touch(models):
    # For an unknown object the pad idles by the minimax policy (4.3 K under
    # the object on fingertip-7): aluminium, the worst material idling at
    # the object, gains on every seed; wood pays part of it back, and the
    # worse of the two stays better than aluminium idling at the object.
    for seed in SEEDS:
        at_object = skin_rms(models, "aluminium", "impedance", seed)
        aluminium = skin_rms(models, "aluminium", "impedance", seed, "policy")
        wood = skin_rms(models, "wood", "impedance", seed, "policy")
        assert aluminium < at_object
        assert max(aluminium, wood) < at_object
