"""The master's session rules (teleop/session.py, issue 26), with no
socket and no clock: the contact events it sends for the display's onset
and release, what it keeps of the slave's messages, and the hard cases (a
decision and its trajectory reordered, a setpoint of another contact or
older than the one held, a touch that ends with no release detected)."""

import math
from dataclasses import dataclass, replace

import pytest

from telethermal.control.contact import ContactChange
from telethermal.render.sampled import SampledGenerator
from telethermal.teleop.link import SlaveLink
from telethermal.teleop.session import MasterSession, SlaveSession
from telethermal.wire import messages as wire

CLASSES = ("aluminium", "wood")
CURVES = {m: {"t_s": [0.1, 1.0], "g_w_m2k": [1000.0 * (i + 1), 500.0 * (i + 1)]}
          for i, m in enumerate(CLASSES)}


@dataclass
class Step:
    contact: ContactChange | None


def session() -> MasterSession:
    s = MasterSession(SlaveLink(generator=SampledGenerator(CURVES), classes=CLASSES))
    s.on_message(wire.ContactEvent(contact_id=0, touching=False, t_s=0.0, force_n=0.0,
                                   object_temp_c=22.0, object_id="a", object_material=None,
                                   object_confidence=None), 0.0)
    return s


def estimate(contact_id, t, label="aluminium", decided=True):
    return wire.MaterialEstimate(contact_id=contact_id, t_since_contact_s=t,
                                 classes=list(CLASSES), posteriors=[1.0, 0.0], label=label,
                                 confidence=0.99, decided=decided, reason="confident",
                                 object_temp_c=22.0)


def trajectory(contact_id, label="aluminium"):
    c = CURVES[label]
    return wire.FluxTrajectory(contact_id=contact_id, material=label, object_temp_c=22.0,
                               t_s=[0.0] + c["t_s"], g_w_m2k=[0.0] + c["g_w_m2k"],
                               valid_s=60.0, t0_s=10.0)


def test_onset_and_release_become_contact_events_with_fresh_ids():
    s = session()
    out = s.period(Step(ContactChange(True, 0.25)), 10.0, 2.0, 31.0)
    assert [(o.kind, o.message.contact_id, o.message.touching, o.t_s) for o in out] == \
        [("contact_event", 1, True, 10.25)]
    assert out[0].lossless and out[0].message.finger_temp_c == 31.0
    assert s.link.contact_id == 1 and s.link.onset_s == 10.25
    assert s.period(Step(None), 10.0, 2.0, 31.0) == []
    out = s.period(Step(ContactChange(False, 1.5)), 10.0, 0.0, 31.0)
    assert [(o.message.contact_id, o.message.touching, o.t_s) for o in out] == \
        [(1, False, 11.5)]
    assert s.contact_id is None and s.link.contact_id is None
    out = s.period(Step(ContactChange(True, 3.0)), 10.0, 2.0, 31.0)
    assert out[0].message.contact_id == 2
    # The driver's touch ends with the contact open: the slave hears the lift.
    out = s.close_contact(14.0, 31.0)
    assert [(o.message.contact_id, o.message.touching) for o in out] == [(2, False)]
    assert s.close_contact(14.0, 31.0) == []


@pytest.mark.parametrize("order", ["decision first", "trajectory first"])
def test_a_reordered_decision_and_trajectory_leave_the_same_news(order):
    s = session()
    s.period(Step(ContactChange(True, 0.0)), 10.0, 2.0, 31.0)
    messages = [estimate(1, 0.08), trajectory(1)]
    if order == "trajectory first":
        messages.reverse()
    for i, m in enumerate(messages):
        s.on_message(m, 10.1 + 0.01 * i, 0.0)
    news = s.news(10.2, True)
    assert news.estimate.label == "aluminium" and news.estimate.decided
    assert s.link.trajectory.material == "aluminium"
    assert s.trajectory_at_s == pytest.approx(10.1 if order == "trajectory first" else 10.11)
    assert s.first_news_s == pytest.approx(10.11 if order == "trajectory first" else 10.1)


def test_messages_of_another_contact_are_stale_and_setpoints_keep_the_newest():
    s = session()
    s.period(Step(ContactChange(True, 0.0)), 10.0, 2.0, 31.0)
    sp = lambda cid, t, f: wire.FluxSetpoint(contact_id=cid,                  # noqa: E731
                                             t_since_contact_s=t, flux_w_m2=f)
    s.on_message(sp(1, 0.20, -900.0), 10.2)
    s.on_message(sp(1, 0.10, -100.0), 10.21)          # older, arrived late: ignored
    s.on_message(sp(7, 0.30, -5.0), 10.22)            # another contact: ignored
    assert s.news(10.3, True).setpoint_w_m2 == -900.0
    s.on_message(estimate(7, 0.05), 10.3)
    assert s.link.counters["stale"] == 1 and s.first_news_s is None
    s.period(Step(ContactChange(False, 1.0)), 10.0, 0.0, 31.0)
    s.on_message(estimate(1, 0.9), 11.2)              # after the lift: stale
    assert s.link.counters["stale"] == 2
    s.period(Step(ContactChange(True, 2.0)), 10.0, 2.0, 31.0)
    assert s.news(12.1, True).setpoint_w_m2 is None and math.isinf(s.setpoint_t_s)


class FakePad:
    """What the slave session reads of a pad that never reached its onset."""
    classes = CLASSES
    object_ir_c = 22.0
    onset_s = None
    estimate = None
    stream = None
    samples_read = 0

    def advance_to(self, t_s):
        return []


def test_the_slave_session_lifts_only_the_contact_of_its_owner():
    s = SlaveSession(CURVES, 100.0)
    with pytest.raises(ValueError, match="no object placed"):
        s.touch(1, 0.0, 31.0)
    s.place(FakePad(), "a")
    touch = wire.ContactEvent(contact_id=4, touching=True, t_s=5.0, force_n=2.0)
    assert s.classify(touch, "m1") == "touch"
    s.touch(4, 5.0, 31.0, owner="m1")
    assert s.classify(touch, "m1") == "ignored"        # a touch during a contact
    lift = wire.ContactEvent(contact_id=4, touching=False, t_s=5.2, force_n=0.0)
    assert s.classify(lift, "m2") == "ignored"         # another master session
    assert s.classify(replace(lift, contact_id=3), "m1") == "ignored"
    assert s.classify(lift, "m1") == "lift"
    with pytest.raises(ValueError, match="during a contact"):
        s.place(FakePad(), "b")
    # A contact that ends before the pad's onset: the lift alone, nothing learned.
    assert s.step(5.1) == []
    out, verdict = s.lift(5.2)
    assert [(o.kind, o.message.touching) for o in out] == [("contact_event", False)]
    assert verdict == "ignored" and not s.touching
    assert s.lift(5.3) == ([], "ignored")
    with pytest.raises(ValueError, match="estimates must be"):
        SlaveSession(CURVES, 100.0, estimates="carrier pigeon")


def test_a_slave_restarted_mid_contact_reaches_the_display_as_news():
    # The restarted slave sends its session_config anew: the display renders
    # its curves from the next period's news (no driver assigns the display's
    # generator), and the master's own contact stays open until its release.
    from telethermal.devices.readings import PadSensors
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.teleop.master import MasterDisplay

    s = session()
    s.period(Step(ContactChange(True, 0.0)), 10.0, 2.0, 31.0)
    display = MasterDisplay(DisplayConfig(feedforward_model="static", rate_hz=1000.0), None,
                            1e-3, 0.01, 31.0, idle_c=22.0)
    display.step(0.0, 1e-3, PadSensors(0.0, 22.0, 0.0), s.news(10.0, True))
    before = display.generator
    assert before is s.link.generator
    curves = {m: {"t_s": [0.1, 1.0], "g_w_m2k": [7000.0, 3000.0]} for m in CLASSES}
    s.on_message(wire.SessionConfig(scene="x", sample_rate_hz=100.0, classes=list(CLASSES),
                                    identifier="m", threshold=0.9, curves=curves), 10.5)
    s.on_message(wire.ContactEvent(contact_id=0, touching=False, t_s=10.5, force_n=0.0,
                                   object_temp_c=22.0, object_id="a"), 10.5)
    display.step(0.001, 1e-3, PadSensors(0.0, 22.0, 0.0), s.news(10.501, True))
    assert display.generator is not before and display.generator is s.link.generator
    assert s.contact_id == 1 and s.link.contact_id == 1


def test_the_last_contacts_decision_is_not_news_at_the_next_onset():
    # make demo caught it: the display steps on the news read before the
    # period's onset opens the new contact; the previous touch's decision
    # (aluminium) was still held then, and the display rendered it on the
    # next object (plexiglass: 5.2 K skin error on the services).
    s = session()
    s.period(Step(ContactChange(True, 0.0)), 10.0, 2.0, 31.0)
    s.on_message(estimate(1, 0.08), 10.1, 0.0)
    assert s.news(10.2, True).estimate.label == "aluminium"
    s.period(Step(ContactChange(False, 1.0)), 10.0, 0.0, 31.0)
    assert s.news(12.0, True).estimate is None          # between contacts
    s.period(Step(ContactChange(True, 3.0)), 10.0, 2.0, 31.0)
    assert s.news(13.0, True).estimate is None          # the new contact's own only
