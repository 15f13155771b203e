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


#: Why the two wood first-touch assertions below are expected to fail (issue
#: 43, open): on the display's junction loop for its bonded 0.1 s sensor
#: (current slewed at 100 A/s, the impedance horizon 0.2 s) wood's first touch
#: at the object lost to the static controller (seeds 1-4: impedance 0.255 /
#: 0.316 / 0.316 / 0.261 K against static 0.220 / 0.278 / 0.360 / 0.224 K) and
#: missed 0.3 K (seeds 2, 3). Where it is lost: before the decision the
#: impedance controller renders the posteriors' mean 1/e; the first,
#: metal-weighted posteriors (1/e 1.0e-3 against wood's 2.1e-3) send the
#: junction cold for ~25 ms, and the slower loop starts the junction up about
#: 50 ms after the static controller's (anchored on the pad's measured
#: surface) (docs/display-loop.md). Idling by the policy (the product's first
#: touch) impedance is ahead on wood (seeds 1-4: 0.81-0.98 K against
#: 0.85-1.08 K), pre-conditioned for wood far ahead (0.047 / 0.060 K against
#: 0.144 / 0.143 K), and ahead on the metals idling at the object (aluminium,
#: seeds 1-4, 1.51-1.89 K against 1.56-2.00 K): it stays the default. Strict:
#: a loop that meets them again makes these fail, to be turned back into
#: plain assertions.
WOOD_FIRST_TOUCH = pytest.mark.xfail(strict=True, reason=(
    "issue 43: on the bonded-sensor junction loop, wood's first touch at the object "
    "renders worse with impedance than static, and misses 0.3 K on seed 2"))


# Aluminium: with the slave's pad going down at the master's onset (the
# session rules, issue 26) the static controller starts its flux 31 ms
# later and loses more than impedance rendering (seed 1: 1.39 against
# 1.49 K, seed 2: 1.77 against 1.83 K); with the slave touching at the
# finger's contact the two tied at the pumping limit (1.32 against 1.32 K).
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


@WOOD_FIRST_TOUCH
def test_impedance_rendering_on_an_insulators_first_touch_beats_tracking_the_flux(models):
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
