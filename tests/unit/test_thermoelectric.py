"""The Peltier module on its heat sink: energy balance, the datasheet's
steady states, the H-bridge's limits, the junction loop's anti-windup, the
display plant driven by current, and a heat sink warming over a session."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.control.junction import JunctionLoop
from telethermal.sim.plant import DisplayPlant
from telethermal.errors import ControlError, SceneError
from telethermal.physics.scene import load_scene
from telethermal.physics.thermoelectric import (
    DEFAULT_HEAT_SINK, DEFAULT_MODULE, HBridge, ModuleState, SinkParams, ThermoelectricStack,
    default_driver, derive, get_heat_sink, get_module, hold_current_a, sink_params)
from telethermal.sim.touch import display_model

SPEC = get_module(DEFAULT_MODULE)
PARAMS = derive(SPEC)
SINK = sink_params(get_heat_sink(DEFAULT_HEAT_SINK), SPEC)


def pinned_sink(temp_c):
    """A sink that holds the hot side at the room's temperature (a huge
    capacity, negligible resistances): the datasheet's test condition."""
    return SinkParams(SINK.spec, 1e12, 1e-9, 1e-9), temp_c


@settings(max_examples=200, deadline=None)
@given(st.floats(-8.5, 8.5), st.floats(-20, 60), st.floats(-20, 80))
def test_electrical_power_is_heat_rejected_less_heat_pumped(current, cold, hot):
    qc, qh, power = PARAMS.heat_w(current, cold, hot)
    scale = max(abs(qc), abs(qh), abs(power), 1e-12)
    assert abs((qh - qc) - power) <= 1e-9 * scale
    assert power == pytest.approx(current * float(PARAMS.voltage_v(current, cold, hot)),
                                  rel=1e-12, abs=1e-12)


def test_steady_states_meet_the_datasheet():
    # dTmax at Qc = 0, I = Imax: the cold side with no load, the hot side
    # held at the datasheet's Th, stepped to steady state.
    sink, th = pinned_sink(SPEC.th_c)
    stack = ThermoelectricStack(PARAMS, sink, th, ModuleState(th, th, th))
    for _ in range(4000):
        stack.step(SPEC.imax_a, 0.01, 0.0, 0.0)
    dt_k = stack.state.hot_c - stack.state.cold_c
    assert dt_k == pytest.approx(SPEC.dtmax_k, rel=0.02)
    # Qmax at dT = 0, I = Imax: a load pinning the cold side at Th; the heat
    # it must supply is what the module pumps.
    stack = ThermoelectricStack(PARAMS, sink, th, ModuleState(th, th, th))
    pin = 1e6                        # W/K
    for _ in range(200):
        stack.step(SPEC.imax_a, 0.01, pin * th, -pin)
    load_w = pin * (th - stack.state.cold_c)
    assert load_w == pytest.approx(SPEC.qmax_w, rel=0.02)
    # The derived resistance against the datasheet's (+-10 %).
    assert PARAMS.resistance_ohm == pytest.approx(SPEC.resistance_ohm, rel=0.10)


def test_the_stack_conserves_energy_over_a_touch():
    # Display plant + module + sink, driven by a current that cools then
    # heats: the change of stored heat (layers, finger, junctions, sink)
    # equals electrical energy less heat to the room, to 1e-9 relative.
    scene = load_scene("fingertip-7")
    model = display_model(tuple(scene.pad.layers), 3.0, 1e-3)
    area = SPEC.area_m2
    stack = ThermoelectricStack(PARAMS, SINK, 24.0, ModuleState(24.0, 24.0, 24.0))
    plant = DisplayPlant(model, 24.0, 33.0, 3000.0, 1e-3, 0.15)
    before = plant.stored_j_m2() * area + stack.stored_j()
    energy = 0.0
    for k in range(2000):
        _, heat = plant.step_current(stack, 4.0 if k < 1000 else -6.0, area)
        energy += 1e-3 * (heat.power_w - heat.to_air_w)
    after = plant.stored_j_m2() * area + stack.stored_j()
    assert after - before == pytest.approx(energy, rel=1e-9)


def test_the_h_bridge_bounds_current_and_voltage():
    driver = HBridge(current_limit_a=8.5, supply_v=5.0)
    assert driver.limit(PARAMS, 20.0, 20.0, 30.0) == (8.5, True)
    assert driver.limit(PARAMS, -20.0, 20.0, 30.0) == (-8.5, True)
    assert driver.limit(PARAMS, 1.0, 20.0, 30.0) == (1.0, False)
    low = HBridge(current_limit_a=8.5, supply_v=1.0)
    current, cut = low.limit(PARAMS, 8.5, 0.0, 60.0)
    assert cut and abs(float(PARAMS.voltage_v(current, 0.0, 60.0))) == pytest.approx(1.0)


def test_a_current_that_is_not_finite_is_refused():
    scene = load_scene("fingertip-7")
    plant = DisplayPlant(display_model(tuple(scene.pad.layers), 1.0, 1e-3), 24.0, 33.0,
                         3000.0, 1e-3)
    stack = ThermoelectricStack(PARAMS, SINK, 24.0, ModuleState(24.0, 24.0, 24.0))
    for bad in (math.nan, math.inf, -math.inf):
        with pytest.raises(ControlError, match="finite"):
            plant.step_current(stack, bad, SPEC.area_m2)
    loop = JunctionLoop(PARAMS, default_driver(PARAMS))
    assert loop.update(20.0, math.nan, 24.0, 1e-3).current_a == 0.0
    assert loop.update(math.inf, 24.0, 24.0, 1e-3).current_a == 0.0


def test_hold_current_pumps_what_it_is_asked():
    current = hold_current_a(PARAMS, 15.0, 30.0, 2.0)
    qc, _, _ = PARAMS.heat_w(current, 15.0, 30.0)
    assert qc == pytest.approx(2.0, rel=1e-9)


def lumped_pad(stack, current, heat_j_k, load_w, dt):
    """The pad as one mass on the junction, with ``load_w`` flowing into it."""
    c = heat_j_k / dt
    return stack.step(current, dt, c * stack.state.cold_c + load_w, -c)


def test_saturation_and_anti_windup():
    # Ask for a junction the module cannot reach (-60 C), for 3 s: the
    # current sits at Imax, the integral does not wind up, and once the
    # target is reachable again (20 C) the junction gets there without
    # the overshoot a wound-up integral would give.
    stack = ThermoelectricStack(PARAMS, SINK, 24.0, ModuleState(24.0, 24.0, 24.0))
    loop, dt = JunctionLoop(PARAMS, default_driver(PARAMS)), 1e-3
    for _ in range(3000):
        out = loop.update(-60.0, stack.state.cold_c, stack.state.sink_c, dt)
        lumped_pad(stack, out.current_a, 0.3, 0.0, dt)
    assert out.saturated and out.current_a == pytest.approx(SPEC.imax_a)
    assert abs(loop.integral_a) < 2 * SPEC.imax_a
    temps = []
    for _ in range(3000):
        out = loop.update(20.0, stack.state.cold_c, stack.state.sink_c, dt)
        lumped_pad(stack, out.current_a, 0.3, 0.0, dt)
        temps.append(stack.state.cold_c)
    assert temps[-1] == pytest.approx(20.0, abs=0.05)
    assert max(temps) <= 20.0 + 1.0


def test_the_heat_sink_warms_over_ten_minutes_of_touches():
    # Ten minutes of touches on a cold object: the pad held 8 K under the
    # room while a finger's 3 W flows in for 3 s of every 6. The sink warms
    # (it rejects pumped heat plus Joule heat through 1 K/W), and the loop
    # holds the junction through it: 3 W at 8 K under the room is well
    # inside what the module pumps (Qmax 18.8 W at dT = 0), so tracking is
    # asserted outright, within 0.5 K once the first touch has settled,
    # with the current within Imax and the hot side under its datasheet
    # limit at every period.
    stack = ThermoelectricStack(PARAMS, SINK, 24.0, ModuleState(16.0, 24.0, 24.0))
    loop, dt = JunctionLoop(PARAMS, default_driver(PARAMS)), 0.01
    errors, sinks, hots, currents = [], [], [], []
    for k in range(int(600 / dt)):
        touching = (k * dt) % 6.0 < 3.0
        load = 3.0 if touching else 0.0
        out = loop.update(16.0, stack.state.cold_c, stack.state.sink_c, dt, load)
        lumped_pad(stack, out.current_a, 0.3, load, dt)
        if k * dt > 10.0:
            errors.append(abs(stack.state.cold_c - 16.0))
        sinks.append(stack.state.sink_c)
        hots.append(stack.state.hot_c)
        currents.append(abs(out.current_a))
    assert sinks[-1] > 24.0 + 1.0                    # warmed by more than 1 K
    assert sinks[-1] > sinks[len(sinks) // 2]        # and still warming at 5 minutes
    assert max(errors) < 0.5
    assert loop.saturated_periods == 0
    assert max(currents) <= SPEC.imax_a
    assert max(hots) < SPEC.hot_side_max_c


def test_unknown_module_or_sink_is_a_clear_error():
    with pytest.raises(SceneError, match="unknown thermoelectric module 'nope'"):
        get_module("nope")
    with pytest.raises(SceneError, match="unknown heat sink 'nope'"):
        get_heat_sink("nope")


def test_a_scene_names_its_module_or_gets_the_default(tmp_path):
    assert load_scene("fingertip-7").pad.module == DEFAULT_MODULE
    from importlib import resources
    src = resources.files("telethermal").joinpath("scenes/fingertip-7.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(src.replace('kind = "peltier"', 'kind = "peltier"\nmodule = "TEC-X"'))
    with pytest.raises(SceneError, match=r"\[pad\].*'module' = 'TEC-X'"):
        load_scene(bad)
