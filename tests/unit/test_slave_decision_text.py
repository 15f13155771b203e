"""The slave's "decided" and "touch over" lines give the same time for the
same touch: the time the identified label itself was decided, and the group
the pad committed to first when there was one (issue 28: "decided ...
t=0.30 s" against "(decided at 0.04 s)" for one touch)."""


from telethermal.ident.anytime import Estimate
from telethermal.teleop.decision import pad_decision, touch_decision
from telethermal.teleop.slave import Slave, SlaveEvent


def _pad(*estimates):
    pad = Slave.__new__(Slave)                # only the events matter here
    pad.events = [SlaveEvent(e.t_s, e) for e in estimates]
    return pad


def _est(t_s, label, decided, reason=""):
    return Estimate(t_s, (0.5, 0.5), label, 0.9, decided, reason)


def test_a_group_refined_later_names_both_times():
    pad = _pad(_est(0.02, "aluminium", False), _est(0.04, "aluminium|steel", True,
                                                       "confident group"),
               _est(0.30, "aluminium", True, "confident"))
    assert pad.committed_at_s == 0.04 and pad.decided_at_s("aluminium") == 0.30
    text = pad_decision(pad).text()
    assert text == "decided at 0.30 s, after committing to aluminium|steel at 0.04 s"


def test_a_direct_decision_has_one_time():
    pad = _pad(_est(0.02, "wood", False), _est(0.08, "wood", True, "confident"))
    assert pad_decision(pad).text() == "decided at 0.08 s"
    assert pad.committed_at_s == pad.decided_at_s("wood") == 0.08


def test_a_group_that_stands_is_decided_when_first_committed():
    pad = _pad(_est(0.06, "plexiglass|rubber", True, "confident group"),
               _est(1.0, "plexiglass|rubber", True, "confident group"))
    assert pad_decision(pad).text() == "decided at 0.06 s"


def test_the_master_reports_the_slaves_times():
    """The master's summary takes the estimates it heard through the same
    definition (teleop/decision.py): a group that stood was decided at its
    first commitment; a group refined later committed at the group's time
    (``decision_time_s``, as the slave reports it; the master said the
    member's time before issue 45) and identified at the member's."""
    group = [_est(0.06, "plexiglass|rubber", True, "confident group"),
             _est(0.5, "plexiglass|rubber", True, "confident group"),
             _est(1.0, "plexiglass|rubber", True, "confident group")]
    assert touch_decision(group).fields() == {
        "identified": "plexiglass|rubber", "decision_time_s": 0.06, "identified_at_s": 0.06}
    refined = [_est(0.04, "aluminium|steel", True, "confident group"),
               _est(0.22, "aluminium", True, "confident")]
    assert touch_decision(refined).fields() == {
        "identified": "aluminium", "decision_time_s": 0.04, "identified_at_s": 0.22}
    assert touch_decision(refined).fields() == pad_decision(_pad(*refined)).fields()
    assert touch_decision([]).fields() == {
        "identified": "unknown", "decision_time_s": None, "identified_at_s": None}
    assert touch_decision([_est(0.3, "wood", False)]).fields() == {
        "identified": "unknown", "decision_time_s": None, "identified_at_s": None}
