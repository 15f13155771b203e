"""The display's floor with a real Peltier module (control/preconditioning.py):
the plant against the simulator's own display plant, the bounded solve
against the unbounded least squares, the module's limits on the nonlinear
module, monotonicity in Qmax, and bad input."""

import numpy as np
import pytest

from telethermal.control import preconditioning as pc

from telethermal.control import display_floor
from telethermal.sim.plant import DisplayPlant
from telethermal.errors import ControlError, UnknownMaterialError
from telethermal.physics.scene import load_scene
from telethermal.sim.touch import display_model


@pytest.fixture(scope="module")
def scene():
    return load_scene("fingertip-7")


@pytest.fixture(scope="module")
def touch(scene):
    return display_floor.nominal_touch(scene)


def test_junction_plant_matches_display_plant(scene, touch):
    """Physics: with the junction's temperature from the junction-node model
    imposed on the display plant (isothermal back, exact per step) at a fine
    step, the skin's surface temperature is the same: the two share cells
    and conductances, and the node only adds its capacity and input."""
    hw = display_floor.hardware(scene)
    dt, contact_s = 1e-4, 0.3
    plant = display_floor.JunctionPlant(hw, touch, contact_s, dt)
    q = np.where(np.arange(plant.n) * dt < 0.05, -4e4, 1.5e4)     # W/m^2, two levels
    idle = 24.0
    free_j, free_s = plant.free(idle)
    junction = free_j + np.convolve(plant.junction_pulse, q)[:plant.n]
    skin = free_s + np.convolve(plant.skin_pulse, q)[:plant.n]
    ref = DisplayPlant(display_model(hw.pad_layers, round(contact_s + 1.0, 3), 1e-3), idle,
                       touch.finger_c, touch.conductance_w_m2k, dt)
    start = np.r_[idle, junction[:-1]]
    ref_skin = np.array([ref.step(0.5 * (a + b)).skin_surface_c
                         for a, b in zip(start, junction)])
    # The input moved the junction by far more than the tolerance below
    # (1.9 K: 950 times it), so a wrong skin would show.
    assert np.ptp(junction) > 500 * 2e-3
    np.testing.assert_allclose(ref_skin, skin, atol=2e-3)


def test_bounded_equals_unbounded_where_limits_do_not_bind(scene, touch):
    """With a module 1e10 times stronger the bounds never bind (the unbounded
    optimum asks ~1e13 W/m^2 through the 0.8 mm plate: the inverse through the
    film is ill-conditioned): the bounded
    solve reaches the unconstrained least squares' error (to 1e-6 K)."""
    hw = display_floor.hardware(scene, qmax_scale=1e10)
    plant = display_floor.JunctionPlant(hw, touch, contact_s=0.4)
    target = display_floor.direct_skin_c(scene, "aluminium", touch, plant.n)
    free_j, free_s = plant.free(touch.object_c)
    lo, hi = display_floor.pump_bounds_w_m2(hw, np.full(plant.n, touch.object_c), touch.object_c)
    q = display_floor.bounded_fit(plant.skin_matrix, target - free_s, lo, hi)
    q_free = np.linalg.lstsq(plant.skin_matrix, target - free_s, rcond=None)[0]
    assert np.all(np.abs(q_free) < 0.5 * np.minimum(-lo, hi))    # the limits do not bind
    bounded = np.sqrt(np.mean((free_s + plant.skin_matrix @ q - target) ** 2))
    free = np.sqrt(np.mean((free_s + plant.skin_matrix @ q_free - target) ** 2))
    assert bounded == pytest.approx(free, abs=1e-6)


def test_limits_hold_on_the_nonlinear_module(scene, touch):
    """The trajectory's realising current on ThermoelectricStack stays within
    Imax (0 violations), the module binds (peak current near Imax on
    aluminium), and the nonlinear skin follows the linear one."""
    hw = display_floor.hardware(scene)
    plant = display_floor.JunctionPlant(hw, touch, contact_s=0.5)
    target = display_floor.direct_skin_c(scene, "aluminium", touch, plant.n)
    floor = display_floor.best_touch(hw, plant, target, touch.object_c)
    v = floor.verified
    assert v.violations == 0
    assert np.abs(v.current_a).max() <= hw.params.spec.imax_a * (1 + 1e-9)
    assert np.abs(v.current_a).max() > 0.9 * hw.params.spec.imax_a
    lo, hi = display_floor.pump_bounds_w_m2(hw, v.cold_c, v.hot_c)
    assert np.all((floor.q_j_w_m2 >= lo) & (floor.q_j_w_m2 <= hi))
    nonlinear = np.sqrt(np.mean((v.skin_c - target) ** 2))
    assert nonlinear == pytest.approx(floor.skin_rms_k, abs=0.02)


def test_larger_qmax_never_raises_the_floor(scene, touch):
    """Scaling Imax and Qmax together scales Qc at every temperature, so the
    admissible set only grows: the floor cannot rise (1e-3 K: solver)."""
    floors = []
    for scale in (0.5, 1.0, 2.0, 4.0):
        hw = display_floor.hardware(scene, qmax_scale=scale)
        plant = display_floor.JunctionPlant(hw, touch, contact_s=0.5)
        target = display_floor.direct_skin_c(scene, "aluminium", touch, plant.n)
        floors.append(display_floor.best_touch(hw, plant, target, touch.object_c,
                                    nonlinear=False).skin_rms_k)
    assert np.all(np.diff(floors) <= 1e-3), floors
    assert floors[-1] < floors[0]


def test_unknown_material_is_named(scene, touch):
    with pytest.raises(UnknownMaterialError, match="unobtainium"):
        display_floor.direct_skin_c(scene, "unobtainium", touch, 10)
    with pytest.raises(UnknownMaterialError, match="unobtainium"):
        pc.idle_for(scene, "unobtainium", 24.0, 33.0)
    with pytest.raises(ControlError, match="qmax_scale"):
        display_floor.hardware(scene, qmax_scale=0.0)


def test_idle_for_applies_the_rule(scene, monkeypatch):
    """The product's call: the table's fraction of the finger-object
    difference, clipped to the skin band (the table itself stubbed)."""
    table = {"minimax": {"fraction_of_finger_minus_object": -0.5},
             "preconditioned": {m: {"fraction_of_finger_minus_object": -2.0}
                                for m in scene.materials}, "groups": {}}
    monkeypatch.setattr(pc, "scene_policy", lambda scene: table)
    assert pc.idle_for(scene, None, 24.0, 33.0) == pytest.approx(19.5)
    assert pc.idle_for(scene, "aluminium", 24.0, 33.0) == pytest.approx(15.0)   # clipped
