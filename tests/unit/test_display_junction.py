"""The display's junction loop on its bonded sensor (control/junction.py,
control/junction_design.py): the design's margins on its own model, the
closed loop on the module with the sensor's lag (simulated clock), and the
limits counted on the request before any clamp."""

import dataclasses
import math

import numpy as np
import pytest

from telethermal.control.current_quality import ripple_rms_a, sign_reversals
from telethermal.control.junction import DisplayJunctionLoop, JunctionGains
from telethermal.control.junction_design import (PHASE_MARGIN_DEG, design_gains, loop_margins,
                                                 plant_model)
from telethermal.control.junction_probe import PROBE_K, PROBE_LAGS, PROBE_MIN_S
from telethermal.physics.scene import load_scene
from telethermal.physics.thermoelectric import (DEFAULT_JUNCTION_SENSOR, HBridge, ModuleState,
                                                ThermoelectricStack, default_driver,
                                                get_junction_sensor)

SCENE = load_scene("fingertip-7")
PARAMS, SINK = SCENE.pad.module_params()
SENSOR = get_junction_sensor(DEFAULT_JUNCTION_SENSOR)
DT = 0.002
MODEL = plant_model(PARAMS, SCENE.pad.layers, SCENE.pad.area_m2, 0.0, SENSOR.tau_s, DT)


def probe_current_a(start_c=24.0):
    """The re-arm probe's current in closed form from the configuration:
    PROBE_K C / (S T duration), duration PROBE_LAGS sensor lags (at least
    PROBE_MIN_S)."""
    probe_s = max(PROBE_LAGS * SENSOR.tau_s, PROBE_MIN_S)
    return PROBE_K * MODEL.heat_j_k / (PARAMS.seebeck_v_k * (start_c + 273.15) * probe_s)


def designed_loop(driver=None, model=MODEL):
    kp, ki, _ = design_gains(model)
    return DisplayJunctionLoop(PARAMS, driver or default_driver(PARAMS), model,
                               JunctionGains(kp, ki))


def test_the_sensor_is_a_part_with_a_lag_as_mounted():
    """The chip's bonded time constant from its size and the bond (the
    table's derivation: (rho c) h d / k), not 0."""
    assert SENSOR.tau_s == pytest.approx(3.6e6 * 0.5e-3 * 50e-6 / 0.9, rel=0.05)
    assert SENSOR.bias_limit_k > 0 and SENSOR.noise_k > 0 and SENSOR.lsb_k > 0
    assert "NTCG103JF103F" in SENSOR.source


def test_the_design_meets_its_phase_margin_on_its_own_model():
    """python-control's margin on the design model equals the margin the
    analytic design asked for (to 0.5 deg: the Pade delay against the exact
    one, at a crossover of 5 rad/s and a 2 ms delay, differs by < 1e-6 rad),
    and the loop stays stable with the sensor's lag at half, twice and ten
    times its stated value. Ten times is the issue's hard case: its claim is
    stability (a positive phase margin and a gain margin above 1; the 0.8 mm
    plate's heavier junction leaves it 10.0 deg, checked against the
    analytic margin at that crossover), not a designed margin."""
    kp, ki, wc = design_gains(MODEL)
    m = loop_margins(MODEL, kp, ki)
    assert m.phase_margin_deg == pytest.approx(PHASE_MARGIN_DEG, abs=0.5)
    assert m.crossover_rad_s == pytest.approx(wc, rel=1e-3)
    # The stated design (docs/display-loop.md): crossover 3.66 rad/s, bandwidth 0.93 Hz.
    assert 0.5 < m.bandwidth_hz < 3.0
    assert loop_margins(MODEL, kp, ki, 0.5 * SENSOR.tau_s).phase_margin_deg > PHASE_MARGIN_DEG
    assert loop_margins(MODEL, kp, ki, 2 * SENSOR.tau_s).phase_margin_deg > 40.0
    tenfold = loop_margins(MODEL, kp, ki, 10 * SENSOR.tau_s)
    assert tenfold.phase_margin_deg > 0.0 and tenfold.gain_margin > 1.0
    # ... and python-control's margin there is the analytic one (the loop's
    # phase at the crossover where |L| = 1, by bisection), to 0.5 deg.
    slow = dataclasses.replace(MODEL, sensor_tau_s=10 * SENSOR.tau_s)
    wi = ki / kp

    def gain(w):
        return kp * math.hypot(1.0, wi / w) * slow.b_k_as / math.hypot(w, slow.a_per_s) \
            / math.hypot(1.0, w * slow.sensor_tau_s)

    lo, hi = 1e-3, 1e3
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if gain(mid) > 1.0 else (lo, mid)
    phase = math.degrees(math.atan(lo / wi) - math.pi / 2 - math.atan(lo / slow.a_per_s)
                         - math.atan(lo * slow.sensor_tau_s) - lo * slow.delay_s)
    assert tenfold.phase_margin_deg == pytest.approx(180.0 + phase, abs=0.5)


class PadInAir:
    """The module under the pad's layers in air (lumped with the junction,
    as DisplayTouch idles them), read through the bonded sensor's lag, on
    the simulated clock (physics steps of DT)."""

    def __init__(self, start_c, lag_s, layers_heat_scale=1.0, params=PARAMS):
        self.stack = ThermoelectricStack(params, SINK, SCENE.room_temp_c,
                                         ModuleState(start_c, SCENE.room_temp_c,
                                                     SCENE.room_temp_c))
        self.heat = layers_heat_scale * SCENE.pad.area_m2 * sum(
            layer.material.volumetric_heat_j_m3k * layer.thickness_m for layer in SCENE.pad.layers)
        self.sensed_c, self.lag_s = start_c, lag_s

    def step(self, current_a):
        c = self.heat / DT
        self.stack.step(current_a, DT, c * self.stack.state.cold_c, -c)
        self.sensed_c += -math.expm1(-DT / self.lag_s) * (self.stack.state.cold_c - self.sensed_c)


def run_step(lag_scale, seconds=4.0, start_c=24.0, target_c=14.0, stopped=None):
    """The step on the pad in air; ``stopped`` (a list), if given, gets the
    loop's stop flag after each period."""
    pad, loop = PadInAir(start_c, SENSOR.tau_s * lag_scale), designed_loop()
    true, current = [], []
    for _ in range(int(seconds / DT)):
        out = loop.update(target_c, pad.sensed_c, pad.stack.state.sink_c, DT)
        pad.step(out.current_a)
        true.append(pad.stack.state.cold_c)
        current.append(out.current_a)
        if stopped is not None:
            stopped.append(loop.stopped)
    return np.array(true), np.array(current), loop


def test_a_10_k_step_with_the_sensors_lag_settles_with_little_overshoot():
    """A 10 K step down of the junction target, the sensor at its stated lag:
    the true junction reaches the target (within 0.1 K from 2 s on) and
    overshoots it by under 5 % of the step (measured 0.16 K, 2 %: the
    smoothed target moves no faster than the module can follow, the
    feed-forward moves the junction, the PI only trims)."""
    true, current, loop = run_step(1.0)
    assert 14.0 - true.min() < 0.5
    assert abs(true[int(2.0 / DT):] - 14.0).max() < 0.1
    assert np.abs(current).max() <= PARAMS.spec.imax_a and not loop.stopped


@pytest.mark.parametrize("lag_scale", [0.5, 2.0])
def test_a_sensor_off_its_datasheet_settles(lag_scale):
    """The sensor lagging half or twice its stated value: the loop settles
    (from 2 s on within 0.1 K; overshoot measured 0.03 K and 0.97 K), never
    stopped, no sign reversal in the last seconds."""
    true, current, loop = run_step(lag_scale, seconds=6.0)
    assert abs(true[int(2.0 / DT):] - 14.0).max() < 0.1
    assert not loop.stopped
    assert sign_reversals(current[int(2.0 / DT):]) == 0


def test_a_sensor_ten_times_slower_stops_the_module_never_a_limit_cycle():
    """The sensor lagging ten times its stated value (a debonded chip) from
    the start, with a 10 K step of the target at t = 0: the sensor and its
    model disagree by over 3 K for 0.5 s and the loop stops within 1.5 s of
    the step (the stop taken from the loop's own flag, not from the
    current; measured 0.94 s); 0 A from the stop on. Before the stop the
    current does sit at Imax, one-sided (measured 379 periods, 0.18-0.94 s,
    while the slow sensor hides the cooling): one run at the limit, no sign
    reversal, so never a limit cycle. The run is bounded by what the step
    itself needs at Imax, in closed form from the configuration: the
    junction's heat capacity through the 10 K step over the module's net
    cooling at Imax at the target, S T I - I^2 R / 2 - K (T_sink - T) (0.91
    s); a run past it would be Imax held after the step no longer needs it
    (windup)."""
    flags = []
    true, current, loop = run_step(10.0, seconds=8.0, stopped=flags)
    assert loop.stopped
    stop = int(np.argmax(flags))               # the first period the loop is stopped
    assert flags[stop] and stop * DT < 1.5
    at_limit = np.flatnonzero(np.abs(current[:stop]) >= 0.999 * PARAMS.spec.imax_a)
    assert len(at_limit) == 0 or np.all(np.diff(at_limit) == 1)   # one run, not a cycle
    net_cooling_w = (PARAMS.seebeck_v_k * (14.0 + 273.15) * PARAMS.spec.imax_a
                     - 0.5 * PARAMS.spec.imax_a ** 2 * PARAMS.resistance_ohm
                     - PARAMS.conductance_w_k * (SCENE.room_temp_c - 14.0))
    assert len(at_limit) * DT <= MODEL.heat_j_k * 10.0 / net_cooling_w
    assert sign_reversals(current[:stop]) == 0
    assert np.all(current[stop:] == 0.0)
    # After the stop the junction relaxes toward the sink, monotonically.
    assert np.all(np.diff(true[stop + 50:]) >= -1e-9)


def test_a_request_of_three_times_imax_is_counted_before_the_clamp():
    """Holding 10 C, the sensor suddenly reads 40 K over the target: the PI
    asks for far over Imax (kp 0.85 A/K x 40 K); the driver sends Imax, and
    the count says so (largest request >= 3 Imax)."""
    loop = designed_loop()
    imax = PARAMS.spec.imax_a
    for _ in range(10):
        loop.update(10.0, 10.0, 30.0, DT)
    assert loop.limits.requested_over_imax_periods == 0
    cut_before = loop.limits.saturated_periods
    outs = [loop.update(10.0, 50.0, 30.0, DT) for _ in range(10)]
    assert all(abs(o.current_a) <= imax for o in outs)
    assert loop.limits.requested_over_imax_periods == 10
    assert loop.limits.largest_request_a >= 3 * imax
    assert loop.limits.voltage_over_supply_periods == 10      # 3 Imax R alone is 8 V
    assert loop.limits.saturated_periods - cut_before == 10


def test_the_voltage_limit_binds_on_a_4_v_supply():
    """A driver rated 15 A on a 4 V supply, the shipped module (R 0.32 ohm):
    holding 15 C, the sensor then reads 25 K over the target; the current
    the driver can force is ``(4 V - S (Th - Tc)) / R`` (12.2 A here),
    under its own limit: what flows sits on the supply, and the request's
    voltage is counted over it. (With the driver's limit at Imax, 8.5 A,
    a 4 V supply binds only when ``S (Th - Tc)`` exceeds 1.25 V, a 105 K
    difference: the current limit binds first.)"""
    driver = HBridge(15.0, 4.0)
    loop = designed_loop(driver)
    hot = 45.0
    for _ in range(10):
        loop.update(15.0, 15.0, hot, DT)
    for _ in range(100):
        out = loop.update(15.0, 40.0, hot, DT)
    bound = (4.0 - PARAMS.seebeck_v_k * (hot - 40.0)) / PARAMS.resistance_ohm
    assert out.current_a == pytest.approx(bound, rel=1e-9) and bound < 15.0
    assert float(PARAMS.voltage_v(out.current_a, 40.0, hot)) == pytest.approx(4.0)
    assert loop.limits.voltage_over_supply_periods > 0
    assert loop.limits.largest_request_v > 4.0


def test_the_current_slew_is_bounded():
    loop = designed_loop()
    last = 0.0
    for _ in range(100):
        out = loop.update(0.0, 30.0, 30.0, DT)
        assert abs(out.current_a - last) <= loop.slew_a_s * DT + 1e-12
        last = out.current_a
    assert loop.limits.slew_limited_periods > 0


def test_a_missing_reading_gives_0_a_and_no_fresh_start():
    """A junction reading that is not finite, after plausible ones: 0 A,
    the PI emptied, the smoothed target kept (a fresh start would take the
    next reading, however implausible, as its own reference) and no
    disagreement timed (nothing disagreed yet)."""
    loop = designed_loop()
    loop.update(14.0, 24.0, 24.0, DT)
    for bad in (math.nan, math.inf, -math.inf):
        out = loop.update(14.0, bad, 24.0, DT)
        assert out.current_a == 0.0 and math.isnan(out.estimate_c)
        assert loop.integral_a == 0.0 and loop.reference_c is not None
    assert loop.implausible_s == 0.0 and not loop.stopped


@pytest.mark.parametrize("missing", ["junction", "hot side"])
def test_a_sensor_alternating_nan_and_an_implausible_value_stops_in_its_stated_time(missing):
    """Holding 24 C on a sensor that agrees, the sensor then reads nan and
    40 C (16 K off its model, over IMPLAUSIBLE_K) in turn, or reads 40 C
    while the hot side goes missing every other period: on the simulated
    clock the loop stops IMPLAUSIBLE_S after the first implausible reading
    (to a period: the missing periods go on timing it), and stays at 0 A."""
    loop = designed_loop()
    for _ in range(50):
        loop.update(24.0, 24.0, 24.0, DT)
    assert not loop.stopped
    stopped_after_s = None
    for k in range(int(2.0 * loop.IMPLAUSIBLE_S / DT)):
        if k % 2 == 0:
            sensed, hot = (math.nan, 24.0) if missing == "junction" else (40.0, math.nan)
        else:
            sensed, hot = 40.0, 24.0
        loop.update(24.0, sensed, hot, DT)
        if loop.stopped:
            stopped_after_s = (k + 1) * DT
            break
    first_implausible_s = DT if missing == "junction" else 0.0
    assert stopped_after_s is not None
    # Not before its time (half a period for the sum of periods' rounding).
    late_s = stopped_after_s - first_implausible_s - loop.IMPLAUSIBLE_S
    assert -0.5 * DT < late_s <= 1.5 * DT
    assert all(loop.update(24.0, s, 24.0, DT).current_a == 0.0 for s in (24.0, math.nan) * 5)


def test_a_bonded_sensor_that_goes_missing_for_4_s_is_not_stopped_when_it_returns():
    """The junction held 10 K under the room; the readings then go missing
    for 4 s (a driver outage: 0 A, the junction warms toward its sink, 10 K
    x (1 - exp(-4 s / 8.6 s)) = 3.7 K by the model's a = G/C, over
    IMPLAUSIBLE_K). The loop's model coasts with the module at 0 A, so the
    returning sensor agrees with it: no disagreement timed at all (a model
    held still would see the 3.7 K), no stop, and the junction is back
    within 0.1 K of the target 3 s later."""
    pad, loop = PadInAir(24.0, SENSOR.tau_s), designed_loop()
    for k in range(int(10.0 / DT)):
        outage = 3.0 <= k * DT < 7.0
        out = loop.update(14.0, math.nan if outage else pad.sensed_c,
                          pad.stack.state.sink_c, DT)
        assert out.current_a == 0.0 or not outage
        pad.step(out.current_a)
        assert loop.implausible_s == 0.0
        if k * DT == pytest.approx(7.0 - DT):
            assert pad.stack.state.cold_c - 14.0 > loop.IMPLAUSIBLE_K
    assert not loop.stopped
    assert abs(pad.stack.state.cold_c - 14.0) < 0.1


def test_reversals_and_ripple_are_counted_as_stated():
    """Reversals: a square wave of +-1 A at 2 Hz for 1 s has 3 sign changes
    (4 half-periods); a +-0.05 A dither none (inside the hysteresis). Ripple:
    a 0.5 A sine at 50 Hz (5 periods in the 0.1 s window: its moving mean is
    0) has RMS 0.5/sqrt(2)."""
    t = np.arange(0, 1.0, DT)
    assert sign_reversals(np.where((t * 4).astype(int) % 2, -1.0, 1.0)) == 3
    assert sign_reversals(0.05 * np.sin(2 * np.pi * 40 * t)) == 0
    sine = 3.0 + 0.5 * np.sin(2 * np.pi * 50 * t)
    assert ripple_rms_a(sine, DT) == pytest.approx(0.5 / math.sqrt(2), rel=0.02)


def test_a_sensor_ten_times_slower_is_stopped_then_refused_at_idle():
    """After the 10x-lag stop the module only conducts; idle, the junction
    settles toward its hot side and the slow sensor follows it there, so
    "it reads the hot side" alone would re-arm it (and its next move would
    stop it again). The re-arm probe's warming current shows the lag (the
    sensor sees 0.15-0.35 of the modelled warming): refused, still
    stopped, never re-armed; the module at 0 A but for the probe's current
    (sized from the configured model to warm the junction PROBE_K over its
    duration: PROBE_K C / (S T duration), 0.81 A here)."""
    pad, loop = PadInAir(24.0, SENSOR.tau_s * 10.0), designed_loop()
    for _ in range(int(2.0 / DT)):
        out = loop.update(14.0, pad.sensed_c, pad.stack.state.sink_c, DT)
        pad.step(out.current_a)
    assert loop.stopped
    currents = []
    for _ in range(int(60.0 / DT)):
        out = loop.update(14.0, pad.sensed_c, pad.stack.state.sink_c, DT)
        assert not loop.rearm_if_settled(pad.sensed_c, pad.stack.state.sink_c, DT)
        pad.step(out.current_a)
        currents.append(out.current_a)
    assert loop.stopped and loop.rearms == 0 and loop.rearm_refusals >= 1
    assert "does not follow the module" in loop.rearm_refused
    probe_a = probe_current_a()
    # The reading it starts from is within a few kelvin of 24 C: the pump's
    # S T within 2 % of the one above.
    assert max(abs(c) for c in currents) <= 1.02 * probe_a


def test_the_master_rearms_a_stopped_loop_only_at_idle_and_says_so(caplog):
    """The display's master re-arms its stopped junction loop at idle (no
    force on the pad) once the bonded sensor has settled at the hot side
    and followed the probe, counting the event and logging it; while the
    pad is touched it stays stopped (0 A, no probe) however well the sensor
    agrees. A sensor that then comes off into the air (it reads the room)
    stops the loop again: it stays stopped for the rest of that idle (one
    re-arm per idle, no stop/re-arm cycle), and the next touch's idle may
    re-arm it once more."""
    import logging

    from telethermal.devices.readings import PadSensors
    from telethermal.teleop.display_config import JUNCTION_REARMED, JUNCTION_STOPPED, DisplayConfig
    from telethermal.teleop.master import MasterDisplay, SlaveNews
    from telethermal.physics.layered import pad_resistance

    config = DisplayConfig(feedforward_model="static")
    dt = 1.0 / config.rate_hz
    assert dt == DT                                # the pad in air steps in DT
    master = MasterDisplay(config, None, pad_resistance(tuple(SCENE.pad.layers)),
                           SCENE.sensors.flux_lag_s, 33.0, idle_c=24.0,
                           pad_layers=tuple(SCENE.pad.layers), module=PARAMS)
    news, pad = SlaveNews(24.0, None, ()), PadInAir(24.0, SENSOR.tau_s)
    master.junction_loop.stopped = True            # as after an implausible sensor
    t, idle_s = 0.0, 3 * DisplayJunctionLoop.REARM_S + 2.0

    def run(seconds, touched, bonded=True):
        nonlocal t
        for _ in range(int(seconds / dt)):
            junction = pad.sensed_c if bonded else SCENE.room_temp_c
            sensors = PadSensors(-500.0 if touched else 0.0, 24.0, 5.0 if touched else 0.0,
                                 junction, pad.stack.state.sink_c)
            step = master.step(t, dt, sensors, news)
            pad.step(step.current_a)
            t += dt
            yield step

    for step in run(idle_s, touched=True):
        assert master.junction_loop.stopped and step.current_a == 0.0
    with caplog.at_level(logging.WARNING):
        list(run(idle_s, touched=False))
    assert master.events.get(JUNCTION_REARMED) == 1 and "re-armed" in caplog.text
    assert not master.junction_loop.stopped
    list(run(idle_s, touched=False, bonded=False))
    assert master.junction_loop.stopped          # the sensor in the air stopped it again
    assert master.events.get(JUNCTION_STOPPED) == 2
    list(run(idle_s, touched=False))
    assert master.junction_loop.stopped and master.events.get(JUNCTION_REARMED) == 1
    list(run(0.2, touched=True))
    list(run(4 * idle_s, touched=False))           # the junction warmed by the last run
    assert master.events.get(JUNCTION_REARMED) == 2


def test_no_probe_current_flows_in_the_period_a_finger_is_detected():
    """A stopped loop probing its sensor at idle: from the first period the
    master's detector sees the finger, the module gets 0 A (the probe asked
    for in the period before is cancelled, not run under the finger)."""
    from telethermal.devices.readings import PadSensors
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.teleop.master import MasterDisplay, SlaveNews
    from telethermal.physics.layered import pad_resistance

    config = DisplayConfig(feedforward_model="static")
    dt = 1.0 / config.rate_hz
    master = MasterDisplay(config, None, pad_resistance(tuple(SCENE.pad.layers)),
                           SCENE.sensors.flux_lag_s, 33.0, idle_c=24.0,
                           pad_layers=tuple(SCENE.pad.layers), module=PARAMS)
    news, pad = SlaveNews(24.0, None, ()), PadInAir(24.0, SENSOR.tau_s)
    master.junction_loop.stopped = True
    t, probing = 0.0, 0
    while probing < 5:                              # a few periods into the probe
        sensors = PadSensors(0.0, 24.0, 0.0, pad.sensed_c, pad.stack.state.sink_c)
        step = master.step(t, dt, sensors, news)
        pad.step(step.current_a)
        probing += step.current_a != 0.0
        t += dt
        assert t < 3 * DisplayJunctionLoop.REARM_S, "no probe started"
    touching = []
    for _ in range(20):
        sensors = PadSensors(-500.0, 24.0, 5.0, pad.sensed_c, pad.stack.state.sink_c)
        step = master.step(t, dt, sensors, news)
        touching.append((step.touching, step.current_a))
        t += dt
    first = next(i for i, (touched, _) in enumerate(touching) if touched)
    assert all(current == 0.0 for _, current in touching[first:]), touching
