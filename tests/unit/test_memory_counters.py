"""The memory's counters mean one thing on both sides (issue 45, deliverable
2): ``memory_overruled`` counts a touch whose decision disagreed with what
the memory announced for the object, ``memory_kept`` one that named a class
early on a remembered new material, its estimate consistent with the
remembered one (PROTOCOL.md sections 4, 6b, 6c). The slave (its session, at
the lift, on the touch's final decision) and the master (its link, as the
decision arrives) judge the same touch by one rule, :func:`judge`; the
slave service counts through its session.

Before this, the slave service counted every touch the memory weighed as a
disagreement (``kept``, ``doubted``, ``overruled``, ``replaced``) as
``memory_overruled``, so a class consistent with a remembered new material
was ``memory_kept`` on the master and ``memory_overruled`` on the slave; and
the master did not count a new material inconsistent with the remembered
one, which the slave's memory takes as another object's."""

import pytest

from telethermal.ident.anytime import NEW_MATERIAL, Estimate, Reason
from telethermal.teleop.memory import Judgement, ObjectMemory, judge
from telethermal.teleop.session import SlaveSession

from test_link import CLASSES, CURVES, OBJECT_C, fresh_link

#: A remembered new material's estimate (W s^0.5/(m^2 K)): e, lo, hi.
GLASS = (1390.0, 1270.0, 1520.0)


def _decision(label, e=None, lo=None, hi=None):
    p_steel = 0.995 if label == "steel" else 0.005
    reason = Reason.NEW_MATERIAL if label == NEW_MATERIAL else Reason.CONFIDENT
    return Estimate(0.5, (1.0 - p_steel, p_steel), label, 0.995, True, reason, e, lo, hi)


class DecidedPad:
    """What the slave session reads of a pad whose touch ended on ``estimate``."""
    classes = tuple(CLASSES)
    object_ir_c = OBJECT_C
    onset_s = 0.01
    stream = None
    samples_read = 0

    def __init__(self, estimate):
        self.estimate = estimate


def _one_touch(remembered: Estimate, final: Estimate, early=()) -> tuple[dict, dict]:
    """One touch of an object the slave's memory learnt from ``remembered``,
    ending on ``final`` (after the decisions ``early``, sent as they came):
    the slave session's counters and the master link's, the link told what
    the session announced and sent, then the master's contact ending."""
    memory = ObjectMemory(0.99)
    memory.learn("thing", remembered, 1.0, CLASSES)
    slave = SlaveSession(CURVES, 1000.0, memory=memory)
    slave.place(DecidedPad(final), "thing")
    link = fresh_link()
    link.on_message(slave.announcement(0.0).message, 0.0)
    slave.touch(7, 0.0, 31.0)
    link.begin(7)
    assert link.counters["memory_used"] == 1
    for i, e in enumerate(early):
        slave.pad.estimate = e
        link.on_message(slave._decision(0.1 * (i + 1), e).message, 0.1 * (i + 1), 0.0)
    slave.pad.estimate = final
    sends, _ = slave.lift(1.0)          # the final decision, then the lift
    for s in sends:
        link.on_message(s.message, 1.0, 0.0)
    link.end()                          # the master's contact ends
    keys = ("memory_overruled", "memory_kept")
    return {k: slave.counters[k] for k in keys}, {k: link.counters[k] for k in keys}


NEW = _decision(NEW_MATERIAL, *GLASS)


@pytest.mark.parametrize("remembered, final, overruled, kept", [
    # A class whose estimate holds the remembered new material's: kept.
    (NEW, _decision("steel", 1600.0, 900.0, 2900.0), 0, 1),
    # A class far from it, or one without an estimate (an older identifier): overruled.
    (NEW, _decision("steel", 14000.0, 12500.0, 15500.0), 1, 0),
    (NEW, _decision("steel"), 1, 0),
    # Another new material (inconsistent estimates): overruled; the same one: neither.
    (NEW, _decision(NEW_MATERIAL, 20000.0, 18000.0, 22000.0), 1, 0),
    (NEW, _decision(NEW_MATERIAL, 1420.0, 1330.0, 1510.0), 0, 0),
    # Classes: another one disagrees, the same agrees.
    (_decision("plexiglass"), _decision("steel"), 1, 0),
    (_decision("steel"), _decision("steel"), 0, 0),
])
def test_the_slave_and_the_master_count_the_same_touch_alike(remembered, final, overruled,
                                                             kept):
    slave, master = _one_touch(remembered, final)
    assert slave == master == {"memory_overruled": overruled, "memory_kept": kept}


def test_a_touch_with_several_decisions_is_counted_once_on_its_last():
    """The review's case (PROTOCOL.md 6c): an object remembered as a new
    material, two early classes consistent with its estimate, then the
    same new material: nothing counted on either side (the master counted
    memory_kept per early decision before); an early disagreement refined
    to agree is not a disagreement either."""
    early = (_decision("steel", 1600.0, 900.0, 2900.0),) * 2
    final = _decision(NEW_MATERIAL, 1420.0, 1330.0, 1510.0)
    assert _one_touch(NEW, final, early) == ({"memory_overruled": 0, "memory_kept": 0},) * 2
    assert _one_touch(_decision("plexiglass"), _decision("plexiglass"),
                      (_decision("steel"),)) == ({"memory_overruled": 0, "memory_kept": 0},) * 2
    # Ending on the early class: kept, once.
    assert _one_touch(NEW, early[0], early) == ({"memory_overruled": 0, "memory_kept": 1},) * 2


def test_an_undecided_or_unknown_decision_says_nothing_of_the_memory():
    undecided = Estimate(0.5, (0.4, 0.6), "steel", 0.6, False, "")
    unknown = Estimate(0.5, (0.5, 0.5), "unknown", 0.5, True, Reason.NOT_CONFIDENT)
    assert judge("plexiglass", None, undecided) is None
    assert judge("plexiglass", None, unknown) is None
    assert _one_touch(_decision("plexiglass"), unknown)[0] == \
        {"memory_overruled": 0, "memory_kept": 0}
    # A vaguer decision (a pair holding the remembered material) leaves it in force.
    pair = Estimate(0.5, (0.5, 0.5), "plexiglass|steel", 0.995, True, Reason.CONFIDENT_GROUP)
    assert judge("plexiglass", None, pair) == Judgement.VAGUER


@pytest.fixture(scope="module")
def models(trained_models):
    from test_sim_network import SCENE
    return trained_models.pair(SCENE, 0)


def test_a_touch_against_the_memory_counts_alike_in_process_and_on_the_simulated_network(
        models):
    """The same wood touch of an object remembered as steel, in process and
    over the simulated network (the services: tests/integration/
    test_services.py, the link's and the slave's status counters): one
    disagreement on each side, nothing kept; and the same decision fields
    (teleop/decision.py)."""
    from test_sim_network import SCENE, touch

    from telethermal.render.sampled import sample_curves
    from telethermal.sim.inprocess import run_session

    identifier, generator = models
    steel = Estimate(0.5, (), "steel", 0.99, True, Reason.CONFIDENT)
    local = run_session(SCENE, "wood", identifier, generator, contact_s=1.0, seed=6,
                        expected_material=steel).summary
    memory = ObjectMemory()
    memory.learn("wood", steel, 0.0)
    curves = sample_curves(generator, [m for m in generator.materials
                                       if m in identifier.classes_])
    network = touch((identifier, curves), "wood", seed=6, object_id="wood", memory=memory)
    want = {"master": {"memory_overruled": 1, "memory_kept": 0},
            "slave": {"memory_overruled": 1, "memory_kept": 0}}
    assert local["memory_counts"] == network["memory_counts"] == want
    fields = ("identified", "decision_time_s", "identified_at_s")
    assert local["identified"] == "wood"
    assert {k: local[k] for k in fields} == {k: network[k] for k in fields}
