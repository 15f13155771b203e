"""The slave's "decided" and "touch over" lines give the same time for the
same touch: the time the identified label itself was decided, and the group
the pad committed to first when there was one (issue 28: "decided ...
t=0.30 s" against "(decided at 0.04 s)" for one touch)."""


from telethermal.ident.anytime import Estimate
from telethermal.services.slave import decision_text
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
    text = decision_text(pad, "aluminium")
    assert text == "decided at 0.30 s, after committing to aluminium|steel at 0.04 s"


def test_a_direct_decision_has_one_time():
    pad = _pad(_est(0.02, "wood", False), _est(0.08, "wood", True, "confident"))
    assert decision_text(pad, "wood") == "decided at 0.08 s"
    assert pad.committed_at_s == pad.decided_at_s("wood") == 0.08


def test_a_group_that_stands_is_decided_when_first_committed():
    pad = _pad(_est(0.06, "plexiglass|rubber", True, "confident group"),
               _est(1.0, "plexiglass|rubber", True, "confident group"))
    assert decision_text(pad, "plexiglass|rubber") == "decided at 0.06 s"


def test_the_master_reports_the_same_time_for_a_group_that_stood():
    from telethermal.services.master import decided_at_s
    group = [_est(0.06, "plexiglass|rubber", True, "confident group"),
             _est(0.5, "plexiglass|rubber", True, "confident group"),
             _est(1.0, "plexiglass|rubber", True, "confident group")]
    assert decided_at_s(group, group[-1]) == 0.06
    refined = [_est(0.04, "aluminium|steel", True, "confident group"),
               _est(0.22, "aluminium", True, "confident")]
    assert decided_at_s(refined, refined[-1]) == 0.22
    assert decided_at_s([], None) is None
    assert decided_at_s([], _est(0.3, "wood", False)) is None
