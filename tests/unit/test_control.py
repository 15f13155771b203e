"""PID and safety supervisor: the hard cases of the rendering issue that need
no plant (the plant-level ones come with the display loop)."""

import logging
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.control.pid import Pid, PidGains
from telethermal.control.safety import (Clamp, Fault, Reading, Request, SafetyLimits,
                                        initial_state, safety_event_count, supervise)
from telethermal.errors import ControlError

DT = 1e-3


def first_order_plant(y, u, dt, tau=0.05):
    """Exact step of y' = (u - y) / tau with u held."""
    decay = math.exp(-dt / tau)
    return u + (y - u) * decay


def test_pi_loop_removes_steady_state_error():
    # First-order plant under PI: the integral drives the error to zero; after
    # 40 plant time constants the error is below 1e-6 of the step.
    pid = Pid(PidGains(kp=2.0, ki=40.0), DT)
    y = 0.0
    for _ in range(2000):
        u = pid.update(1.0, y, DT).output
        y = first_order_plant(y, u, DT)
    assert abs(1.0 - y) < 1e-6


def test_setpoint_step_gives_no_derivative_kick():
    pid = Pid(PidGains(kp=1.0, kd=5.0), DT)
    pid.update(0.0, 0.0, DT)
    out = pid.update(1000.0, 0.0, DT)      # step of the setpoint, measurement still
    assert out.derivative == 0.0 and out.output == pytest.approx(1000.0)


def test_saturation_for_ten_seconds_then_release_does_not_wind_up():
    gains = PidGains(kp=1.0, ki=10.0, output_min=-1.0, output_max=1.0)
    pid = Pid(gains, DT)
    for _ in range(10_000):                 # 10 s pinned at the limit
        out = pid.update(100.0, 0.0, DT)
    assert out.saturated and out.integral <= gains.output_max
    # Release: the setpoint drops below the measurement; the output must leave
    # the upper limit at once instead of unwinding a 10 s integral.
    out = pid.update(-0.5, 0.0, DT)
    assert out.output < gains.output_max


@pytest.mark.parametrize("dt", [0.0, -DT])
def test_non_positive_steps_are_refused(dt):
    with pytest.raises(ControlError, match="dt_s"):
        Pid(PidGains(kp=1.0), DT).update(1.0, 0.0, dt)


def test_a_step_100_times_nominal_causes_no_jump():
    pid = Pid(PidGains(kp=1.0, ki=5.0, kd=0.5), DT)
    for k in range(100):
        before = pid.update(1.0, 0.2 + 1e-4 * k, DT)
    after = pid.update(1.0, 0.2 + 1e-4 * 100, 100 * DT)
    assert after.skipped_long_step and after.derivative == before.derivative
    assert after.integral == pytest.approx(before.integral)
    assert abs(after.output - before.output) < 0.02


def test_bumpless_start_continues_the_applied_output():
    pid = Pid(PidGains(kp=2.0, ki=1.0), DT)
    pid.reset(measurement=30.0, output=0.7, setpoint=31.0)
    assert pid.update(31.0, 30.0, DT).output == pytest.approx(0.7, abs=1e-2)


def test_non_finite_inputs_are_refused():
    with pytest.raises(ControlError, match="measurement"):
        Pid(PidGains(kp=1.0), DT).update(1.0, math.nan, DT)


# ------------------------------------------------------------------ safety
LIM = SafetyLimits()


def run(readings, requests, dt=DT, state=None):
    state = state or initial_state(LIM)
    out = []
    for reading, request in zip(readings, requests):
        applied, state = supervise(state, reading, request, LIM, dt)
        out.append(applied)
    return out, state


def healthy(k, temp=33.0):
    # A live sensor: a little noise on every reading.
    return Reading(k * DT, temp + 1e-3 * math.sin(k), 100.0 + math.cos(k))


def test_fresh_healthy_setpoints_pass_through_rate_limited():
    requests = [Request(34.0, 500.0, k * DT) for k in range(100)]
    out, state = run([healthy(k) for k in range(100)], requests)
    assert not out[-1].safe and out[-1].flux_w_m2 == 500.0
    # 5 K/s for 1 ms steps: the temperature creeps 5 mK a step toward 34 C.
    assert out[1].temp_c - out[0].temp_c == pytest.approx(LIM.max_rate_k_s * DT)
    assert state.count("left safe state") == 1


@pytest.mark.parametrize("bad", [Reading(0.05, math.nan, 0.0), Reading(0.05, 120.0, 0.0),
                                 Reading(0.05, 33.0, math.inf)])
def test_bad_readings_enter_the_safe_state_within_one_period(bad, caplog):
    readings = [healthy(k) for k in range(50)] + [bad]
    requests = [Request(40.0, 800.0, k * DT) for k in range(51)]
    with caplog.at_level(logging.WARNING):
        out, state = run(readings, requests)
    assert out[-1].safe and out[-1].temp_c == LIM.neutral_c and out[-1].flux_w_m2 is None
    assert state.count("entered safe state") == 1
    assert "safe state entered" in caplog.text


def test_a_stuck_sensor_enters_the_safe_state():
    stuck = Reading(0.0, 36.0, 250.0)
    readings = [healthy(k) for k in range(10)] + [
        Reading(k * DT, stuck.pad_temp_c, stuck.flux_w_m2) for k in range(10, 700)]
    requests = [Request(36.0, 250.0, k * DT) for k in range(700)]
    out, state = run(readings, requests)
    first_safe = next(i for i, a in enumerate(out) if a.safe)
    # Unchanged from reading 10 on; stuck_after_s = 0.5 s = 500 periods.
    assert first_safe == 10 + 500
    assert "stuck sensor" in out[-1].reasons


def test_an_expired_setpoint_enters_the_safe_state_and_recovery_leaves_it():
    readings = [healthy(k) for k in range(1200)]
    requests = [Request(35.0, 300.0, 0.0)] * 1200          # never refreshed
    out, state = run(readings, requests)
    assert not out[500].safe and out[501].safe and "setpoint expired" in out[501].reasons
    fresh = [Request(35.0, 300.0, (1200 + k) * DT) for k in range(10)]
    out2, state = run([healthy(1200 + k) for k in range(10)], fresh, state=state)
    assert not out2[0].safe and state.count("left safe state") == 2


def test_a_flux_that_would_push_the_skin_past_43_is_clamped_and_counted(caplog):
    hot = [Reading(k * DT, 43.2 + 1e-4 * (k % 3), 900.0) for k in range(5)]
    with caplog.at_level(logging.INFO):
        out, state = run(hot, [Request(47.0, 900.0, k * DT) for k in range(5)])
    assert all(a.flux_w_m2 == 0.0 and a.temp_c <= LIM.skin_max_c for a in out)
    assert state.count("clamped: flux at temperature limit") == 5
    assert "setpoint limited" in caplog.text


def test_bad_periods_are_refused():
    with pytest.raises(ControlError):
        supervise(initial_state(LIM), healthy(0), Request(33.0, 0.0, 0.0), LIM, 0.0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(allow_nan=True, allow_infinity=True, width=32),
                          st.floats(-1e6, 1e6), st.floats(-200, 200)), min_size=1, max_size=40))
def test_whatever_is_asked_the_applied_temperature_stays_in_the_band(steps):
    state = initial_state(LIM)
    previous = state.applied_temp_c
    for k, (temp_req, flux_req, pad_c) in enumerate(steps):
        reading = Reading(k * DT, pad_c + 1e-6 * k, 10.0 + k)
        applied, state = supervise(state, reading, Request(temp_req, flux_req, k * DT), LIM, DT)
        assert LIM.skin_min_c <= applied.temp_c <= LIM.skin_max_c
        if not applied.safe:
            assert abs(applied.temp_c - previous) <= LIM.max_rate_k_s * DT + 1e-12
            assert abs(applied.flux_w_m2) <= LIM.max_flux_w_m2
        previous = applied.temp_c
    assert np.isfinite(previous)


# ------------------------------------------------------------------ contact
from telethermal.control.contact import ContactDetector  # noqa: E402
from telethermal.physics.sensors import ForceSensor  # noqa: E402


def test_press_and_lift_are_detected_once_with_the_true_onset(rng):
    # A 10 N press rising with a 30 ms time constant from t = 0.2 s, noisy;
    # the first sample above 2 N is at t0 + 0.03 ln(10/8) = 6.7 ms after onset.
    t = np.arange(0, 2.0, 1e-3)
    force = ForceSensor(noise_n_rms=0.05).read_n(t - 0.2, 10.0, rng)
    force[t > 1.5] = rng.normal(0, 0.05, np.sum(t > 1.5))      # lifted at 1.5 s
    detector = ContactDetector()
    events = [e for e in (detector.update(a, b) for a, b in zip(t, force)) if e]
    assert [e.touching for e in events] == [True, False]
    assert events[0].t_s == pytest.approx(0.2 + 0.03 * math.log(10 / 8), abs=3e-3)
    assert events[1].t_s == pytest.approx(1.5, abs=2e-3)


def test_a_brush_shorter_than_the_debounce_is_not_a_touch():
    detector = ContactDetector(debounce_s=0.02)
    t = np.arange(0, 0.1, 1e-3)
    force = np.where((t > 0.05) & (t < 0.06), 5.0, 0.0)           # 10 ms spike
    assert not any(detector.update(a, b) for a, b in zip(t, force))


def test_noise_around_one_threshold_does_not_chatter():
    detector = ContactDetector(on_n=2.0, off_n=1.0, debounce_s=0.0)
    events = [detector.update(k * 1e-3, 2.5 if k == 0 else 1.5 + 0.4 * (-1) ** k)
              for k in range(200)]
    assert sum(e is not None for e in events) == 1                 # in, and stays in


def test_bad_contact_samples_are_refused():
    detector = ContactDetector()
    detector.update(0.0, 0.0)
    with pytest.raises(ControlError):
        detector.update(0.0, 1.0)
    with pytest.raises(ControlError):
        detector.update(0.1, math.nan)


def test_a_limit_downstream_of_the_controller_stops_integration():
    # The output asked for is cut after the controller (a slew limit): the
    # integral must not keep growing against it, so it does not overshoot later.
    pid = Pid(PidGains(kp=0.0, ki=10.0), DT)
    for _ in range(100):
        out = pid.update(1.0, 0.0, DT)
        pid.limited_downstream(out.output, min(out.output, 0.0))      # nothing passes
    assert pid.update(1.0, 0.0, DT).integral == pytest.approx(10.0 * DT)
    free = Pid(PidGains(kp=0.0, ki=10.0), DT)
    for _ in range(100):
        out = free.update(1.0, 0.0, DT)
        free.limited_downstream(out.output, out.output)                # all passes
    assert out.integral == pytest.approx(100 * 10.0 * DT)


def test_the_safety_count_holds_entries_and_clamps_by_the_names_recordings_hold():
    # Summaries and recordings written before the names were enums hold the
    # same strings; faults are counted by name beside, not as events.
    events = {"entered safe state": 2, "left safe state": 2, "stuck sensor": 4,
              "clamped: rate": 3, "clamped: flux at temperature limit": 1}
    assert safety_event_count(events) == 6
    assert {f.value for f in Fault} >= {"stuck sensor", "no setpoint", "setpoint expired"}
    assert Clamp.RATE.event == "clamped: rate"
