"""One definition of what a touch decided (issue 45, deliverable 2):
teleop/decision.py's ``touch_decision`` gives the ``identified``,
``decision_time_s`` and ``identified_at_s`` of every touch summary. Cases
where the summaries used to differ (the in-process run, the slave service,
the master service): a touch that said only "unknown" (the slave reported
no time), a group refined later (the master reported the member's time), a
touch that committed and was then revised to "unknown", estimates that
arrive out of order (the master's accepted list), and a newer undecided
posterior after a decision."""

from telethermal.ident.anytime import Estimate, Reason
from telethermal.teleop.decision import touch_decision


def _est(t_s, label, decided=True, reason=Reason.CONFIDENT):
    return Estimate(t_s, (0.5, 0.5), label, 0.9, decided, reason)


def test_a_touch_that_said_only_unknown_was_decided_when_it_said_so():
    d = touch_decision([_est(0.02, "wood", False),
                        _est(0.5, "unknown", reason=Reason.NOT_CONFIDENT)])
    assert d.fields() == {"identified": "unknown", "decision_time_s": 0.5,
                          "identified_at_s": None}
    assert d.estimate.reason == Reason.NOT_CONFIDENT and d.committed is None


def test_a_commitment_revised_to_unknown_keeps_its_commitment_time():
    d = touch_decision([_est(0.06, "wood"),
                        _est(0.8, "unknown", reason=Reason.PAD_MODEL_MISFIT)])
    assert d.fields() == {"identified": "unknown", "decision_time_s": 0.06,
                          "identified_at_s": None}


def test_a_change_of_mind_is_identified_at_its_own_time_and_committed_at_the_first():
    d = touch_decision([_est(0.06, "graphite"), _est(1.0, "new material",
                                                     reason=Reason.NEW_MATERIAL)])
    assert d.fields() == {"identified": "new material", "decision_time_s": 0.06,
                          "identified_at_s": 1.0}


def test_the_order_of_arrival_does_not_matter_and_a_later_posterior_does_not_undecide():
    estimates = [_est(0.04, "aluminium|steel", reason=Reason.CONFIDENT_GROUP),
                 _est(0.22, "aluminium"), _est(0.3, "aluminium", decided=False)]
    want = {"identified": "aluminium", "decision_time_s": 0.04, "identified_at_s": 0.22}
    assert touch_decision(estimates).fields() == want
    assert touch_decision(reversed(estimates)).fields() == want
    assert touch_decision([None, *estimates]).fields() == want


def test_every_summary_says_when_alike():
    """The demo's line, admin touch and the master's log word the fields
    one way (teleop/decision.when_decided)."""
    from telethermal.services.admin_client import describe_touch
    from telethermal.teleop.decision import when_decided

    refined = touch_decision([_est(0.06, "plexiglass|rubber", reason=Reason.CONFIDENT_GROUP),
                              _est(0.38, "plexiglass")]).fields()
    assert when_decided(refined) == "at 0.38 s (first committed at 0.06 s)"
    assert when_decided(touch_decision([_est(0.06, "wood")]).fields()) == "at 0.06 s"
    assert when_decided(touch_decision([]).fields()) is None
    line = describe_touch({"contact_id": 1, **refined, "render_start_s": 0.4,
                           "safety_events": 0, "rtt_s": None, "direct": None})[0]
    assert "(decided at 0.38 s (first committed at 0.06 s))" in line
