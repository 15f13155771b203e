"""Estimates that loss cannot stall (issue 15, item 3; PROTOCOL.md section 6a).

Two transport endpoints on loopback behind the fault proxy, all three on one
simulated clock: each step the clock stands still while loopback delivers
what is due, then moves on by ``STEP_S``. Every delay below is simulated
time, so the figures do not depend on how busy the machine is.

A contact, as the slave sends it: a burst of estimates (one per
identification window), then the decision and a contact event. In the old
flow every estimate was a lossless ``material_estimate``: one lost estimate
held the decision behind it until a resend arrived. Now estimates travel as
``posterior_estimate`` on the lossy stream; only the decision and the
contact event are lossless, and they never wait for an estimate.
"""

from __future__ import annotations

import dataclasses
import pytest
import zmq

from telethermal.sim.channel import Direction
from telethermal.sim.proxy import FaultProfile, FaultProxy, Link
from telethermal.ports import free_ports
from telethermal.wire.lossless import LosslessStream
from telethermal.wire.transport import Endpoint, TransportConfig

PLAIN = TransportConfig(security="plain", control_port=0, stream_port=0, heartbeat_s=0.1,
                        dead_after_s=1.0)
STEP_S = 0.005
DELAY_S = 0.05                 # one way, each direction
WINDOW_S = 0.02                # an estimate every identification window
BURST = 10                     # estimates before the decision


class SimClock:
    """Whole steps of STEP_S (no drift from adding floats)."""

    def __init__(self) -> None:
        self.steps = 0

    @property
    def t_s(self) -> float:
        return self.steps * STEP_S

    def __call__(self) -> float:
        return self.t_s


class Net:
    """A slave and a master endpoint through the fault proxy, on ``clock``.
    ``arrivals``: the master's first receipt of each lossless seq;
    ``delivered``: (seq, kind, simulated time) as the master's poll returns
    them."""

    def __init__(self, slave_to_master: Direction, master_to_slave: Direction | None = None,
                 seed: int = 3):
        self.clock = SimClock()
        self.slave = Endpoint("slave", PLAIN, clock=self.clock)
        control, stream = free_ports(2)
        link = Link(control_port=control, stream_port=stream,
                    slave_control_port=self.slave.ports[0],
                    slave_stream_port=self.slave.ports[1], seed=seed)
        self.proxy = FaultProxy(FaultProfile(link, master_to_slave or slave_to_master,
                                             slave_to_master), clock=self.clock)
        self.master = Endpoint("master", dataclasses.replace(PLAIN, control_port=control,
                                                             stream_port=stream),
                               clock=self.clock)
        self.master.deliver_stream = frozenset({"posterior_estimate"})
        self.arrivals: dict[int, tuple[float, int]] = {}     # seq -> (time, expected then)
        self.delivered: list[tuple[int, str, float]] = []
        self.sent_kind: dict[int, str] = {}                   # the slave's lossless seqs
        self.decided: dict[int, bool] = {}                    # ... of material_estimate
        push = self.master.lossless.receiver.push

        def watched_push(seq, message, now_s):
            if seq not in self.arrivals:
                self.arrivals[seq] = (now_s, self.master.lossless.receiver.expected)
            return push(seq, message, now_s)

        self.master.lossless.receiver.push = watched_push
        self.run_until(lambda: self.slave.peer_alive and self.master.peer_alive, 5.0)
        assert self.slave.peer_alive and self.master.peer_alive, "no session through the proxy"

    def close(self) -> None:
        for e in (self.master, self.proxy, self.slave):
            e.close()

    def _settle(self) -> None:
        """Loopback moves what is due while the simulated clock stands still:
        rounds until no socket of the three has had anything to read for
        two rounds of 1 ms in a row."""
        quiet = 0
        while quiet < 2:
            poller = zmq.Poller()
            for sock in (self.proxy.front, self.proxy.back, self.proxy.back_stream,
                         self.slave.control, self.master.control, self.master.stream):
                poller.register(sock, zmq.POLLIN)
            busy = poller.poll(1)
            self.proxy.step(0.0)
            self.slave.poll(0.0)
            for m in self.master.poll(0.0):
                self.delivered.append((m["seq"], m["kind"], self.clock.t_s))
            quiet = 0 if busy else quiet + 1

    def run_until(self, done, seconds: float) -> None:
        end = self.clock.steps + round(seconds / STEP_S)
        while self.clock.steps < end and not done():
            self._settle()
            self.clock.steps += 1

    def run_to(self, t_s: float) -> None:
        self.run_until(lambda: False, t_s - self.clock.t_s)

    def send(self, kind: str, **fields) -> tuple[int, float]:
        seq = self.slave.send(kind, **fields)
        if kind in ("material_estimate", "contact_event"):
            self.sent_kind[seq] = kind
            self.decided[seq] = bool(fields.get("decided"))
        return seq, self.clock.t_s

    def delivered_at(self, seq: int, kind: str) -> float | None:
        return next((t for s, k, t in self.delivered if s == seq and k == kind), None)


def estimate(contact_id: int, i: int, decided: bool = False) -> dict:
    p = min(0.5 + 0.05 * i, 0.995)
    return dict(contact_id=contact_id, t_since_contact_s=i * WINDOW_S,
                classes=["steel", "wood"], posteriors=[p, 1.0 - p], label="steel",
                confidence=p, decided=decided, reason="confident" if decided else "",
                object_temp_c=24.0)


def contact(net: Net, contact_id: int, estimates_lossless: bool) -> dict:
    """One contact's messages, the burst an identification window apart;
    returns the seqs and send times of its decision and contact event."""
    kind = "material_estimate" if estimates_lossless else "posterior_estimate"
    for i in range(1, BURST + 1):
        net.send(kind, **estimate(contact_id, i))
        net.run_to(net.clock.t_s + WINDOW_S)
    decided = estimate(contact_id, BURST + 1, decided=True)
    if not estimates_lossless:
        net.send("posterior_estimate", **decided)      # every estimate goes on the stream
    decision = net.send("material_estimate", **decided)
    lift = net.send("contact_event", contact_id=contact_id, touching=False,
                    t_s=net.clock.t_s, force_n=0.0, object_temp_c=24.0)
    return {"decision": decision, "lift": lift}


def delays(net: Net, sent: dict) -> dict:
    return {name: net.delivered_at(seq, "material_estimate" if name == "decision" else
                                   "contact_event") - t for name, (seq, t) in sent.items()}


def burst_then_decision(partition: tuple[float, float] | None, estimates_lossless: bool):
    """The burst sent from 2.30 to 2.48 s, the decision and the contact
    event at 2.50 s. ``partition``: a blackhole on the slave -> master
    direction (estimates, heartbeats and status alike). The slave's state
    changes at 2.25 s, as at a touch: its status goes then, and next a
    second later, both outside the partition."""
    net = Net(Direction(delay_s=DELAY_S, partitions=(partition,) if partition else ()),
              Direction(delay_s=DELAY_S))
    try:
        net.run_to(2.25)
        net.slave.state = "touching"
        net.run_to(2.3)
        sent = contact(net, 1, estimates_lossless)
        net.run_until(lambda: all(net.delivered_at(seq, k) is not None for (seq, _), k in
                                  zip(sent.values(), ("material_estimate", "contact_event"))),
                      5.0)
        return delays(net, sent), net.slave.counters["resent"], net.proxy.counters
    finally:
        net.close()


def test_a_burst_of_lost_estimates_does_not_delay_the_decision():
    # Every estimate of the burst is lost (a partition of the slave ->
    # master direction from 2.2975 to 2.4875 s); the decision and the
    # contact event are sent at 2.50 s, after it.
    burst = (2.2975, 0.19)
    clean, resent_clean, _ = burst_then_decision(None, estimates_lossless=False)
    lost, resent_lost, proxy = burst_then_decision(burst, estimates_lossless=False)
    assert proxy["slave_to_master_stream"]["partitioned"] == BURST      # the burst, lost
    assert proxy["slave_to_master"]["partitioned"] > 0                  # heartbeats too
    assert resent_clean == resent_lost == 0
    # Nothing was resent: the lost estimates were never asked for, and the
    # decision arrives as it would have with nothing lost: after the link's
    # delay, and before waiting behind a resend could bring it (a round trip
    # more). The simulated clock moves in 5 ms steps and loopback delivers
    # within the step, or some steps later on a loaded host (the settle ends
    # after two quiet 1 ms polls): lateness only adds, so each run is held
    # between the two, not to another run's lateness.
    for name in ("decision", "lift"):
        for run in (clean, lost):
            assert DELAY_S - STEP_S / 2 <= run[name] < 3 * DELAY_S - STEP_S / 2, (clean, lost)
    # The old flow, every estimate lossless: the decision waits behind the
    # lost ones until they are resent, at least a round trip later.
    old, resent_old, _ = burst_then_decision(burst, estimates_lossless=True)
    assert resent_old >= BURST
    # (resend request and resend: one round trip, 2 DELAY_S, after the one
    # way the decision takes anyway, to within a step; lateness only adds)
    for name in ("decision", "lift"):
        assert old[name] >= DELAY_S + 2 * DELAY_S - STEP_S / 2, (clean, old)


@pytest.mark.parametrize("delay_s", [0.05, 0.2])
def test_a_lost_tail_is_asked_for_at_the_next_heartbeat(delay_s):
    # A sparse lossless stream: the lift is the last message for a while, and
    # it is lost (a 20 ms blackhole as it leaves). No successor shows a gap;
    # the slave's next heartbeat says what it sent last (last_seq) and the
    # master asks for it: a heartbeat and three crossings of the link, not the
    # slave's retransmission timer (two round trips and a heartbeat).
    net = Net(Direction(delay_s=delay_s, partitions=((2.4975, 0.02),)),
              Direction(delay_s=delay_s))
    try:
        net.run_to(2.25)
        net.slave.state = "touching"
        net.run_to(2.5)
        seq, at = net.send("contact_event", contact_id=1, touching=False, t_s=2.5, force_n=0.0)
        net.run_until(lambda: net.delivered_at(seq, "contact_event") is not None, 5.0)
        took = net.delivered_at(seq, "contact_event") - at
        assert net.arrivals[seq][0] - at > delay_s + STEP_S        # the first copy was lost
        heartbeat = PLAIN.heartbeat_s
        retransmission = max(3 * heartbeat, 2 * (2 * delay_s) + heartbeat) + delay_s
        # Asked for at the heartbeat (a heartbeat and three crossings), not
        # by the retransmission timer: nearer the first. Loopback's lateness
        # on a loaded host (steps of the simulated clock) only adds, so the
        # bound is halfway between the two, not the first plus two steps.
        assert took <= (heartbeat + 3 * delay_s + retransmission) / 2, (took, retransmission)
        assert net.master.counters["gaps"] >= 1
    finally:
        net.close()


@pytest.mark.parametrize("loss", [0.05, 0.2])
def test_under_random_loss_decisions_never_wait_for_an_estimate(loss):
    # 20 contacts, each a burst of 10 estimates, its decision and a contact
    # event, with ``loss`` on every message of both directions (acks and
    # resend requests too). The same network, the same seed, the two flows.
    results = {}
    for lossless in (False, True):
        net = Net(Direction(delay_s=DELAY_S, loss=loss), seed=11)       # both directions
        try:
            sent = []
            for contact_id in range(1, 21):
                sent.append(contact(net, contact_id, lossless))
                net.run_to(net.clock.t_s + 0.2)
            net.run_until(lambda: net.slave.unacked == 0, 10.0)
            results[lossless] = (net, sent, _waits(net, lossless))
        finally:
            net.close()
    new_net, new_sent, new_waits = results[False]
    old_net, old_sent, old_waits = results[True]
    for net, sent in ((new_net, new_sent), (old_net, old_sent)):   # lossless: all, in order
        seqs = [s for s, k, _ in net.delivered if k in ("material_estimate", "contact_event")]
        assert seqs == sorted(seqs) and {c["decision"][0] for c in sent} <= set(seqs)
    # Estimates were lost on the new flow's stream, and no decision or
    # contact event ever waited for one: what held one up, if anything, was
    # a lost decision, contact event or status before it.
    assert new_net.master.counters["stream_lost"] > 0
    assert new_waits["behind_estimate"] == 0
    assert old_waits["behind_estimate"] > 0
    # (Figures: `figures()` below. One run, new flow against old: at 5 % loss
    # decisions on time 19/20 against 15/20, held 2 against 9; at 20 %:
    # 15/20 against 4/20, held 6 against 25. What is still held waits for a
    # lost decision, contact event or status of its own stream: see the
    # lost-tail test.)


def _waits(net: Net, estimates_lossless: bool) -> dict:
    """How many decisions and contact events were held at the master behind
    a missing seq, and how many of those behind a missing estimate."""
    estimate_seqs = {s for s, k in net.sent_kind.items()
                     if k == "material_estimate" and not net.decided[s]}
    out = {"held": 0, "behind_estimate": 0}
    for seq, kind, at in net.delivered:
        if kind not in ("material_estimate", "contact_event") or seq in estimate_seqs:
            continue
        first, expected = net.arrivals[seq]
        if at > first:
            out["held"] += 1
            if set(range(expected, seq)) & estimate_seqs:
                out["behind_estimate"] += 1
    return out


def figures() -> None:
    """The figures quoted in README.md and PROTOCOL.md (one run; loopback
    and the seeded channel make them vary a little from run to run):
    ``PYTHONPATH=src python tests/faults/test_estimates_under_loss.py``."""
    import statistics
    from unittest import mock

    for loss in (0.05, 0.2):
        for lossless in (False, True):
            net = Net(Direction(delay_s=DELAY_S, loss=loss), seed=11)
            try:
                sent = []
                for contact_id in range(1, 21):
                    sent.append(contact(net, contact_id, lossless))
                    net.run_to(net.clock.t_s + 0.2)
                net.run_until(lambda: net.slave.unacked == 0, 10.0)
                d = [delays(net, c)["decision"] for c in sent]
                print(f"loss {loss:.0%}, estimates {'lossless' if lossless else 'on the stream'}"
                      f": decision delay mean {1e3 * statistics.mean(d):.0f} ms, on time "
                      f"{sum(x <= DELAY_S + 3 * STEP_S for x in d)}/20; {_waits(net, lossless)}")
            finally:
                net.close()
    for delay_s in (0.05, 0.2):
        for tail_rule in (True, False):
            with mock.patch.object(LosslessStream, "_check_tail",
                                   LosslessStream._check_tail if tail_rule
                                   else lambda self, last_seq, now: None):
                net = Net(Direction(delay_s=delay_s, partitions=((2.4975, 0.02),)),
                          Direction(delay_s=delay_s))
                try:
                    net.run_to(2.5)
                    seq, at = net.send("contact_event", contact_id=1, touching=False, t_s=2.5,
                                       force_n=0.0)
                    net.run_until(lambda: net.delivered_at(seq, "contact_event") is not None, 5)
                    print(f"{1e3 * delay_s:.0f} ms one way, a lost lift: delivered after "
                          f"{net.delivered_at(seq, 'contact_event') - at:.3f} s "
                          f"({'with' if tail_rule else 'without'} heartbeat.last_seq)")
                finally:
                    net.close()


if __name__ == "__main__":
    figures()
