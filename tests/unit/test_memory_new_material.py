"""Issue 30, deliverable 2: the object memory keeps a new material "like any
other", that is with what a repeated touch needs to be rendered right from
its first instant: its effusivity estimate (teleop/memory.py's
:class:`Effusivity`), announced in the object fields (PROTOCOL.md 6b, 6c)
and rendered by the master from t = 0."""

import math

import pytest

from telethermal.ident.anytime import NEW_MATERIAL, Estimate, Reason
from telethermal.teleop.memory import FROM_MEMORY, Z95, Effusivity, ObjectMemory, Verdict
from telethermal.wire.codec import decode, encode
from telethermal.wire.messages import ContactEvent

from test_link import OBJECT_C, drive, estimate, fresh_link

TRAINED = ("graphite", "marble", "plexiglass")


def _new(e, lo, hi):
    return Estimate(1.0, (1.0, 0.0, 0.0), NEW_MATERIAL, 0.9999, True, Reason.NEW_MATERIAL,
                    e, lo, hi, "graphite")


def _sd(e, lo, hi):
    """The sd of ln e an interval says: its wider half over the quantile."""
    return max(math.log(e / lo), math.log(hi / e)) / Z95


def test_the_remembered_estimate_is_the_inverse_variance_mean_with_the_sharpest_interval():
    memory = ObjectMemory(0.99)
    touches = [(1390.0, 1270.0, 1520.0), (1450.0, 1200.0, 1750.0), (1330.0, 1250.0, 1420.0)]
    for t, (e, lo, hi) in enumerate(touches):
        memory.learn("glass-1", _new(e, lo, hi), float(t), TRAINED)
    got = memory.recall("glass-1")
    assert got.material == "new material" and got.touches == 3
    w = [_sd(e, lo, hi) ** -2 for e, lo, hi in touches]
    mean = sum(wi * math.log(e) for wi, (e, _, _) in zip(w, touches)) / sum(w)
    sharpest = min(_sd(e, lo, hi) for e, lo, hi in touches)
    # Closed form, to rounding.
    assert got.effusivity.log_e == pytest.approx(mean, abs=1e-12)
    assert got.effusivity.sd == pytest.approx(sharpest, rel=1e-12)
    fields = got.effusivity.fields
    assert fields["effusivity_lo_w_s05_m2k"] == pytest.approx(math.exp(mean - Z95 * sharpest))
    assert fields["effusivity_hi_w_s05_m2k"] == pytest.approx(math.exp(mean + Z95 * sharpest))
    # What status shows carries it too.
    assert memory.to_dict()["glass-1"]["effusivity_w_s05_m2k"] == pytest.approx(math.exp(mean))


def test_an_interval_clipped_at_the_grid_keeps_its_sd():
    """A metal early in its touch: its interval reaches past the estimator's
    grid (1.2e5) and is clipped there; the sd is its lower half's, not the
    clipped width's (0.65 here: a weight 16 % too large)."""
    e, sd = 37_000.0, 0.7
    lo, hi = e * math.exp(-Z95 * sd), 1.2e5            # e exp(+Z95 sd) would be 1.46e5
    got = Effusivity.of_fields(e, lo, hi)
    assert got.sd == pytest.approx(sd, rel=1e-12) and got.weight == pytest.approx(sd ** -2)


def test_a_remembered_class_carries_no_estimate_and_a_touch_without_one_adds_nothing():
    memory = ObjectMemory(0.99)
    named = Estimate(1.0, (0.995, 0.004, 0.001), "graphite", 0.995, True, Reason.CONFIDENT,
                     1510.0, 1450.0, 1570.0)
    memory.learn("plate", named, 1.0, TRAINED)
    assert memory.recall("plate").effusivity is None
    bare = Estimate(1.0, (1.0, 0.0, 0.0), NEW_MATERIAL, 0.9999, True, Reason.NEW_MATERIAL)
    memory.learn("cup", bare, 1.0, TRAINED)          # an older identifier's: no estimate
    assert memory.recall("cup").material == "new material"
    assert memory.recall("cup").effusivity is None
    memory.learn("cup", _new(1390.0, 1270.0, 1520.0), 2.0, TRAINED)
    only = Effusivity.of(_new(1390.0, 1270.0, 1520.0))
    assert memory.recall("cup").effusivity.log_e == pytest.approx(only.log_e, abs=1e-12)


def test_another_new_material_under_the_name_disagrees_and_two_in_a_row_replace_it():
    """Foam (e ~ 42) remembered; a touch estimating ~1,400 (glass) is another
    new material: weighed like a disagreeing class (kept against three),
    and two such in a row, consistent with each other, replace it."""
    memory = ObjectMemory(0.99)
    for t in (1.0, 2.0, 3.0):
        memory.learn("thing", _new(42.0, 40.0, 44.5), t, TRAINED)
    assert memory.learn("thing", _new(1390.0, 1270.0, 1520.0), 4.0, TRAINED) == Verdict.KEPT
    assert memory.recall("thing").effusivity.log_e == pytest.approx(
        Effusivity.of(_new(42.0, 40.0, 44.5)).log_e)       # not pooled with the other
    assert memory.learn("thing", _new(1420.0, 1300.0, 1550.0), 5.0, TRAINED) == \
        Verdict.REPLACED
    now = memory.recall("thing").effusivity
    assert 1270.0 < math.exp(now.log_e) < 1550.0
    # A consistent touch after it pools, no disagreement.
    assert memory.learn("thing", _new(1400.0, 1250.0, 1560.0), 6.0, TRAINED) == \
        Verdict.CONFIRMED


def test_two_inconsistent_new_materials_in_a_row_do_not_replace_a_memory():
    """Two disagreeing new-material touches that disagree with each other too
    (1,400 then 20,000): no single other object is shown, the memory stays."""
    memory = ObjectMemory(0.99)
    for t in (1.0, 2.0, 3.0):
        memory.learn("thing", _new(42.0, 40.0, 44.5), t, TRAINED)
    memory.learn("thing", _new(1390.0, 1270.0, 1520.0), 4.0, TRAINED)
    assert memory.learn("thing", _new(20000.0, 18000.0, 22000.0), 5.0, TRAINED) != \
        Verdict.REPLACED
    assert math.exp(memory.recall("thing").effusivity.log_e) == pytest.approx(42.0)


def _announce(e=1390.0, lo=1270.0, hi=1520.0):
    return ContactEvent(contact_id=0, touching=False, t_s=0.0, force_n=0.0,
                        object_temp_c=OBJECT_C, object_id="glass-1",
                        object_material="new material", object_confidence=0.998,
                        object_effusivity_w_s05_m2k=e, object_effusivity_lo_w_s05_m2k=lo,
                        object_effusivity_hi_w_s05_m2k=hi)


def test_the_announcement_survives_the_wire():
    back = decode(encode({**_announce().to_dict(), "v": 1, "seq": 1, "sent_s": 0.0}))
    assert back["object_effusivity_w_s05_m2k"] == 1390.0
    assert back["object_effusivity_lo_w_s05_m2k"] == 1270.0
    assert back["object_effusivity_hi_w_s05_m2k"] == 1520.0


def test_the_session_announces_what_the_memory_holds():
    from telethermal.teleop.session import SlaveSession

    session = SlaveSession({}, 100.0, memory=ObjectMemory(0.99))
    session.object_id = "glass-1"
    assert "object_effusivity_w_s05_m2k" not in session.object_fields()
    session.memory.learn("glass-1", _new(1390.0, 1270.0, 1520.0), 1.0, TRAINED)
    fields = session.object_fields()
    assert fields["object_material"] == "new material"
    assert fields["object_effusivity_w_s05_m2k"] == pytest.approx(1390.0)
    assert fields["object_effusivity_lo_w_s05_m2k"] < 1390.0 < \
        fields["object_effusivity_hi_w_s05_m2k"]


def test_a_repeated_touch_of_a_new_material_renders_its_estimate_from_t0():
    link = fresh_link()
    link.on_message(_announce(), 0.0)
    link.begin(1)
    assert link.estimate.reason == FROM_MEMORY and link.estimate.label.is_new
    assert link.estimate.effusivity_w_s05_m2k == 1390.0
    master, steps = drive(link, {}, seconds=0.2)
    during = [s for s in steps if s.t_s >= 0.03]
    assert during and all(s.phase == "render" for s in during)
    assert master.rendered_estimate is not None
    assert master.rendered_estimate.effusivity_w_s05_m2k == 1390.0


def test_an_announcement_without_the_estimate_is_ignored_as_before():
    link = fresh_link()
    link.on_message(ContactEvent(contact_id=0, touching=False, t_s=0.0, force_n=0.0,
                                 object_temp_c=OBJECT_C, object_id="glass-1",
                                 object_material="new material", object_confidence=0.998), 0.0)
    link.begin(1)
    assert link.memory is None and link.counters["memory_used"] == 0
    # An unusable one (interval not holding the estimate) likewise.
    link.on_message(_announce(e=1390.0, lo=1400.0, hi=1520.0), 0.0)
    link.begin(2)
    assert link.memory is None


def _named(label, e, lo, hi, t=0.06):
    m = estimate(1, t, label=label, decided=True, p_steel=0.995 if label == "steel" else 0.005)
    return type(m)(**{**m.fields(), "effusivity_w_s05_m2k": e,
                      "effusivity_lo_w_s05_m2k": lo, "effusivity_hi_w_s05_m2k": hi})


def test_an_early_class_consistent_with_the_remembered_new_material_does_not_overrule_it():
    """The closed set names an unseen material's nearest class early (glass
    named graphite at 0.06 s): with an estimate consistent with the
    memory's, the memory stands; a fresh new material then takes over."""
    link = fresh_link()
    link.on_message(_announce(), 0.0)
    link.begin(1)
    link.on_message(_named("steel", 1600.0, 900.0, 2900.0), 0.0)
    assert link.estimate.reason == FROM_MEMORY
    fresh = _named("steel", 1420.0, 1330.0, 1510.0, t=1.0)
    fresh = type(fresh)(**{**fresh.fields(), "label": "new material",
                           "reason": "new material", "nearest": "plexiglass"})
    link.on_message(fresh, 0.0)
    assert link.estimate.reason == "new material"
    assert link.estimate.effusivity_w_s05_m2k == 1420.0
    # Counted once, at the contact's end, on its last decision (the same
    # new material): neither kept nor overruled.
    link.end()
    assert (link.counters["memory_kept"], link.counters["memory_overruled"]) == (0, 0)
    # A touch that ends on the early class: kept.
    link.begin(2)
    early = _named("steel", 1600.0, 900.0, 2900.0)
    link.on_message(type(early)(**{**early.fields(), "contact_id": 2}), 0.0)
    link.end()
    assert (link.counters["memory_kept"], link.counters["memory_overruled"]) == (1, 0)


def test_a_class_inconsistent_with_the_remembered_new_material_overrules_it():
    link = fresh_link()
    link.on_message(_announce(), 0.0)
    link.begin(1)
    link.on_message(_named("steel", 14000.0, 12500.0, 15500.0), 0.0)
    link.end()
    assert link.estimate.label == "steel" and link.counters["memory_overruled"] == 1
    # A class decision without an estimate (an older slave's) overrules it too.
    link.begin(2)
    link.on_message(estimate(2, 0.1, label="steel", decided=True, p_steel=0.995), 0.0)
    link.end()
    assert link.estimate.label == "steel" and link.counters["memory_overruled"] == 2




def test_a_new_material_doubting_a_class_keeps_its_estimate_for_later():
    """One touch named graphite, then two new materials: the first leaves
    nothing announced (doubted), the second makes the new material what
    the evidence supports; announced with both touches' pooled estimate,
    the doubting touch's included."""
    memory = ObjectMemory(0.99)
    memory.learn("cup", Estimate(1.0, (0.995, 0.004, 0.001), "graphite", 0.995, True,
                                 Reason.CONFIDENT), 1.0, TRAINED)
    a, b = _new(1390.0, 1270.0, 1520.0), _new(1450.0, 1300.0, 1620.0)
    assert memory.learn("cup", a, 2.0, TRAINED) == Verdict.DOUBTED
    assert memory.recall("cup") is None
    memory.learn("cup", b, 3.0, TRAINED)
    got = memory.recall("cup")
    assert got is not None and got.material == "new material"
    want = Effusivity.of(a).pooled(Effusivity.of(b))
    assert got.effusivity.log_e == pytest.approx(want.log_e, abs=1e-12)
