"""The simulated network of ``bench faults`` (sim/network.py) and issue
15's hard cases on it, all on the simulated clock.

The network model is checked against the protocol's conservation laws:
every lossless message reaches the application exactly once and in order,
whatever the loss, jitter, duplication and reordering; a lossy message at
most as often as the channel delivered it; a lost lossy message delays
nothing behind it, a lost lossless one holds back its successors."""

import logging
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from telethermal.sim.channel import Direction
from telethermal.physics.scene import load_scene, with_finger
from telethermal.render.sampled import sample_curves
from telethermal.teleop.link import SlaveLink
from telethermal.teleop.display_config import DisplayConfig
from telethermal.teleop.memory import ObjectMemory
from telethermal.sim.network import NetworkSpec, SimNetwork, run_network_touch
from telethermal.wire.messages import CLASSES, ContactEvent

SCENE = with_finger(load_scene("fingertip-7"))


def msg(i, kind="material_estimate"):
    """A message numbered ``i`` (by its contact id) of ``kind``."""
    return CLASSES[kind](contact_id=i, t_since_contact_s=0.0, classes=[], posteriors=[],
                         label="", confidence=0.0, decided=False, reason="",
                         object_temp_c=20.0)


def drain(net, until_s, step_s=0.01, direction="s2m", t0=0.0):
    got, t = [], t0
    while t <= until_s:
        got += [(t, m) for m in net.due(t, direction)]
        t += step_s
    return got


#: The link has been up this long before a test's first message: both
#: sides' heartbeats have timed the round trip, as between services that
#: idled before a touch (a fresh link knows no round trip yet). Half a
#: heartbeat period past a beat, so no beat coincides with a send.
T0 = 2.05


def warm(net):
    for t in np.arange(0.0, T0, 0.01):
        net.due(float(t), "s2m")
        net.due(float(t), "m2s")


@settings(max_examples=40, deadline=None)
@given(loss=st.floats(0.0, 0.6), jitter_s=st.floats(0.0, 0.2), dup=st.floats(0.0, 0.5),
       reorder=st.floats(0.0, 0.5), seed=st.integers(0, 2**16))
def test_lossless_messages_arrive_once_and_in_order(loss, jitter_s, dup, reorder, seed):
    d = Direction(delay_s=0.05, jitter="uniform", jitter_s=jitter_s, loss=loss, duplicate=dup,
                  reorder=reorder)
    net = SimNetwork(NetworkSpec.symmetric(d), np.random.default_rng(seed))
    for i in range(30):
        net.send(0.01 * i, "s2m", msg(i), lossless=True)
        net.send(0.01 * i + 0.005, "s2m", msg(i, "posterior_estimate"), lossless=False)
    got = drain(net, 60.0, 0.05)
    lossless = [m.contact_id for _, m in got if m.kind == "material_estimate"]
    c = net.counters("s2m")
    # In order and once each; a gap the protocol gave up (open for 5 dead
    # periods: possible at 60 % loss both ways) is counted, never silent.
    assert lossless == sorted(set(lossless)) and set(lossless) <= set(range(30))
    assert len(lossless) + c["skipped"] == 30 and c["sent"] == 30
    lossy = [m.contact_id for _, m in got if m.kind == "posterior_estimate"]
    assert len(lossy) <= 2 * 30 and set(lossy) <= set(range(30))


@pytest.mark.parametrize("broken", [False, True])
def test_the_simulated_link_runs_the_services_stream_so_breaking_it_breaks_the_link(
        monkeypatch, broken):
    # Issue 45: the simulated rows run wire/lossless.py itself, not a copy
    # of it. A stream that never sends a kept message again (neither asked
    # nor on its timer: a broken protocol) loses on the simulated link what
    # the real stream recovers.
    if broken:
        from telethermal.wire.lossless import LosslessStream
        monkeypatch.setattr(LosslessStream, "resend_from", lambda self, first: None)
    d = Direction(delay_s=0.05, loss=0.3)
    net = SimNetwork(NetworkSpec.symmetric(d), np.random.default_rng(7))
    for i in range(30):
        net.send(0.01 * i, "s2m", msg(i), lossless=True)
    got = [m.contact_id for _, m in drain(net, 60.0, 0.05)]
    c = net.counters("s2m")
    if broken:
        assert c["resent"] == 0 and c["skipped"] > 0 and len(got) < 30
    else:
        assert c["resent"] > 0 and c["skipped"] == 0 and got == list(range(30))


def drop_first(net, direction, kinds=("material_estimate", "posterior_estimate")):
    """``direction`` loses the first message of ``kinds`` sent on it."""
    original, state = net._transmit, {"dropped": False}

    def transmit(now, d, action, payload, kind):
        if d == direction and kind in kinds and not state["dropped"]:
            state["dropped"] = True
            return
        original(now, d, action, payload, kind)
    net._transmit = transmit


@pytest.mark.parametrize("lossless_estimate", [False, True])
def test_a_lost_estimate_holds_back_a_decision_only_when_ordered(lossless_estimate):
    net = SimNetwork(NetworkSpec.symmetric(Direction(delay_s=0.2)), np.random.default_rng(0))
    warm(net)
    drop_first(net, "s2m")
    net.send(T0, "s2m", msg(0, "posterior_estimate"), lossless=lossless_estimate)
    net.send(T0 + 0.01, "s2m", msg(1), lossless=True)              # the decision
    got = drain(net, T0 + 3.0, 0.001, t0=T0)
    t_decision = next(t for t, m in got if m.contact_id == 1) - T0
    if lossless_estimate:
        # Behind the gap: a resend request (0.2 s back), the resend (0.2 s).
        assert t_decision == pytest.approx(0.21 + 0.4, abs=1.5e-3)
        assert [m.contact_id for _, m in got] == [0, 1]
    else:
        assert t_decision == pytest.approx(0.21, abs=1.5e-3)
        assert [m.contact_id for _, m in got] == [1]                 # the lost estimate is gone


def test_a_lost_tail_is_found_by_the_next_heartbeat():
    net = SimNetwork(NetworkSpec.symmetric(Direction(delay_s=0.05)), np.random.default_rng(0))
    warm(net)
    drop_first(net, "s2m")
    net.send(T0, "s2m", msg(0), lossless=True)                # alone: no gap to see
    got = drain(net, T0 + 2.0, 0.001, t0=T0)
    assert [m.contact_id for _, m in got] == [0]
    # PROTOCOL.md section 4: the slave's next heartbeat (the beat 0.05 s after
    # the send) carries last_seq (0.1 s at the master), the resend goes back
    # (0.15 s), the message comes again (0.2 s).
    assert got[0][0] - T0 == pytest.approx(0.2, abs=1.5e-3)
    assert net.counters("s2m")["gaps"] == 1 and net.counters("s2m")["resent"] == 1


def test_a_lost_tail_without_heartbeats_waits_for_the_retransmission_timer():
    # The slave's heartbeats lost from the drop on: the master never learns
    # of the tail; the slave's own timer sends it again after max(3
    # heartbeats, 2 round trips + 1 heartbeat) = 0.3 s without an ack moving.
    net = SimNetwork(NetworkSpec.symmetric(Direction(delay_s=0.05)), np.random.default_rng(0))
    warm(net)
    original = net._transmit

    def no_heartbeats(now, direction, action, payload, kind):
        if not (direction == "s2m" and action == "heartbeat"):
            original(now, direction, action, payload, kind)
    net._transmit = no_heartbeats
    drop_first(net, "s2m")
    net.send(T0, "s2m", msg(0), lossless=True)
    got = drain(net, T0 + 2.0, 0.001, t0=T0)
    # The timer is read at the slave's beats (every 0.1 s): the first one 0.3 s
    # or more after the send is 0.35 s after it, then 0.05 s on the wire.
    assert [m.contact_id for _, m in got] == [0]
    assert got[0][0] - T0 == pytest.approx(0.40, abs=1.5e-3)
    assert net.counters("s2m")["resent"] == 1


def test_two_objects_announced_in_quick_succession_are_read_in_order():
    # Jitter far larger than their spacing reorders them on the wire; the
    # lossless stream puts them back, so the second object is the one held.
    for seed in range(20):
        net = SimNetwork(NetworkSpec.symmetric(Direction(delay_s=0.1, jitter="uniform",
                                                         jitter_s=0.1, loss=0.1)),
                         np.random.default_rng(seed))
        link = SlaveLink(classes=("steel", "wood"))
        for i, (obj, material) in enumerate((("plate", "steel"), ("board", "wood"))):
            net.send(0.005 * i, "s2m", ContactEvent(contact_id=0, touching=False, t_s=0.0,
                                                    force_n=0.0, object_temp_c=25.0 + i,
                                                    object_id=obj, object_material=material,
                                                    object_confidence=0.99), lossless=True)
        for _, m in drain(net, 5.0):
            link.on_message(m, 0.0)
        link.begin(1)
        assert (link.object_id, link.estimate.label, link.object_temp_c) == \
            ("board", "wood", 26.0), seed


# ------------------------------------------------------------- whole touches
@pytest.fixture(scope="module")
def models(trained_models):
    ident, gen = trained_models.pair(SCENE, 0)
    return ident, sample_curves(gen, [m for m in gen.materials if m in ident.classes_])


def touch(models, material="wood", spec=NetworkSpec(), **kw):
    ident, curves = models
    kw.setdefault("contact_s", 1.0)
    return run_network_touch(SCENE, material, ident, curves, DisplayConfig(), spec, **kw).summary


def test_an_estimate_arriving_after_the_contact_ended_changes_nothing(models):
    # Lifted at 0.15 s; the slave's pad goes down at ~0.13 s and its first
    # estimates reach the master ~0.1 s after they are made.
    spec = NetworkSpec.symmetric(Direction(delay_s=0.1))
    s = touch(models, spec=spec, contact_s=0.15, seed=3)
    assert s["link_counters"]["stale"] > 0          # the slave's news came after the lift
    assert s["render_start_s"] is None and s["safety_events"] == 0


def test_a_repeated_touch_renders_from_the_start_at_any_delay(models):
    memory = ObjectMemory()
    first = touch(models, spec=NetworkSpec.symmetric(Direction(delay_s=0.5)), seed=4,
                  object_id="board", memory=memory, contact_s=2.0)
    # A first touch: nothing before the round trip (1 s) and the identification.
    assert memory.recall("board").material == "wood" and first["render_start_s"] > 1.0
    again = touch(models, spec=NetworkSpec.symmetric(Direction(delay_s=0.5)), seed=5,
                  object_id="board", memory=memory)
    oracle = touch(models, seed=5, mode="oracle")
    assert again["link_counters"]["memory_used"] == 1
    assert again["render_start_s"] == oracle["render_start_s"]     # the master's onset
    # The target of the bench (<= 1.05x the oracle floor), on this touch.
    assert again["flux_rms_error_rel_whole"] <= 1.05 * oracle["flux_rms_error_rel_whole"]
    # And the oracle is a floor of it: it knows the material, so it idles
    # pre-conditioned for it as the repeated touch does (an oracle idling
    # for an unknown object was 1.7x worse than the repeat it bounded).
    assert oracle["flux_rms_error_rel_whole"] <= 1.05 * again["flux_rms_error_rel_whole"]


def test_memory_that_disagrees_with_a_fresh_identification_loses(models, caplog):
    memory = ObjectMemory()
    memory.learn("board", __import__("telethermal.ident.anytime", fromlist=["Estimate"]).Estimate(
        0.5, (), "steel", 0.99, True, "confident"), 0.0)
    with caplog.at_level(logging.WARNING):
        s = touch(models, "wood", seed=6, object_id="board", memory=memory)
    assert s["link_counters"]["memory_used"] == 1
    assert s["link_counters"]["memory_overruled"] == 1
    assert s["identified"] == "wood"
    # The memory weighs the touch against the one it held (issue 29): one
    # touch against one leaves the pair; a second wood touch refines it.
    assert memory.recall("board").material == "steel|wood"
    assert memory.counters["doubted"] == 1
    assert any("fresh" in r.getMessage() for r in caplog.records)
    touch(models, "wood", seed=7, object_id="board", memory=memory)
    assert memory.recall("board").material == "wood" and memory.counters["refined"] == 1


def test_a_restarted_slave_has_forgotten_and_the_touch_is_a_first_touch(models):
    memory = ObjectMemory()
    touch(models, seed=7, object_id="board", memory=memory)
    assert memory.recall("board") is not None
    restarted = ObjectMemory()                       # a new slave process
    s = touch(models, seed=8, object_id="board", memory=restarted)
    assert s["link_counters"]["memory_used"] == 0
    assert s["render_start_s"] >= s["first_news_s"]


def test_delay_changing_from_20_to_500_ms_mid_contact(models):
    spec = NetworkSpec.symmetric(Direction(delay_s=0.02), change_at_s=0.05,
                                 then=Direction(delay_s=0.5))
    s = touch(models, spec=spec, seed=9, contact_s=2.0)
    steady = touch(models, spec=NetworkSpec.symmetric(Direction(delay_s=0.5)), seed=9,
                   contact_s=2.0)
    assert s["safety_events"] == 0 and s["identified"] == "wood"
    # The contact event left before the change (20 ms); the slave's news came
    # back at 500 ms: between the two steady cases.
    assert 0.02 + 0.5 < s["first_news_s"] < steady["first_news_s"]
    assert math.isfinite(s["flux_rms_error_rel_whole"])


def test_oracle_and_modes_are_checked(models):
    with pytest.raises(ValueError, match="mode must be one of"):
        touch(models, mode="psychic")
    with pytest.raises(ValueError, match="estimates must be one of"):
        NetworkSpec(estimates="carrier pigeon")
    with pytest.raises(ValueError, match="go together"):
        NetworkSpec(change_at_s=1.0)


@pytest.mark.parametrize("seed", [5, 6])
def test_a_first_touch_at_200_ms_renders_within_the_fault_test_s_bound(models, seed):
    """The bound tests/faults/test_session_faults.py held on the real clock
    (a real-clock outcome there since), on the simulated clock: a first
    wood touch with 200 ms each way renders the decision with a flux error
    under 8 % of peak after it (the zero-delay target of 5 % plus what the
    idle policy trades on an insulator while the decision is 0.4 s late)
    and no safety event."""
    s = touch(models, spec=NetworkSpec.symmetric(Direction(delay_s=0.2)), seed=seed,
              contact_s=2.0)
    assert s["identified"] == "wood" and s["render_start_s"] is not None
    # After the first news (the services' figure runs from rendering's start).
    assert s["flux_rms_error_rel_after_news"] < 0.08, s["flux_rms_error_rel_after_news"]
    assert s["safety_events"] == 0
