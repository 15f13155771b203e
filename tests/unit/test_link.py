"""The master's view of the slave under a network's hard cases (issue 6):
late, reordered and duplicated messages, a clock offset that puts the
anchor in the master's future, a slave that changes its mind, a lost link.
No sockets: the messages are handed to :class:`SlaveLink` in the order a
faulty network would deliver them, and the display is driven with what it
makes of them."""

import math
from dataclasses import replace

import numpy as np
import pytest

from telethermal.render.sampled import sample_curves
from telethermal.teleop.link import SlaveLink
from telethermal.devices.readings import PadSensors
from telethermal.teleop.display_config import DisplayConfig
from telethermal.teleop.master import MasterDisplay
from telethermal.physics.layered import pad_resistance
from telethermal.wire.messages import FluxTrajectory, MaterialEstimate, SessionConfig

from test_master import FINGER_C, OBJECT_C, SCENE, TAU, closed_form_generator

CLASSES = ["plexiglass", "steel"]
CURVES = sample_curves(closed_form_generator(), CLASSES)


def config_msg():
    return SessionConfig(scene="closed-form", sample_rate_hz=1000.0, classes=CLASSES,
                         identifier="test", threshold=0.9, curves=CURVES)


def estimate(cid, t, label="steel", decided=False, p_steel=0.6):
    return MaterialEstimate(contact_id=cid, t_since_contact_s=t, classes=CLASSES,
                            posteriors=[1 - p_steel, p_steel], label=label,
                            confidence=max(p_steel, 1 - p_steel), decided=decided,
                            reason="confident" if decided else "", object_temp_c=OBJECT_C)


def trajectory(cid, material="steel", t0_s=None, scale=1.0, valid_s=60.0):
    c = CURVES[material]
    return FluxTrajectory(contact_id=cid, material=material, object_temp_c=OBJECT_C,
                          t_s=[0.0] + c["t_s"], g_w_m2k=[0.0] + [scale * g for g in c["g_w_m2k"]],
                          valid_s=valid_s, t0_s=t0_s)


def fresh_link():
    link = SlaveLink()
    link.on_message(config_msg(), 0.0)
    return link


def drive(link, deliveries, seconds=1.0, alive=lambda t: True, rate=1000.0):
    """Touch at t = 0 on the master's clock; ``deliveries``: {time: [messages]}
    handed to the link when the master's clock reaches that time. Returns the
    display's steps. The pad's sensors read a fixed contact (the desired flux
    does not depend on them)."""
    master = MasterDisplay(DisplayConfig(feedforward_model="static", rate_hz=rate),
                           link.generator, pad_resistance(SCENE.pad.layers),
                           TAU, FINGER_C, idle_c=OBJECT_C)
    pending = sorted(deliveries.items())
    steps, dt = [], 1.0 / rate
    for k in range(int((0.1 + seconds) * rate)):
        t = k * dt - 0.1
        while pending and pending[0][0] <= t:
            for m in pending.pop(0)[1]:
                link.on_message(m, t, offset_s=0.0)
        onset = master.last_onset_s
        step = master.step(t, dt, PadSensors(-2000.0 + k % 3, 27.0 + 1e-3 * (k % 4),
                                             10.0 if t >= 0 else 0.0),
                           link.news(t, alive(t)))
        if master.last_onset_s != onset:
            link.onset(master.last_onset_s)
        steps.append(step)
    return master, steps


def desired(steps):
    return np.array([s.desired_flux_w_m2 for s in steps])


def test_an_estimate_for_a_contact_that_is_over_is_stale():
    link = fresh_link()
    link.begin(1)
    link.end()
    link.on_message(estimate(1, 0.4, decided=True, p_steel=1.0), 1.0)
    link.on_message(trajectory(1), 1.0)
    assert link.estimates == [] and link.trajectory is None
    assert link.counters["stale"] == 2


def test_two_quick_contacts_with_their_messages_reordered():
    # Contact 1 is lifted early and contact 2 begins; the network delivers
    # contact 2's first estimate, then contact 1's decision and trajectory,
    # then contact 2's later estimates out of order. Only contact 2's count,
    # newest first.
    link = fresh_link()
    link.begin(1)
    link.begin(2)
    for m in (estimate(2, 0.02, "plexiglass", p_steel=0.3), estimate(1, 0.5, decided=True,
              p_steel=1.0), trajectory(1), estimate(2, 0.06, "plexiglass", p_steel=0.2),
              estimate(2, 0.04, "plexiglass", p_steel=0.25)):
        link.on_message(m, 0.5, offset_s=0.0)
    assert [e.t_s for e in link.estimates] == [0.02, 0.06]
    assert link.news(0.5, True).estimate.posteriors == (0.8, 0.2)
    assert link.trajectory is None
    assert link.counters["stale"] == 2 and link.counters["older_estimate"] == 1


@pytest.mark.parametrize("clock_error_s", [0.0, 5.0])
def test_an_anchor_in_the_masters_future_is_counted_and_not_waited_for(clock_error_s):
    # The slave touched 0.15 s after the master; its trajectory says so on the
    # slave's clock. With a 5 s error in the offset estimate the anchor lands
    # 5 s in the master's future: the master plays from its own onset all the
    # same, so the rendered flux is identical to the right-offset case.
    def run(error):
        link = fresh_link()
        link.begin(1)
        msgs = [estimate(1, 0.3, decided=True, p_steel=1.0), trajectory(1, t0_s=0.15 + error)]
        return link, desired(drive(link, {0.35: msgs})[1])

    right_link, right = run(0.0)
    link, rendered = run(clock_error_s)
    np.testing.assert_array_equal(rendered, right)
    assert np.isfinite(rendered[-500:]).all()
    if clock_error_s:
        assert link.counters["anchor_in_future"] == 1 and math.isnan(link.anchor_lag_s)
    else:
        assert link.anchor_lag_s == pytest.approx(0.15, abs=1e-9)


def test_a_duplicated_trajectory_changes_nothing():
    def run(copies):
        link = fresh_link()
        link.begin(1)
        msgs = [estimate(1, 0.3, decided=True, p_steel=1.0)] + [trajectory(1)] * copies
        return link, desired(drive(link, {0.35: msgs[:2], 0.6: msgs[2:]})[1])

    _, once = run(1)
    link, thrice = run(3)
    np.testing.assert_array_equal(thrice, once)
    assert link.counters["duplicate_trajectory"] == 2
    assert link.counters["replaced_trajectory"] == 0


def test_a_slave_that_changes_its_mind_replaces_the_trajectory_without_a_step():
    link = fresh_link()
    link.begin(1)
    master, steps = drive(link, {
        0.3: [estimate(1, 0.25, decided=True, p_steel=1.0), trajectory(1)],
        0.6: [estimate(1, 0.55, "plexiglass", decided=True, p_steel=0.0),
              trajectory(1, "plexiglass")]})
    q = desired(steps)
    t = np.arange(len(q)) * 1e-3 - 0.1
    assert link.counters["replaced_trajectory"] == 1
    assert master.rendering == "plexiglass" and master.events["decision changed"] == 1
    gen = closed_form_generator()
    jump = abs((gen.normalised("steel", 0.6)[0] - gen.normalised("plexiglass", 0.6)[0])
               * (OBJECT_C - FINGER_C))
    around = (t > 0.55) & (t < 0.8)
    assert np.max(np.abs(np.diff(q[around]))) < 0.1 * jump     # blended, no step


def test_link_loss_keeps_a_valid_trajectory_and_decays_without_one():
    limits = DisplayConfig().limits
    slew = DisplayConfig().slew_k_s * 1e-3 + 1e-9
    down = lambda t: not (0.4 <= t < 0.9)                     # noqa: E731

    # With a trajectory valid for 60 s: rendering goes on through the outage.
    link = fresh_link()
    link.begin(1)
    _, steps = drive(link, {0.2: [estimate(1, 0.15, decided=True, p_steel=1.0),
                                  trajectory(1)]}, alive=down)
    assert all(s.phase == "render" for s in steps if 0.25 < s.t_s < 1.0)
    # So does a final "unknown" (its posterior mixture is rendered).
    link = fresh_link()
    link.begin(1)
    final_unknown = replace(estimate(1, 0.15, "unknown", p_steel=0.7), decided=True,
                            reason="not confident")
    _, steps = drive(link, {0.2: [final_unknown]}, alive=down)
    assert all(s.phase == "contact" and math.isfinite(s.desired_flux_w_m2)
               for s in steps if 0.25 < s.t_s < 1.0)

    # With only posteriors (or a trajectory past its valid_s): the pad goes to
    # neutral at no more than the slew limit, then resumes without a step.
    for deliveries in ({0.2: [estimate(1, 0.15, p_steel=0.6)]},
                       {0.2: [estimate(1, 0.15, decided=True, p_steel=1.0),
                              trajectory(1, valid_s=0.3)]}):
        link = fresh_link()
        link.begin(1)
        master, steps = drive(link, deliveries, seconds=1.5, alive=down)
        phases = {s.phase for s in steps if 0.45 < s.t_s < 0.9}
        assert phases == {"link lost"}
        applied = np.array([s.junction_applied_c for s in steps])
        t = np.array([s.t_s for s in steps])
        assert applied[(t > 0.85) & (t < 0.9)] == pytest.approx(limits.neutral_c)
        assert np.max(np.abs(np.diff(applied))) <= slew
        assert steps[-1].phase in ("contact", "render") and master.events["link lost"] == 1
        assert np.isfinite(desired(steps)[t > 1.0]).all()
