"""The display's junction loop in whole sessions (simulated clock) with its
bonded sensor's lag off its stated value: the hard cases of the display
loop (docs/display-loop.md)."""

import numpy as np
import pytest

from telethermal.control.current_quality import sign_reversals
from telethermal.physics.scene import load_scene
from telethermal.teleop.display_config import JUNCTION_STOPPED
from telethermal.sim.inprocess import run_session

SCENE = load_scene("fingertip-7")
CONTACT_S = 3.0


@pytest.fixture(scope="module")
def models(trained_models):
    return trained_models.pair(SCENE, 0)


def touch(models, lag_scale, material="aluminium", seed=1):
    identifier, generator = models
    return run_session(SCENE, material, identifier, generator, contact_s=CONTACT_S, seed=seed,
                       junction_lag_scale=lag_scale)


def at_the_limit_after(result, t0_s):
    """Periods after ``t0_s`` of contact with the current at the driver's limit."""
    tr, imax = result.trace, result.summary["module"]["imax_a"]
    late = tr["t_s"] >= t0_s
    return int(np.sum(np.abs(tr["current_a"][late]) >= 0.999 * imax))


@pytest.mark.parametrize("lag_scale", [0.5, 2.0])
def test_aluminium_with_the_sensor_at_half_and_twice_its_lag(models, lag_scale):
    """Regression of the review's case (a 50 ms sensor lag: the old 10 A/K
    loop oscillated at +-8.5 A about 6 Hz, 1,205 periods saturated) and its
    2x: no safety event, the loop never stopped, no period at the current
    limit after the first second (the metal's onset may use it), and no
    sustained oscillation: no sign reversal of the current in the contact's
    last second (a limit cycle persists; the old loop's reversed about 12
    times a second)."""
    res = touch(models, lag_scale)
    s, module = res.summary, res.summary["module"]
    assert module["junction_sensor"]["true_tau_s"] == pytest.approx(
        lag_scale * module["junction_sensor"]["tau_s"])
    assert s["safety_events"] == 0
    assert JUNCTION_STOPPED not in s["display_event_counts"]
    assert at_the_limit_after(res, 1.0) == 0
    tr = res.trace
    last = (tr["t_s"] >= CONTACT_S - 1.0) & (tr["t_s"] < CONTACT_S)     # to the release
    assert sign_reversals(tr["current_a"][last]) == 0


#: A case stricter than issue 43's targets as written (they put the
#: reversals on the shipped display, ``bench render``'s ``limits``, and the
#: sensor's spread on safety events): with the module's own 0.8 mm plate
#: (the junction's heat capacity doubled) the sensor lagging half its stated
#: value reverses the current more than 2 times per second of contact on
#: this touch (the touch's transients in its first 1.5 s; none after;
#: docs/display-loop.md).
HALF_LAG_REVERSALS = pytest.mark.xfail(strict=True, reason=(
    "issue 43: 2.34 reversals per s with the sensor at half its lag, over 2"))


@pytest.mark.parametrize("lag_scale", [pytest.param(0.5, marks=HALF_LAG_REVERSALS), 1.0, 2.0])
def test_aluminium_reverses_within_the_target(models, lag_scale):
    """Issue 43's reversal and ripple targets (set on the shipped display)
    held over the sensor's lags the loop is designed for (half to twice its
    stated value; aluminium, seed 1): the current's sign reversals <= 2 per
    second of contact and its ripple <= 0.3 A RMS."""
    module = touch(models, lag_scale).summary["module"]
    assert module["ripple_rms_a"] <= 0.3
    assert module["reversals_per_s"] <= 2.0


def test_a_sensor_ten_times_slower_is_made_safe_or_stable(models):
    """The sensor at 10x its lag (1 s: a debonded chip) from the session's
    start (-PRE_CONTACT_S): either the loop stays off the current limit
    after the first second, or it stops the module within 1.5 s of contact
    (the stop time the master records, not read off the current), with no
    period at the current limit in the 0.5 s before the stop and 0 A from
    it on (logged as a display event); never a limit cycle."""
    res = touch(models, 10.0)
    stopped_at = res.summary["module"]["junction_stopped_at_s"]
    tr = res.trace
    if JUNCTION_STOPPED in res.summary["display_event_counts"]:
        assert stopped_at is not None and stopped_at < 1.5
        before = (tr["t_s"] >= stopped_at - 0.5) & (tr["t_s"] < stopped_at)
        imax = res.summary["module"]["imax_a"]
        assert not np.any(np.abs(tr["current_a"][before]) >= 0.999 * imax)
        assert np.all(tr["current_a"][tr["t_s"] > stopped_at] == 0.0)
    else:
        assert stopped_at is None
        assert at_the_limit_after(res, 1.0) == 0


def test_a_humid_room_lifts_a_remembered_metals_idle_above_the_dew_point(models):
    """80 % RH at 24 C (dew point 20.4 C): aluminium remembered idles at the
    dew point plus its margin instead of its pre-conditioned 15.6 C; the
    display says so (an event and the log) and the touch stays safe."""
    from dataclasses import replace

    from telethermal.control.dew import DEW_MARGIN_K

    identifier, generator = models
    humid = replace(SCENE, room_humidity_pct=80.0)
    s = run_session(humid, "aluminium", identifier, generator, contact_s=2.0, seed=1,
                    expected_material="aluminium").summary
    assert s["display_idle_c"] >= s["dew_point_c"] + DEW_MARGIN_K - 1e-9   # the command
    # The pad's true surface with nothing on it (before the contact and
    # after the release), not the command: above the dew point, no fog.
    # The 1.5 K margin is NOT held on it: measured 0.26 K (aluminium, seed
    # 1, 80 % RH), the command's floor does not bound the true surface.
    assert s["idle_surface_minus_dew_k"] > 0.0
    assert s["display_event_counts"].get("idle lifted above the dew point", 0) >= 1
    assert s["safety_events"] == 0


def test_a_posterior_collapsing_onto_a_conductor_does_not_send_the_pad_the_wrong_way(models):
    """Graphite, seed 2: the pad is held at its idle until the first
    posterior; the posterior mixture (mostly insulators by 1/e) then asks a
    junction far above the idle, and the hand-over closes that step at its
    slope. The posterior then collapses onto graphite, a conductor: the
    controller's wish falls to a few kelvin above the idle, still above it
    and rising. The junction command must then never go below where the
    touch started (with the hand-over's offset kept whole it went kelvins
    below the idle, cooling the finger the controller wanted warmed). The
    bound: 0.05 K (the command's own slope is 0.2 K a period)."""
    res = touch(models, 1.0, material="graphite", seed=2)
    tr = res.trace
    first = (tr["t_s"] >= 0.0) & (tr["t_s"] < 0.5)
    command = tr["junction_cmd_c"][first]
    assert command.min() >= command[0] - 0.05
    assert res.summary["safety_events"] == 0
