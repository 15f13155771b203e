"""Issue 15's rules for what the master makes of the slave's estimates and
object memory (``SlaveLink``), with the messages handed over in the order
a faulty network delivers them, and the slave's :class:`ObjectMemory`."""

from dataclasses import replace

from telethermal.ident.anytime import Estimate
from telethermal.teleop.link import SlaveLink
from telethermal.teleop.memory import FROM_MEMORY, ObjectMemory
from telethermal.wire.messages import ContactEvent, PosteriorEstimate

from test_link import CLASSES, OBJECT_C, config_msg, drive, estimate, fresh_link


def posterior(cid, t, **kw):
    return PosteriorEstimate(**estimate(cid, t, **kw).fields())


def announce(object_id, material=None, confidence=None):
    return ContactEvent(contact_id=0, touching=False, t_s=0.0, force_n=0.0,
                        object_temp_c=OBJECT_C, object_id=object_id, object_material=material,
                        object_confidence=confidence)


def test_a_late_decision_is_not_replaced_by_newer_posteriors():
    link = fresh_link()
    link.begin(1)
    for t in (0.01, 0.02, 0.03):
        link.on_message(posterior(1, t), 0.0)
    # The decision at 0.02 was lost and arrives resent after newer posteriors.
    link.on_message(estimate(1, 0.02, decided=True, p_steel=0.99), 0.0)
    assert link.estimate.decided and link.estimate.label == "steel"
    link.on_message(posterior(1, 0.04), 0.0)              # undecided, newer
    assert link.estimate.decided
    assert link.counters["older_estimate"] == 0
    link.on_message(posterior(1, 0.015), 0.0)             # older posterior: dropped
    assert link.counters["older_estimate"] == 1


def test_a_repeated_touch_renders_the_remembered_material_from_t0():
    link = fresh_link()
    link.on_message(announce("plate", "steel", 0.98), 0.0)
    link.begin(1)
    _, steps = drive(link, {}, seconds=0.2)
    during = [s for s in steps if s.t_s >= 0.03]
    assert during and all(s.phase == "render" for s in during)
    assert link.estimate.reason == FROM_MEMORY and link.counters["memory_used"] == 1


def test_fresh_identification_wins_over_memory_and_is_counted():
    link = fresh_link()
    link.on_message(announce("plate", "steel", 0.98), 0.0)
    link.begin(1)
    assert link.estimate.label == "steel"
    link.on_message(posterior(1, 0.05, label="plexiglass", p_steel=0.3), 0.0)
    assert link.estimate.label == "steel"              # an undecided posterior: memory holds
    link.on_message(estimate(1, 0.1, label="plexiglass", decided=True, p_steel=0.01), 0.0)
    assert link.estimate.label == "plexiglass" and link.counters["memory_overruled"] == 0
    link.end()                                         # counted once, at the contact's end
    assert link.counters["memory_overruled"] == 1


def test_an_unknown_decision_does_not_erase_the_memory():
    link = fresh_link()
    link.on_message(announce("plate", "steel", 0.98), 0.0)
    link.begin(1)
    link.on_message(estimate(1, 1.0, label="unknown", decided=True, p_steel=0.5), 0.0)
    link.end()
    assert link.estimate.label == "steel" and link.counters["memory_overruled"] == 0


def test_a_touch_on_another_object_drops_the_memory():
    link = fresh_link()
    link.on_message(announce("plate", "steel", 0.98), 0.0)
    link.begin(3)
    touching = replace(announce("cup"), contact_id=3, touching=True)
    link.on_message(touching, 0.0)
    assert link.estimate is None and link.counters["memory_mismatch"] == 1
    # ...and the announcement of the other object (reordered after it) does
    # not bring the old one back for this contact, but serves the next.
    link.on_message(announce("cup", None), 0.0)
    assert link.estimate is None
    link.begin(4)
    assert link.estimate is None


def test_announcements_in_order_last_one_holds():
    link = fresh_link()
    link.on_message(announce("plate", "steel", 0.98), 0.0)
    link.on_message(announce("cup", "plexiglass", 0.97), 0.0)
    link.begin(1)
    assert link.estimate.label == "plexiglass"
    link.on_message(announce("new", None), 0.0)         # unknown object: nothing remembered
    link.begin(2)
    assert link.estimate is None


def test_a_restarted_slave_announces_nothing_remembered():
    link = fresh_link()
    link.on_message(announce("plate", "steel", 0.98), 0.0)
    link.on_message(config_msg(), 0.0)                     # the slave restarted
    link.on_message(announce("plate", None), 0.0)          # its memory is empty
    link.begin(1)
    assert link.estimate is None


def decided(label, reason="confident", t_s=0.5, confidence=0.99):
    return Estimate(t_s, (0.0,) * len(CLASSES), label, confidence, True, reason)


def test_object_memory_learns_decisions_and_sharpens_them():
    memory = ObjectMemory()
    assert memory.learn("plate", decided("unknown", "gap too small"), 1.0) == "ignored"
    assert memory.learn("plate", decided("steel", FROM_MEMORY), 1.0) == "ignored"
    assert memory.learn(None, decided("steel"), 1.0) == "ignored"
    assert memory.learn("plate", Estimate(0.1, (), "steel", 0.6, False, ""), 1.0) == "ignored"
    assert memory.recall("plate") is None
    assert memory.learn("plate", decided("plexiglass|steel", "confident group"), 1.0) == "learned"
    assert memory.recall("plate").material == "plexiglass|steel"
    assert memory.learn("plate", decided("steel"), 1.5) == "refined"
    assert memory.learn("plate", decided("steel", confidence=0.95), 2.0) == "confirmed"
    assert memory.learn("plate", decided("plexiglass|steel", "confident group"), 2.5) == \
        "confirmed"                                       # vaguer: the member stays
    r = memory.recall("plate")
    assert (r.material, r.touches) == ("steel", 4) and r.confidence > 0.999
    assert memory.counters["learned"] == 1 and memory.counters["refined"] == 1
    assert memory.counters["confirmed"] == 2
    memory.forget("plate")
    assert len(memory) == 0 and memory.to_dict() == {}


CLASSES7 = ("aluminium", "graphite", "marble", "plexiglass", "rubber", "steel", "wood")


def touch(label, p_label=0.995, p_second=None, second=None):
    """A decided touch with posteriors over CLASSES7: ``p_label`` on its
    material, ``p_second`` on ``second``, the rest shared."""
    p = {c: 0.0 for c in CLASSES7}
    p[label] = p_label
    if second:
        p[second] = p_second
    rest = (1.0 - sum(p.values())) / sum(v == 0.0 for v in p.values())
    post = tuple(v if v else rest for v in p.values())
    return Estimate(0.3, post, label, p_label, True, "confident")


def test_the_memory_is_the_normalised_product_of_its_touches_posteriors():
    """Closed form: two touches with posteriors p and q (above the floor):
    the memory's posterior is p q / sum(p q) (touches independent given the
    material, equal priors), to 1e-9."""
    memory = ObjectMemory()
    a = touch("rubber", 0.7, 0.25, "plexiglass")
    b = touch("rubber", 0.6, 0.38, "plexiglass")
    memory.learn("ball", a, 1.0, classes=CLASSES7)
    memory.learn("ball", b, 2.0, classes=CLASSES7)
    pq = [x * y for x, y in zip(a.posteriors, b.posteriors)]
    expected = {c: v / sum(pq) for c, v in zip(CLASSES7, pq)}
    got = memory.to_dict()["ball"]["posteriors"]
    assert all(abs(got[c] - expected[c]) < 1e-6 for c in CLASSES7)   # rounded to 1e-6
    # No touch disagreed: announced as what they decided, with the evidence's posterior.
    r = memory.recall("ball")
    assert r.material == "rubber" and abs(r.confidence - expected["rubber"]) < 1e-12


def test_a_single_touch_committed_at_the_threshold_is_announced_as_decided():
    # Its ruled-out classes floored, the touch's material is below 0.99
    # (0.992 / (0.992 + 0.008 + 5e-3)): the floor weighs disagreements only.
    memory = ObjectMemory()
    memory.learn("plate", touch("aluminium", 0.992, 0.008, "steel"), 1.0, classes=CLASSES7)
    r = memory.recall("plate")
    assert r.material == "aluminium" and r.confidence < 0.99


def test_one_wrong_decision_cannot_flip_a_memory_of_two_right_ones():
    memory = ObjectMemory()
    for t in (1.0, 2.0):
        memory.learn("ball", touch("rubber", 0.999), t, classes=CLASSES7)
    # A confident wrong decision (its posterior of rubber far below the floor).
    wrong = Estimate(0.1, tuple(0.9999994 if c == "plexiglass" else 1e-7 for c in CLASSES7),
                     "plexiglass", 0.9999994, True, "confident")
    assert memory.learn("ball", wrong, 3.0, classes=CLASSES7) == "kept"
    assert memory.recall("ball").material == "rubber" and memory.counters["kept"] == 1
    # Against a single right touch, the same wrong one leaves the honest pair.
    single = ObjectMemory()
    single.learn("ball", touch("rubber", 0.999), 1.0, classes=CLASSES7)
    assert single.learn("ball", wrong, 2.0, classes=CLASSES7) == "doubted"
    assert single.recall("ball").material == "plexiglass|rubber"


def test_a_changed_object_is_found_after_disagreeing_touches_in_a_row():
    memory = ObjectMemory()
    for t in (1.0, 2.0, 3.0):
        memory.learn("cup", touch("marble"), t, classes=CLASSES7)
    assert memory.learn("cup", touch("wood"), 4.0, classes=CLASSES7) == "kept"
    assert memory.learn("cup", touch("wood"), 5.0, classes=CLASSES7) == "replaced"
    r = memory.recall("cup")
    assert r.material == "wood" and r.touches == 2 and memory.counters["replaced"] == 1
    # A right touch between two wrong ones breaks the streak: nothing replaced.
    other = ObjectMemory()
    for label in ("marble", "marble", "wood", "marble", "wood"):
        other.learn("cup", touch(label), 1.0, classes=CLASSES7)
    assert other.recall("cup").material == "marble" and other.counters["replaced"] == 0


def test_a_remembered_pair_renders_its_mixture_and_a_member_refines_it():
    link = fresh_link()
    link.on_message(announce("plate", "plexiglass|steel", 0.97), 0.0)
    link.begin(1)
    assert link.estimate.label == "plexiglass|steel" and link.estimate.posteriors == (0.5, 0.5)
    link.on_message(estimate(1, 0.1, label="steel", decided=True, p_steel=0.99), 0.0)
    assert link.estimate.label == "steel" and link.counters["memory_overruled"] == 0


def test_link_estimate_empty_link():
    assert SlaveLink().estimate is None
