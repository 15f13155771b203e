"""Master sessions against a real slave (PROTOCOL.md section 5a): one
master at a time, a contact owned by the session that opened it, a master
killed mid-contact and restarted, SIGTERM mid-contact; and a message so
large that ZeroMQ drops its connection. Masters written from the document."""

from __future__ import annotations

import signal
import time

import pytest
import zmq

from conftest import DEAD_AFTER_S, GUARD_S, HEARTBEAT_S
from doc_peer import DocMaster, pack
from touch import assert_pad_safe, touch

MATERIAL, SEED = "wood", 2          # a trial the suite's identifier decides (wood, 0.24 s)


@pytest.fixture(scope="module")
def baseline(slave, curve_keys):
    """The decision of a clean touch on the trial every test touches."""
    ctx = zmq.Context()
    m = DocMaster(ctx, slave.control, slave.stream, curve_keys["a"], heartbeat_s=HEARTBEAT_S)
    try:
        m.connect()
        return legit_touch(slave, m, 1)
    finally:
        m.close()
        ctx.destroy(linger=0)
    

def legit_touch(slave, m, contact_id: int) -> dict:
    assert slave.admin("place", material=MATERIAL, seed=SEED)["ok"]
    estimate = touch(m, contact_id)
    assert_pad_safe(slave)
    return {k: estimate[k] for k in ("label", "confidence", "t_since_contact_s", "posteriors")}


def test_a_message_over_the_receive_limit_costs_only_that_connection(slave, masters, baseline):
    # Over 1 MiB ZeroMQ closes the connection before reading: the slave
    # lives on, and the master's socket reconnects and resumes its session.
    m = masters("a")
    before, configs = slave.counters(), len(m.of("session_config"))
    m.send_raw(b"\x00" * (2 * 1024 * 1024))
    m.peer_hello = None                          # say hello again on the new connection
    assert m.pump(GUARD_S, until=lambda: len(m.of("session_config")) > configs)
    assert slave.alive
    after = slave.counters()
    # Not read, so not counted as a message; seen as the session's reconnection.
    assert after["reconnects"] - before["reconnects"] == 1
    assert legit_touch(slave, m, 4) == baseline


# ---------------------------------------------------------------- sessions
def _pad_down(slave) -> bool:
    return slave.admin("status")["pad_down"]


def _touch_down(m, slave, contact_id: int) -> None:
    assert slave.admin("place", material=MATERIAL, seed=SEED)["ok"]
    m.touch(contact_id)
    assert m.pump(GUARD_S, until=lambda: m.of("contact_event", contact_id=contact_id,
                                          touching=True))
    assert _pad_down(slave)


def test_a_master_killed_mid_contact_and_restarted(slave, masters, baseline):
    # The killed master's socket closes without a word; the restarted one (a
    # new session on a new connection) says hello at once. It is refused
    # ("busy") while the old session may still be alive; the pad is lifted
    # when the old session is declared dead, and the new session is served.
    old = masters("a")
    _touch_down(old, slave, 6)
    before = slave.counters()
    old.close()
    killed = time.monotonic()
    new = masters("a", connect=False)
    lifted_at = None

    def lifted():
        nonlocal lifted_at
        if lifted_at is None and not _pad_down(slave):
            lifted_at = time.monotonic()
        return new.peer_hello is not None

    assert new.pump(GUARD_S, until=lifted)
    assert lifted_at is not None                      # lifted before the new session began
    after = slave.counters()
    # Declared dead by the slave's loop, or superseded by the new session's
    # hello when it arrives in the same poll: either way lifted at once.
    assert sum(after[k] - before[k] for k in ("masters_lost", "contacts_superseded")) == 1
    print(f"pad safe {lifted_at - killed:.3f} s after the master was killed "
          f"(dead_after_s {DEAD_AFTER_S})")
    new.connect()
    assert legit_touch(slave, new, 7) == baseline


def test_a_new_session_on_the_same_connection_supersedes_the_contact_at_once(
        slave, masters, baseline):
    # A master that restarts behind the same connection (same routing
    # identity, new session_id) is the contact owner's successor: the pad is
    # lifted as its hello arrives, with no wait for dead_after_s.
    m = masters("a")
    _touch_down(m, slave, 8)
    before = slave.counters()
    m.restart()
    assert m.pump(GUARD_S, until=lambda: m.peer_hello is not None)
    assert not _pad_down(slave)
    after = slave.counters()
    assert after["contacts_superseded"] - before["contacts_superseded"] == 1
    assert after["masters_lost"] == before["masters_lost"]
    m.connect()
    assert m.of("session_config")[0]["seq"] == 1                 # a fresh sequence
    assert m.of("contact_event", contact_id=8, touching=False)    # told of the lift
    assert legit_touch(slave, m, 9) == baseline


def test_a_second_master_cannot_lift_the_first_masters_contact(slave, masters, baseline):
    first = masters("a")
    _touch_down(first, slave, 10)
    second = masters("b", connect=False)
    second.hello()
    assert second.pump(GUARD_S, until=lambda: any(x["kind"] == "fault" and x["code"] == "busy"
                                              for _, x in second.received), heartbeats=False)
    before = slave.counters()
    second.send_raw(pack({**second.envelope("contact_event", True), "contact_id": 10,
                          "touching": False, "t_s": 0.0, "force_n": 0.0}))
    first.sync()
    second.close()
    assert _pad_down(slave)
    assert slave.counters()["not_peer"] - before["not_peer"] == 1
    first.touch(10, touching=False)
    assert first.pump(GUARD_S, until=lambda: first.of("contact_event", contact_id=10,
                                                  touching=False))
    assert_pad_safe(slave)


def test_a_stranger_key_is_rejected_and_counted(slave, masters, curve_keys):
    # Section 8: a key not in the slave's allowed folder gets no session; the
    # slave counts the refusal (curve_rejected) and names the key by its
    # fingerprint and the peer's address in its status.
    before = slave.counters()
    stranger = masters("stranger", connect=False)
    stranger.hello()
    assert not stranger.pump(1.5, until=lambda: stranger.peer_hello is not None,
                             heartbeats=False)
    after = slave.counters()
    assert after["curve_rejected"] > before["curve_rejected"]
    rejected = slave.admin("status")["last_rejected_key"]
    assert rejected and rejected["fingerprint"] and "127.0.0.1" in str(rejected["address"])


@pytest.mark.stops_slave
def test_sigterm_mid_contact_lifts_the_pad_and_says_stopping(slave, curve_keys):
    # The suite's slave, last of all (conftest orders stops_slave tests last).
    ctx = zmq.Context()
    m = DocMaster(ctx, slave.control, slave.stream, curve_keys["a"], heartbeat_s=HEARTBEAT_S)
    try:
        m.connect()
        _touch_down(m, slave, 20)
        slave.proc.send_signal(signal.SIGTERM)
        assert m.pump(GUARD_S, until=lambda: m.of("status", state="stopping"))
        lift = m.of("contact_event", contact_id=20, touching=False)
        stopping = m.of("status", state="stopping")[0]
        assert lift and lift[0]["seq"] < stopping["seq"]
        assert slave.proc.wait(15) == 0
        assert m.deviations == []
    finally:
        m.close()
        ctx.destroy(linger=0)
