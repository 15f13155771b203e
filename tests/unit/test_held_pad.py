"""The slave's sensing pad on its Peltier module (physics/held_pad.py) and
its use by the pad database's generator."""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest

from telethermal.control.junction import JunctionGains, JunctionLoop
from telethermal.data import generate
from telethermal.data.dataset import write_trials
from telethermal.data.generate import pad_database
from telethermal.physics.held_pad import (BatchJunctionLoop, HeldPad, hold_steady_state,
                                          module_step_batch, module_stored_j)
from telethermal.physics.scene import load_scene, pad_contact_model
from telethermal.physics.thermoelectric import (HBridge, ModuleState, ThermoelectricStack,
                                                default_driver)

SCENE = load_scene("fingertip-7")
PARAMS, SINK = SCENE.pad.module_params()
ROOM_C = SCENE.room_temp_c
#: 100 Hz samples from 0.5 s before to 2 s after contact, three onsets off the 1 ms grid.
ONSETS_S = np.array([0.0023, -0.0041, 0.0])
T_S = np.arange(-50, 201)[None, :] / 100.0 - ONSETS_S[:, None]
PAD_C = np.array([34.2, 33.9, 34.0])
OBJECT_C = np.array([24.2, 23.9, 24.0])
H_W_M2K = np.array([2700.0, 3300.0, 3000.0])


def _model(material: str):
    obj = next(o for o in SCENE.objects if o.material == material)
    return pad_contact_model(SCENE, obj)[0]


def _plant(material: str, driver=None) -> HeldPad:
    return HeldPad(_model(material), PARAMS, SINK, driver or default_driver(PARAMS), ROOM_C,
                   sensor_lag_s=SCENE.sensors.flux_lag_s)


def test_ideal_loop_reproduces_the_held_junction():
    """With no current limit and a loop told the layers' true load, the
    junction stays at its set point, and the contact is the ideal-junction
    solution (LayeredContact.solve with the back face held). Both are exact
    in time, so what is left is the junction's residual error: 1e-5 K moves
    the flux by about 1e-5 K times the pad's back conductance (~4e3
    W/m^2K), under 1e-6 of the ~3e4 W/m^2 peak; hence 1e-6 relative for
    the fluxes and 1e-5 K for the surface. Compared after contact only: the
    old solution's values before contact are its initial state seen through
    a contact that has not yet happened (see test_before_contact)."""
    driver = HBridge(1e6, 1e6)
    for material in ("aluminium", "wood"):
        model = _model(material)
        plant = HeldPad(model, PARAMS, SINK, driver, ROOM_C, sensor_lag_s=SCENE.sensors.flux_lag_s)
        held = plant.run(T_S, PAD_C, OBJECT_C, H_W_M2K, oracle_load=True)
        ideal = model.solve(T_S, PAD_C, OBJECT_C, H_W_M2K, back_temp_a_c=PAD_C,
                            sensor_lag_s=SCENE.sensors.flux_lag_s)
        after = T_S > 0
        peak = np.abs(ideal.flux_w_m2[after]).max()
        assert max(held.peak_droop_k.max(), held.peak_rise_k.max()) < 1e-5
        assert np.abs(held.flux_w_m2 - ideal.flux_w_m2)[after].max() < 1e-6 * peak
        assert np.abs(held.flux_sensed_w_m2 - ideal.flux_sensed_w_m2).max() < 1e-6 * peak
        assert np.abs(held.surface_temp_a_c - ideal.surface_temp_a_c)[after].max() < 1e-5


def test_before_contact():
    """Before contact the pad is uniform at its set point and in air: no
    flux, the surface at the set point, the module in its steady hold."""
    held = _plant("steel").run(T_S, PAD_C, OBJECT_C, H_W_M2K)
    before = T_S <= 0
    assert np.all(held.flux_w_m2[before] == 0) and np.all(held.flux_sensed_w_m2[before] == 0)
    np.testing.assert_array_equal(held.surface_temp_a_c, np.where(before, PAD_C[:, None],
                                                                  held.surface_temp_a_c))
    np.testing.assert_array_equal(held.junction_c[before], np.broadcast_to(PAD_C[:, None],
                                                                           T_S.shape)[before])


def test_steady_hold_stays_put():
    """The steady hold: nothing pumped out of the junction (Qc = 0), the hot
    side's heat crossing grease and sink to the room; one module step from
    it, with its current and no load, moves nothing (to rounding)."""
    cold = np.array([34.0, 14.0, 24.0])
    current, hot, sink = hold_steady_state(PARAMS, SINK, ROOM_C, cold)
    qc, qh, _ = PARAMS.heat_w(current, cold, hot)
    np.testing.assert_allclose(qc, 0.0, atol=1e-12)
    np.testing.assert_allclose(hot - sink, qh * SINK.interface_k_w, atol=1e-12)
    np.testing.assert_allclose(sink - ROOM_C, qh * SINK.to_air_k_w, atol=1e-12)
    state = np.stack([cold, hot, sink], axis=1)
    end, _, _ = module_step_batch(PARAMS, SINK, ROOM_C, state, current, 1e-3,
                                  np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(end, state, atol=1e-10)
    assert current[0] < 0 < current[1]         # heating above room, cooling below


def test_module_step_is_the_stacks():
    """The batch step is ThermoelectricStack.step, trial by trial (the same
    backward-Euler equations, solved in closed form in deviations from the
    room instead of by np.linalg.solve in kelvin): equal to 1e-9 K."""
    state = np.array([[34.0, 26.0, 25.0], [15.0, 30.0, 27.0], [24.0, 24.0, 24.0]])
    current = np.array([-2.0, 6.0, 8.5])
    load_a, load_b = np.array([3.0, -1.0, 0.0]), np.array([-0.2, -0.1, 0.0])
    end, power, air = module_step_batch(PARAMS, SINK, ROOM_C, state, current, 1e-3,
                                        load_a, load_b)
    for i in range(3):
        stack = ThermoelectricStack(PARAMS, SINK, ROOM_C, ModuleState(*state[i]))
        step = stack.step(current[i], 1e-3, load_a[i], load_b[i])
        np.testing.assert_allclose(end[i], [stack.state.cold_c, stack.state.hot_c,
                                            stack.state.sink_c], atol=1e-9)
        np.testing.assert_allclose([power[i], air[i]], [step.power_w, step.to_air_w],
                                   rtol=1e-9, atol=1e-9)


def test_batch_loop_is_the_junction_loop():
    """BatchJunctionLoop follows control/junction.py's JunctionLoop period by
    period, its default gains JunctionGains' own, saturation and anti-windup
    included (a 1 A limit makes it saturate)."""
    assert (BatchJunctionLoop(PARAMS, default_driver(PARAMS), 1).kp_a_k,
            BatchJunctionLoop(PARAMS, default_driver(PARAMS), 1).ki_a_ks) == \
        (JunctionGains().kp_a_k, JunctionGains().ki_a_ks)
    driver = HBridge(1.0, 5.0)
    batch = BatchJunctionLoop(PARAMS, driver, 3)
    scalar = [JunctionLoop(PARAMS, driver) for _ in range(3)]
    rng = np.random.default_rng(3)
    target = np.array([34.0, 14.0, 30.0])
    cut_any = False
    for _ in range(200):
        junction = target + rng.normal(0, 0.3, 3)
        hot = 25.0 + rng.normal(0, 1.0, 3)
        load = rng.normal(0, 2.0, 3)
        current, cut = batch.update(target, junction, hot, 1e-3, load)
        for i, loop in enumerate(scalar):
            out = loop.update(target[i], junction[i], hot[i], 1e-3, load[i])
            assert current[i] == pytest.approx(out.current_a, abs=1e-12)
            assert bool(cut[i]) == out.saturated
        cut_any |= bool(cut.any())
    assert cut_any
    np.testing.assert_allclose(batch.integral_a, [s.integral_a for s in scalar], atol=1e-12)


def test_one_pads_float_loop_is_the_batch_loop_bit_for_bit():
    """``update_one`` (a batch of one, on floats) gives the very bits of
    ``update`` on a batch of one: the same IEEE operations in the same
    order, so equality is exact. 20,000 draws on the datasheet's bridge
    (mostly inside its limits: every term of the request compared) and a
    1 A bridge (the cut path); a square by the C library's pow instead of a
    product, one ulp off now and then, makes it fail."""
    rng = np.random.default_rng(4)
    for driver, cut_share in ((default_driver(PARAMS), (0.0, 0.5)),
                              (HBridge(1.0, 5.0), (0.5, 1.0))):
        batch, one = (BatchJunctionLoop(PARAMS, driver, 1) for _ in range(2))
        n, cuts = 20_000, 0
        for _ in range(n):
            target = 30.0 + rng.normal(0, 8.0)
            junction, hot = target + rng.normal(0, 0.2), 28.0 + rng.normal(0, 2.0)
            load = rng.normal(0, 2.0)
            current, cut = batch.update(np.array([target]), np.array([junction]),
                                        np.array([hot]), 1e-3, np.array([load]))
            got = one.update_one(target, junction, hot, 1e-3, load)
            assert got == (current[0], cut[0]) and one.integral_a[0] == batch.integral_a[0]
            cuts += got[1]
        assert cut_share[0] < cuts / n < cut_share[1]
        assert one.saturated_periods[0] == batch.saturated_periods[0] == cuts


def test_a_loop_the_float_path_cannot_stand_for_is_stepped_as_a_batch():
    """The float path is the default loop's own: a subclass that changes
    ``update`` is used as it is, and a loop made for three trials on one
    is refused as before (numpy cannot broadcast it)."""

    class HalfAmpere(BatchJunctionLoop):
        def update(self, target_c, junction_c, hot_c, dt_s, load_w=0.0):
            current, cut = super().update(target_c, junction_c, hot_c, dt_s, load_w)
            return np.clip(current, -0.5, 0.5), cut

    plant = _plant("aluminium")
    held = plant.run(T_S[:1], PAD_C[:1], OBJECT_C[:1], H_W_M2K[:1],
                     loop=HalfAmpere(PARAMS, plant.driver, 1))
    assert held.peak_current_a[0] <= 0.5
    with pytest.raises(ValueError):
        plant.run(T_S[:1], PAD_C[:1], OBJECT_C[:1], H_W_M2K[:1],
                  loop=BatchJunctionLoop(PARAMS, plant.driver, 3))


@pytest.mark.parametrize("driver,oracle", [(None, False), (HBridge(0.3, 5.0), False),
                                           (HBridge(1e6, 1e6), True)],
                         ids=["datasheet", "saturating", "oracle-load"])
def test_one_trial_is_stepped_as_in_a_batch_bit_for_bit(driver, oracle):
    """A batch of one (a live touch) is stepped on floats; every output is
    the same trial's row of a batch of three, exactly (``==``, not a
    tolerance): the one-trial path is a speed-up, not another model."""
    plant = _plant("aluminium", driver)
    t_s = T_S[1]            # one time axis: as many periods in both runs (the energy sums)
    batch = plant.run(t_s, PAD_C, OBJECT_C, H_W_M2K, oracle_load=oracle)
    for i in (0, 2):
        one = plant.run(t_s, PAD_C[i:i + 1], OBJECT_C[i:i + 1], H_W_M2K[i:i + 1],
                        oracle_load=oracle)
        for field in dataclasses.fields(one):
            got, want = getattr(one, field.name), getattr(batch, field.name)
            if isinstance(got, np.ndarray) and got.shape[:1] == (1,):
                want = want[i:i + 1]
            np.testing.assert_array_equal(got, want, err_msg=field.name)
    if driver is not None and not oracle:
        assert one.saturated_periods[0] > 0          # the cut path was taken


@pytest.mark.parametrize("driver", [None, HBridge(0.3, 5.0)], ids=["datasheet", "saturating"])
def test_energy_balance_over_a_contact(driver):
    """Electrical energy - heat to the room = change of the heat stored in
    the module, its sink, the pad's layers and the object (the object's
    back is adiabatic): exact for the discrete scheme (backward Euler's
    balance is exact for its end-point heats; the layers' period-mean inflow
    is the exact integral of their heat flow), so to rounding: 1e-9 relative.
    Also when the current limit cuts the loop (a 0.3 A bridge)."""
    held = _plant("aluminium", driver).run(T_S, PAD_C, OBJECT_C, H_W_M2K)
    assert held.energy_balance_error().max() < 1e-9
    # The junction feeds the pad what the cold block takes: the layers and
    # the object gain heat, the module (and sink) lose it.
    assert np.all(held.layers_stored_j > 0) and np.all(held.module_stored_j < 0)
    if driver is not None:
        assert held.saturated_periods.min() > 0


def test_junction_droops_on_aluminium_and_recovers():
    """Aluminium pulls heat from a pad 10 K warmer: the junction is pulled
    down (droop > 0, not up), within the first 0.2 s (the flux's peak is
    at contact; the loop's PI answers at ~11 Hz), the
    loop's integral brings it back (within 1 % of the peak droop after 2 s),
    and a lower-effusivity wood pulls it less. A pad 10 K colder than the
    object: the junction is pushed up instead."""
    alu = _plant("aluminium").run(T_S, PAD_C, OBJECT_C, H_W_M2K)
    wood = _plant("wood").run(T_S, PAD_C, OBJECT_C, H_W_M2K)
    assert np.all(alu.peak_droop_k > 0) and np.all(alu.peak_rise_k < 0.1 * alu.peak_droop_k)
    assert np.all(alu.peak_droop_k > wood.peak_droop_k) and np.all(wood.peak_droop_k > 0)
    droop = alu.target_c[:, None] - alu.junction_c
    k_peak = droop.argmax(axis=1)
    assert np.all(T_S[np.arange(3), k_peak] < 0.2)
    assert np.all(np.abs(droop[:, -1]) < 0.01 * alu.peak_droop_k)
    cold = _plant("aluminium").run(T_S, OBJECT_C - 10.0, OBJECT_C, H_W_M2K)
    assert np.all(cold.peak_rise_k > 0) and np.all(cold.peak_droop_k < 0.1 * cold.peak_rise_k)


def test_current_within_imax():
    """The driver bounds the current at Imax: on a hard contact (a pad 30 K
    above a cold aluminium block, a perfect-ish contact) the loop asks for
    more than a 2 A bridge gives, and what flows never exceeds it; with the
    module's own Imax it never leaves the datasheet."""
    hard = dict(pad_c=PAD_C + 20.0, object_c=OBJECT_C, conductance_w_m2k=H_W_M2K * 30)
    small = _plant("aluminium", HBridge(2.0, 5.0)).run(T_S, **hard)
    assert small.saturated_periods.min() > 0
    assert np.abs(small.current_a).max() <= 2.0
    full = _plant("aluminium").run(T_S, **hard)
    assert np.abs(full.current_a).max() <= PARAMS.spec.imax_a
    assert full.over_current_periods.sum() == 0 and full.over_hot_periods.sum() == 0


def test_fingertip_pad_database_stays_within_the_datasheet():
    """Every fingertip-7 contact of the generator keeps the module inside
    its datasheet (else generation raises) and records its droop."""
    scene = dataclasses.replace(SCENE, pad=dataclasses.replace(SCENE.pad, trials_per_material=2))
    trials = pad_database(scene, np.random.default_rng(1))
    droop = {t.material: float(t.extra["junction_droop_k"]) for t in trials}
    current = [float(t.extra["module_peak_current_a"]) for t in trials]
    assert all(d > 0 for d in droop.values())
    assert droop["aluminium"] > droop["wood"]
    assert max(current) <= PARAMS.spec.imax_a


def _water_trials(name: str) -> list:
    scene = load_scene(name)
    scene = dataclasses.replace(scene, pad=dataclasses.replace(scene.pad, trials_per_material=2),
                                objects=scene.objects[:3])
    trials = pad_database(scene, np.random.default_rng(7))
    return trials


#: SHA-256 of the written database of _water_trials on main before the pad
#: had a module (452b52f), this venv's numpy/scipy: every water-pad scene
#: of the package (the old tree's code run with this venv, 2026-11-26).
WATER_DIGESTS = {
    "gripper-case-I-cnv": "c0ae6cca5bcb95e9b71952ecffbaabd3b5d67bf036ec03f774b0a4f0277b8119",
    "gripper-case-I-pro": "04594463c9cb99fb105dfeb7ec363bf883163d105e0a034c8a5f15fb1573e345",
    "gripper-case-II": "47e67a31d54f67179f6621990b02c31ac1aa3de7129ca71906ebd12e1eb90ea5",
    "gripper-case-III": "a5d144c438c8896d37a9f80266360e31883d8d64f3e61a1f35d1b0636d22d844",
    "gripper-case-IV": "c0fcbbb5f8a27094c31a7b7155d11f178740cfc4caf82b349c8ab700d09714ee",
    "gripper-case-V": "49722d82ebc42ee06db82d2a6015609c30f35d346004a4dd034dc71479a1d14f",
}


def test_every_water_pad_scene_is_pinned():
    from importlib import resources
    water = sorted(p.name[:-5] for p in resources.files("telethermal").joinpath("scenes").iterdir()
                   if p.name.endswith(".toml") and load_scene(p.name[:-5]).pad.kind == "water")
    assert water == sorted(WATER_DIGESTS)


@pytest.mark.parametrize("name", sorted(WATER_DIGESTS))
def test_water_pad_databases_unchanged(name, tmp_path, monkeypatch):
    """A water pad has no Peltier module: its databases never touch the
    held-pad plant and come out byte for byte as before it existed, solved
    to the scene's own tolerance as then (the touches are now solved finer:
    generate.TOUCH_TOLERANCE_FACTOR)."""
    def refuse(*_a, **_k):
        raise AssertionError("a water pad simulated on a Peltier module")

    monkeypatch.setattr(generate, "HeldPad", refuse)
    monkeypatch.setattr(generate, "TOUCH_TOLERANCE_FACTOR", 1.0)
    write_trials(tmp_path / "pad", _water_trials(name))
    h = hashlib.sha256()
    for p in sorted((tmp_path / "pad").rglob("*")):
        if p.is_file():
            h.update(p.relative_to(tmp_path).as_posix().encode())
            h.update(p.read_bytes())
    assert h.hexdigest() == WATER_DIGESTS[name]


def test_stored_heat_of_a_module_at_room_is_zero():
    assert module_stored_j(PARAMS, SINK, ROOM_C, np.full((1, 3), ROOM_C))[0] == 0.0
