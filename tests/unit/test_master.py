"""The master's display loop on the simulated plant: tracking against the
exact direct-contact solution, hand-over, the skin band and the safe state."""

import re

import numpy as np
import pytest

from telethermal.control.pid import PidGains
from telethermal.control.safety import SafetyLimits
from telethermal.data.dataset import Trial
from telethermal.errors import ControlError
from telethermal.ident.anytime import Estimate
from telethermal.physics.scene import finger_contact_model, load_scene
from telethermal.render.generator import NetworkGenerator
from telethermal.devices.readings import PadSensors
from telethermal.teleop.display_config import DisplayConfig
from telethermal.teleop.master import MasterDisplay, SlaveNews
from telethermal.physics.layered import pad_resistance

from displayloop import display_periods

SCENE = load_scene("fingertip-7")
FINGER_C, OBJECT_C, H = 33.0, 24.0, 5000.0
TAU = SCENE.sensors.flux_lag_s


def static(**kw) -> DisplayConfig:
    """These tests drive the flux PID with its static feed-forward: they give
    the display no pad model, which the impedance controller (the default)
    refuses (issue 26: no silent fall back). They step it every 1 ms."""
    return DisplayConfig(feedforward_model="static", **{"rate_hz": 1000.0, **kw})


@pytest.fixture(scope="module")
def exact():
    """A generator fitted on the exact direct-contact curves (nominal skin,
    no noise), and those curves: the loop is then asked for the truth."""
    t = np.arange(0, 3001) / 1000.0
    trials, refs = [], {}
    for obj in SCENE.objects:
        if obj.material not in ("steel", "plexiglass"):
            continue
        model, _ = finger_contact_model(SCENE, obj)
        ref = model.solve(np.clip(t, 1e-9, None), FINGER_C, OBJECT_C, H, sensor_lag_s=TAU)
        refs[obj.material] = ref
        sensed = np.where(t > 0, ref.flux_sensed_w_m2[0], 0.0)
        trials.append(Trial(f"{obj.material}-0", obj.material, "x.csv", 1000.0, OBJECT_C,
                            FINGER_C, 24.0, "person-0",
                            channels={"t_s": t, "heat_flux_W_m2": sensed}))
    return NetworkGenerator().fit(trials), refs, t


def decided(material, classes=("plexiglass", "steel")):
    p = tuple(1.0 if c == material else 0.0 for c in classes)
    return Estimate(0.0, p, material, 1.0, True, "confident")


def run(gen, news_at, seconds=3.0, config=static(), fault_at=None, pre_s=0.1):
    """Drive the master on the plant; ``news_at(t)`` gives the slave's news."""
    layers = tuple(SCENE.pad.layers)
    master = MasterDisplay(config, gen, pad_resistance(layers), TAU, FINGER_C, idle_c=OBJECT_C)
    rows = [(t, r.contact_flux_w_m2 if r else 0.0, step.junction_applied_c, step.safe,
             step.phase, r.pad_surface_c if r else step.junction_applied_c)
            for t, r, step in display_periods(master, news_at, layers, seconds, config.rate_hz,
                                              pre_s, OBJECT_C, FINGER_C, H, TAU, fault_at)]
    return master, rows


def _tracking_error(exact, material, config, window):
    gen, refs, tt = exact
    master, rows = run(gen, lambda t: SlaveNews(OBJECT_C, decided(material),
                                                ("plexiglass", "steel")), config=config)
    t = np.array([r[0] for r in rows])
    q = np.array([r[1] for r in rows])
    direct = -refs[material].flux_w_m2[0]
    mask = (t >= window[0]) & (t < window[1])
    err = q[mask] - np.interp(t[mask], tt, direct)
    return np.sqrt(np.mean(err ** 2)) / np.abs(direct[1:]).max(), master


@pytest.mark.parametrize("material", ["steel", "plexiglass"])
def test_feed_forward_inverts_the_pad_exactly(exact, material):
    # Feed-forward alone (no feedback), asked for the exact direct-contact
    # flux: over 1-3 s the finger receives it within 0.5 % RMS of the direct
    # peak (measured 0.19 % steel, 0.30 % plexiglass); over 0.2-3 s within
    # 2 % (measured 0.6 %, 1.2 %). The inversion is quasi-static (junction =
    # pad surface + q R_pad) and the sensor film's own heat capacity (time
    # constant ~ L^2/alpha ~ 1 s) is what it misses; the first 0.2 s are out
    # of the pad's reach (a metal's h-limited spike; the junction at the band).
    ff_only = static(gains=PidGains(0.0, 0.0, 0.0, output_min=-25, output_max=25))
    assert _tracking_error(exact, material, ff_only, (1.0, 3.0))[0] < 0.005
    assert _tracking_error(exact, material, ff_only, (0.2, 3.0))[0] < 0.02


@pytest.mark.parametrize("material", ["steel", "plexiglass"])
def test_default_loop_tracks_the_exact_direct_contact_flux(exact, material):
    # The default PI pays back, through its integral, the heat the pad could
    # not deliver in the first instants, so the flux runs over for a while
    # (measured 1.1-1.4 % RMS of peak over 0.2-3 s) and then settles (0.07 %
    # and 0.09 % over 2-3 s); no safety event on the way.
    err, master = _tracking_error(exact, material, static(), (0.2, 3.0))
    assert err < 0.03
    late, _ = _tracking_error(exact, material, static(), (2.0, 3.0))
    assert late < 0.003
    assert master.safety.events.get("entered safe state", 0) == 0
    assert not any(k.startswith("clamped") for k in master.safety.events)


def test_hand_over_is_slew_limited(exact):
    # Hold until 0.4 s, then render: the junction never moves faster than
    # the controller's slew limit, and the supervisor's rate limit is never hit.
    gen, _, _ = exact
    config = static(before="hold")
    master, rows = run(gen, lambda t: SlaveNews(OBJECT_C, decided("steel") if t >= 0.4 else None,
                                                ("plexiglass", "steel")), config=config)
    junction = np.array([r[2] for r in rows])
    assert np.max(np.abs(np.diff(junction))) <= config.slew_k_s / config.rate_hz + 1e-9
    phases = [r[4] for r in rows]
    assert phases[0] == "idle" and "contact" in phases and phases[-1] == "render"
    assert master.rendered_from_s == pytest.approx(0.4, abs=1e-9)
    assert "clamped: rate" not in master.safety.events


@pytest.mark.parametrize("object_c", [-30.0, 90.0])
def test_an_impossible_request_keeps_the_surface_in_the_skin_band(exact, object_c):
    # An object at -30 C or 90 C (as the slave says) asks the pad for far
    # more than the band allows: the junction may go past the band to move
    # the surface, but the surface (what the skin touches) stays within
    # 15-43 C: the supervisor's barrier, no safe state needed.
    gen, _, _ = exact
    limits = SafetyLimits(max_rate_k_s=200.0, max_flux_w_m2=20_000.0)
    master, rows = run(gen, lambda t: SlaveNews(object_c, decided("steel"), ("plexiglass", "steel")),
                       config=static(limits=limits), seconds=1.0)
    surface = np.array([r[5] for r in rows])
    assert surface.min() >= limits.skin_min_c - 0.05
    assert surface.max() <= limits.skin_max_c + 0.05
    assert master.safety.count("surface out of band") == 0


def test_a_dead_flux_sensor_is_the_safe_state_within_one_period(exact):
    gen, _, _ = exact
    limits = static().limits
    master, rows = run(gen, lambda t: SlaveNews(OBJECT_C, decided("steel"), ("plexiglass", "steel")),
                       fault_at=(1.0, 1.2), seconds=2.0)
    for t, _, junction, safe, _, _ in rows:
        if 1.0 <= t < 1.2:
            assert safe and junction == limits.neutral_c       # the very period it happens
    after = [r for r in rows if r[0] >= 1.3]
    assert not any(r[3] for r in after)                        # back once the reading is
    assert master.safety.events["entered safe state"] == 1
    # Leaving it, the controller starts from what the pad was given (the
    # neutral temperature), not from its own last command before the fault:
    # the junction moves within the controller's own slew limit, and the
    # supervisor's looser rate limit (its backstop) never has to cut it.
    config = static()
    junction = np.array([r[2] for r in rows if r[0] >= 1.2 - 1e-9])
    assert np.max(np.abs(np.diff(junction))) <= config.slew_k_s / config.rate_hz + 1e-9
    assert "clamped: rate" not in master.safety.events


def test_release_returns_to_standby_and_bad_config_is_refused(exact):
    gen, _, _ = exact
    layers = tuple(SCENE.pad.layers)
    master = MasterDisplay(static(), gen, pad_resistance(layers), TAU, FINGER_C,
                           idle_c=OBJECT_C)
    news = SlaveNews(OBJECT_C, decided("steel"), ("plexiglass", "steel"))
    for k in range(200):                                     # touch for 0.2 s
        master.step(k * 1e-3, 1e-3, PadSensors(-2000.0 - k, 26.0, 10.0), news)
    for k in range(200, 500):   # lift (the junction may have gone 25 K past the band)
        step = master.step(k * 1e-3, 1e-3, PadSensors(0.5 * (-1) ** k, 26.0, 0.0), news)
    assert step.phase == "idle" and master.last_release_s is not None
    assert step.junction_applied_c == pytest.approx(OBJECT_C)
    with pytest.raises(ControlError, match="before"):
        static(before="guess")
    with pytest.raises(ControlError, match="rate_hz"):
        static(rate_hz=0.0)


# ------------------------------------------------------------------ hard cases
def closed_form_generator(h=5000.0, e_m=14000.0):
    """The finger-material closed form as a generator (no fitting)."""
    from telethermal.physics.materials import get_material
    from telethermal.render.generator import ContactGenerator
    return ContactGenerator._restore(
        {"params": {"steel": (h, e_m, get_material("skin").effusivity),
                    "plexiglass": (h, 600.0, get_material("skin").effusivity)}}, {})


def test_a_step_of_desired_flux_at_onset_gives_no_kick_and_stays_in_the_band():
    # The closed form steps from 0 to h*gap at contact; with a derivative
    # term in the gains the junction still moves at most one slew step per
    # period and the pad's surface never leaves the skin band.
    config = static(gains=PidGains(1e-3, 1e-2, 5e-5, output_min=-25, output_max=25))
    master, rows = run(closed_form_generator(), lambda t: SlaveNews(
        OBJECT_C, decided("steel"), ("plexiglass", "steel")), config=config, seconds=1.0)
    junction = np.array([r[2] for r in rows])
    assert np.max(np.abs(np.diff(junction))) <= config.slew_k_s / config.rate_hz + 1e-9
    surface = np.array([r[5] for r in rows])         # the band guards the surface now
    assert surface.min() >= 15.0 - 0.05 and surface.max() <= 43.0 + 0.05
    assert master.safety.events.get("entered safe state", 0) == 0


def test_a_hot_object_is_limited_at_the_band_counted_and_logged(caplog):
    # An 80 C object: the flux asked for would heat the skin past 43 C. The
    # controller keeps the surface barrier on the junction (from the
    # surface's margin to the band) itself and counts it; the supervisor
    # never has to clamp, the pad surface stays under 43 C and no safe state
    # is needed.
    import logging
    with caplog.at_level(logging.INFO):
        master, rows = run(closed_form_generator(), lambda t: SlaveNews(
            80.0, decided("steel"), ("plexiglass", "steel")), seconds=2.0)
    surface = np.array([r[5] for r in rows])
    assert surface.max() <= 43.0 + 0.05
    assert master.events["rendering limited by the surface band"] >= 1
    assert master.safety.events.get("clamped: surface band", 0) == 0   # kept by the controller
    assert master.safety.count("surface out of band") == 0


def test_a_stuck_flux_sensor_mid_contact_is_the_safe_state():
    gen = closed_form_generator()
    limits = static().limits
    layers = tuple(SCENE.pad.layers)
    master = MasterDisplay(static(), gen, pad_resistance(layers), TAU, FINGER_C,
                           idle_c=OBJECT_C)
    news = SlaveNews(OBJECT_C, decided("steel"), ("plexiglass", "steel"))
    safe_at = None
    for k in range(1500):
        t = k * 1e-3
        stuck = t >= 0.5
        flux = -3000.0 if stuck else -3000.0 - 0.3 * (k % 7)      # bit-identical from 0.5 s
        temp = 26.0 if stuck else 26.0 + 1e-3 * (k % 5)
        step = master.step(t, 1e-3, PadSensors(flux, temp, 10.0), news)
        if step.safe and safe_at is None and t > 0.1:
            safe_at = t
            assert step.junction_applied_c == limits.neutral_c
    assert safe_at == pytest.approx(0.5 + limits.stuck_after_s, abs=2e-3)
    assert master.safety.events["stuck sensor"] >= 1


@pytest.mark.parametrize("dt", [0.0, -1e-3])
def test_a_non_positive_period_is_a_clear_error(dt):
    master = MasterDisplay(static(), closed_form_generator(), 1e-3, TAU, FINGER_C,
                           idle_c=OBJECT_C)
    with pytest.raises(ControlError, match="period|dt"):
        master.step(0.0, dt, PadSensors(0.0, OBJECT_C, 0.0), SlaveNews(OBJECT_C))


def test_a_period_100_times_nominal_makes_no_jump():
    config = static()
    master = MasterDisplay(config, closed_form_generator(), 1e-3, TAU, FINGER_C, idle_c=OBJECT_C)
    news = SlaveNews(OBJECT_C, decided("steel"), ("plexiglass", "steel"))
    last = None
    for k in range(300):
        dt = 0.1 if k == 200 else 1e-3                      # one stall of 100 periods
        t = k * 1e-3 + (0.099 if k >= 200 else 0.0)
        step = master.step(t, dt, PadSensors(-2000.0 + (k % 3), 27.0 + 1e-3 * (k % 4), 10.0),
                           news)
        if last is not None:
            assert abs(step.junction_applied_c - last) <= 2 * config.slew_k_s * 1e-3 + 1e-9
        last = step.junction_applied_c


def test_the_hand_over_from_the_mixture_to_the_decision_has_no_step():
    # Posteriors 70/30 for plexiglass until 0.4 s, then "steel" decided: the
    # desired flux moves to steel's over blend_s, never in one step. Without
    # the blend the step would be |q_steel - q_mix| in one period.
    gen = closed_form_generator()
    classes = ("plexiglass", "steel")

    def news(t):
        if t < 0.4:
            return SlaveNews(OBJECT_C, Estimate(0.2, (0.7, 0.3), "plexiglass", 0.7, False),
                             classes)
        return SlaveNews(OBJECT_C, decided("steel"), classes)

    desired = np.array(_desired_trace(gen, news))
    t = np.arange(len(desired)) * 1e-3 - 0.1
    around = (t > 0.35) & (t < 0.6)
    q_steel = gen.normalised("steel", 0.4)[0]
    q_mix = 0.7 * gen.normalised("plexiglass", 0.4)[0] + 0.3 * q_steel
    jump = abs((q_steel - q_mix) * (OBJECT_C - FINGER_C))
    assert jump > 500.0                               # a real step to smooth
    assert np.nanmax(np.abs(np.diff(desired[around]))) < 0.1 * jump


def _desired_trace(gen, news_at, seconds=0.8, pre_s=0.1, rate=1000.0):
    layers = tuple(SCENE.pad.layers)
    master = MasterDisplay(static(), gen, pad_resistance(layers), TAU, FINGER_C,
                           idle_c=OBJECT_C)
    out = [step.desired_flux_w_m2
           for _, _, step in display_periods(master, news_at, layers, seconds, rate, pre_s,
                                             OBJECT_C, FINGER_C, H, TAU)]
    return out


def test_a_slave_that_changes_its_mind_is_followed_without_a_step():
    # Decided steel at 0.3 s, then plexiglass at 0.6 s: the desired flux moves
    # to plexiglass's over blend_s, counted as a changed decision.
    gen = closed_form_generator()
    classes = ("plexiglass", "steel")

    def news(t):
        return SlaveNews(OBJECT_C, decided("steel" if t < 0.6 else "plexiglass"), classes)

    desired = np.array(_desired_trace(gen, news, seconds=1.0))
    t = np.arange(len(desired)) * 1e-3 - 0.1
    jump = abs((gen.normalised("steel", 0.6)[0] - gen.normalised("plexiglass", 0.6)[0])
               * (OBJECT_C - FINGER_C))
    around = (t > 0.55) & (t < 0.8)
    assert jump > 1000.0
    assert np.nanmax(np.abs(np.diff(desired[around]))) < 0.1 * jump
    late = desired[t > 0.75]
    expected = gen.normalised("plexiglass", t[t > 0.75]) * (OBJECT_C - FINGER_C)
    np.testing.assert_allclose(late, expected, rtol=1e-9)       # it ends on the new material


def test_an_estimate_after_the_finger_lifted_changes_nothing():
    gen = closed_form_generator()
    layers = tuple(SCENE.pad.layers)
    master = MasterDisplay(static(), gen, pad_resistance(layers), TAU, FINGER_C,
                           idle_c=OBJECT_C)
    undecided = SlaveNews(OBJECT_C, None, ("plexiglass", "steel"))
    for k in range(300):                                       # touch, no decision yet
        master.step(k * 1e-3, 1e-3, PadSensors(-2000.0 + k % 3, 26.0 + 1e-3 * (k % 4), 10.0),
                    undecided)
    for k in range(300, 600):                                  # lifted
        master.step(k * 1e-3, 1e-3, PadSensors(0.1 * (k % 3), 24.0 + 1e-3 * (k % 4), 0.0),
                    undecided)
    late = SlaveNews(OBJECT_C, decided("steel"), ("plexiglass", "steel"))
    for k in range(600, 700):                                  # the decision arrives now
        step = master.step(k * 1e-3, 1e-3, PadSensors(0.1 * (k % 3), 24.0 + 1e-3 * (k % 4),
                                                      0.0), late)
    assert step.phase == "idle" and master.rendering is None
    assert step.junction_applied_c == pytest.approx(OBJECT_C)


def test_the_impedance_controller_without_the_pad_model_is_a_clear_error():
    # Issue 26: the display used to fall back to the static PID in silence
    # (the hardware master built it without the pad model).
    with pytest.raises(ControlError, match="pad_layers and contact_conductance_w_m2k"):
        MasterDisplay(DisplayConfig(), closed_form_generator(), 1e-3, TAU, FINGER_C)
    with pytest.raises(ControlError, match="pad model"):
        MasterDisplay(DisplayConfig(), closed_form_generator(), 1e-3, TAU, FINGER_C,
                      pad_layers=tuple(SCENE.pad.layers))
    master = MasterDisplay(DisplayConfig(), closed_form_generator(), 1e-3, TAU, FINGER_C,
                           pad_layers=tuple(SCENE.pad.layers), contact_conductance_w_m2k=H)
    assert master.impedance is not None


def test_the_display_configs_modes_are_enums_taken_from_their_strings():
    from telethermal.teleop.display_config import Before, FeedforwardModel, Idle, Source

    c = DisplayConfig(before="hold", source="setpoints", feedforward_model="static",
                      idle="object")
    assert (c.before, c.source, c.feedforward_model, c.idle) == (
        Before.HOLD, Source.SETPOINTS, FeedforwardModel.STATIC, Idle.OBJECT)
    assert type(c.before) is Before and c.before == "hold"      # a string still compares
    assert DisplayConfig().idle is Idle.POLICY
    for name, bad in (("source", "setpoint"), ("feedforward_model", "dynamic"),
                      ("idle", ["policy"]), ("before", None)):
        with pytest.raises(ControlError, match=re.escape(f"got {bad!r}")) as err:
            DisplayConfig(**{name: bad})
        assert str(err.value).startswith(f"{name} must be one of ")
