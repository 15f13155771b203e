"""A networked telepresence touch on the simulated clock: master and slave
as the services run them, the network between them as the fault proxy
makes it, every message of proto/PROTOCOL.md modelled with its delivery
rule, and no process, socket or wall clock.

It exists so that ``telethermal bench faults`` can compare rendering modes
on many touches with the noise of the real clock gone: the same touch
(operator, object, sensor noise, network draws) is replayed exactly under
every mode and every delay.

What is modelled, and how:

* The master's contact onset (its own force sensor) sends ``contact_event``
  to the slave; the slave's pad goes down on the object when it arrives
  (as ``services/slave.py`` does), so the slave's contact starts one
  master->slave delay after the master's.
* The slave sends what the service sends, at the instants the service
  would: its touching ``contact_event`` at its onset, every estimate as a
  ``posterior_estimate`` on the lossy stream, each decision as a lossless
  ``material_estimate``, a ``flux_trajectory`` per decided material, and
  (for the naive baseline) a ``flux_setpoint`` per sample.
* Lossy stream: each message through a :class:`~telethermal.sim.channel.Channel`
  (loss, delay, jitter, reordering); a lost one is gone.
* Lossless stream (PROTOCOL.md section 4): each side runs the services' own
  :class:`~telethermal.wire.lossless.LosslessStream` (numbering, kept
  messages, ``resend`` on a gap or a lost tail, the retransmission timer,
  gaps given up), its messages, heartbeats and resends through the faulty
  channels; both sides' heartbeats and repairs run every ``heartbeat_s`` on
  the simulated clock (from the first period boundary after the link's
  first use), so the round trip the timers use is measured as the services
  measure it. ``estimates="lossless"`` sends every estimate this way (the
  protocol before issue 15), so the cost of ordered estimates can be
  measured.
* Clocks are the same on both sides (the clock-offset estimate is made, on
  equal clocks); the hello exchange and liveness are not modelled (a
  partition or a crash is measured on the real processes).
"""

from __future__ import annotations

import heapq
import itertools
import logging
import math
from dataclasses import dataclass, replace

import numpy as np

from telethermal.ident.anytime import Reason
from telethermal.physics.scene import with_finger
from telethermal.sim.channel import Channel, Direction
from telethermal.sim.direct import compare_with_direct
from telethermal.sim.loop import run_touch_loop
from telethermal.sim.sides import SimMasterService, SimSlaveService
from telethermal.sim.touch import MasterWorld
from telethermal.teleop.decision import touch_decision
from telethermal.teleop.display_setup import safety_summary
from telethermal.teleop.memory import ObjectMemory, memory_counts
from telethermal.teleop.session import PRE_CONTACT_S, EstimateRoute, Send, estimate_route
from telethermal.teleop.slave import Slave, slave_rng
from telethermal.wire.lossless import LosslessStream
from telethermal.wire.loglimit import LogLimiter
from telethermal.wire.messages import Message, parse
from telethermal.wire.schema import PROTOCOL_VERSION
from telethermal.wire.transport import COUNTERS, ClockOffset, TransportConfig

log = logging.getLogger(__name__)

#: Bytes of a message on the wire, roughly (only a serialising link cares).
MESSAGE_BYTES = {"flux_trajectory": 4200, "material_estimate": 160,
                 "posterior_estimate": 160, "flux_setpoint": 60, "contact_event": 90,
                 "resend": 30, "heartbeat": 60}


@dataclass(frozen=True)
class NetworkSpec:
    """Both directions of the link, and how estimates travel."""

    slave_to_master: Direction = Direction()
    master_to_slave: Direction = Direction()
    heartbeat_s: float = 0.1
    estimates: EstimateRoute = EstimateRoute.STREAM      # a string is read as its route
    #: From this time (master clock) on, both directions behave as
    #: ``then`` (e.g. a route change mid-contact); None: never.
    change_at_s: float | None = None
    then: Direction | None = None

    def __post_init__(self):
        object.__setattr__(self, "estimates", estimate_route(self.estimates))
        if not self.heartbeat_s > 0:
            raise ValueError(f"heartbeat_s must be > 0, got {self.heartbeat_s}")
        if (self.change_at_s is None) != (self.then is None):
            raise ValueError("change_at_s and then go together")

    @classmethod
    def symmetric(cls, direction: Direction, **kw) -> "NetworkSpec":
        return cls(direction, direction, **kw)

    @property
    def round_trip_s(self) -> float:
        return self.slave_to_master.delay_s + self.master_to_slave.delay_s


class _Quiet:
    """A logger whose warnings are this module's debug lines."""

    @staticmethod
    def warning(fmt, *args, exc_info=None):
        log.debug(fmt, *args, exc_info=exc_info)


class _SimEndpoint:
    """One side's lossless stream: the very
    :class:`~telethermal.wire.lossless.LosslessStream` an
    :class:`~telethermal.wire.transport.Endpoint` runs (numbering, the kept
    messages, acknowledgement by heartbeat, resends, the retransmission
    timer, gaps given up), its messages handed to ``transmit`` instead of a
    socket, its clock the simulated one."""

    def __init__(self, role: str, config: TransportConfig, clock, transmit):
        self.role, self.counters = role, dict.fromkeys(COUNTERS, 0)
        self._kind_seq: dict[str, int] = {}
        # What the services log as warnings (a resend throttled, a gap given
        # up) is counted here and logged at debug: a bench runs thousands.
        self._limited = LogLimiter(_Quiet())
        self.stream = LosslessStream(
            role=role, config=config, clock=clock, counters=self.counters,
            offset=ClockOffset(), limited=self._limited, send=transmit,
            unordered=self._unordered, drop=self._drop)

    def _unordered(self, kind: str, now: float, **fields) -> dict:
        seq = self._kind_seq[kind] = self._kind_seq.get(kind, 0) + 1
        return {"kind": kind, "v": PROTOCOL_VERSION, "seq": seq, "sent_s": now, **fields}

    def _drop(self, key: str, now: float, fmt: str, *args) -> None:
        self.counters[key] += 1
        self._limited.warn(key, now, "%s: " + fmt, self.role, *args)


#: Each direction's sending and receiving side.
ENDS = {"s2m": ("slave", "master"), "m2s": ("master", "slave")}


class SimNetwork:
    """The two directions, on a clock the caller advances with :meth:`due`.
    ``send(now, "s2m" | "m2s", message, lossless)``; ``due(now, direction)``
    returns the messages the receiver's application gets up to ``now``, in
    the order it gets them. Lossless messages go through each side's own
    :class:`~telethermal.wire.lossless.LosslessStream` (the services' code);
    both sides' heartbeats, every ``heartbeat_s`` on the simulated clock,
    carry the acknowledgements and run the streams' repair."""

    def __init__(self, spec: NetworkSpec, rng: np.random.Generator):
        self.spec = spec
        self.channels = {"s2m": Channel(spec.slave_to_master, rng),
                         "m2s": Channel(spec.master_to_slave, rng)}
        self._events: list = []          # (time, order, action, direction, payload)
        self._order = itertools.count()
        self._ready = {"s2m": [], "m2s": []}
        self._now = -math.inf
        self._ticking = False
        config = TransportConfig(heartbeat_s=spec.heartbeat_s, dead_after_s=max(
            TransportConfig.dead_after_s, 10 * spec.heartbeat_s))
        self.endpoints = {
            role: _SimEndpoint(role, config, lambda: self._now,
                               lambda m, data=None, d=d: self._transmit(
                                   self._now, d, m["kind"], m, m["kind"]))
            for d, (role, _) in ENDS.items()}

    def counters(self, direction: str) -> dict:
        """``direction``'s lossless figures: sent and resent by its sender;
        gaps, recovered, duplicates and skipped at its receiver."""
        tx, rx = (self.endpoints[r].counters for r in ENDS[direction])
        return {"sent": tx["lossless_sent"], "resent": tx["resent"], "gaps": rx["gaps"],
                "recovered": rx["recovered"], "duplicates": rx["duplicates"],
                "skipped": rx["skipped"]}

    def _push(self, t: float, action: str, direction: str, payload) -> None:
        heapq.heappush(self._events, (t, next(self._order), action, direction, payload))

    def _transmit(self, now: float, direction: str, action: str, payload, kind: str) -> None:
        spec = self.spec
        if spec.change_at_s is not None and now >= spec.change_at_s and \
                self.channels[direction].profile is not spec.then:
            self.channels[direction].profile = spec.then
        for t in self.channels[direction].send(now, MESSAGE_BYTES.get(kind, 100)):
            self._push(t, action, direction, payload)

    def _start(self, now: float) -> None:
        """The heartbeats, from the first period boundary after ``now``."""
        if not self._ticking:
            self._ticking = True
            k = math.floor(now / self.spec.heartbeat_s) + 1
            self._push(k * self.spec.heartbeat_s, "tick", "", k)

    def send(self, now: float, direction: str, message: Message, lossless: bool) -> None:
        self._advance(now)
        if not lossless:
            self._transmit(now, direction, "lossy", message, message.KIND)
            return
        self.endpoints[ENDS[direction][0]].stream.send(str(message.KIND), now,
                                                       message.fields(), True)

    def _arrive(self, t: float, action: str, direction: str, payload) -> None:
        if action == "lossy":
            self._ready[direction].append(payload)
            return
        if action == "tick":                # both sides' housekeeping, as Endpoint.poll
            for incoming, (_, role) in ENDS.items():
                stream = self.endpoints[role].stream
                stream.heartbeat(t)
                self._deliver(incoming, stream.repair(t))   # a gap given up: what follows
            self._push((payload + 1) * self.spec.heartbeat_s, "tick", "", payload + 1)
            return
        # A message of the stream arriving at the receiver of ``direction``
        # (a heartbeat or a resend travels the direction of its sender).
        receiver = self.endpoints[ENDS[direction][1]].stream
        if action == "heartbeat":
            receiver.on_heartbeat(payload, t)
        elif action == "resend":
            receiver.serve_resend(payload, t)
        else:
            self._deliver(direction, receiver.receive(payload, t))

    def _deliver(self, direction: str, messages: list[dict]) -> None:
        self._ready[direction] += [parse(m) for m in messages if m is not None]

    def _advance(self, now: float) -> None:
        self._start(now)
        while self._events and self._events[0][0] <= now:
            t, _, action, d, payload = heapq.heappop(self._events)
            self._now = t
            self._arrive(t, action, d, payload)
        self._now = now

    def due(self, now: float, direction: str) -> list[Message]:
        self._advance(now)
        out, self._ready[direction] = self._ready[direction], []
        return out

    def end(self, role: str) -> "NetworkEnd":
        """``role``'s ("slave" or "master") end of the network, a
        :class:`~telethermal.teleop.links.Link`."""
        sending = next(d for d, (sender, _) in ENDS.items() if sender == role)
        receiving = next(d for d, (_, receiver) in ENDS.items() if receiver == role)
        return NetworkEnd(self, sending, receiving)


class NetworkEnd:
    """One side's end of a :class:`SimNetwork`: a message is sent at its
    ``Send.t_s``; :meth:`due` advances the network to ``now_s``."""

    def __init__(self, net: SimNetwork, sending: str, receiving: str):
        self.net, self.sending, self.receiving = net, sending, receiving

    def send(self, s: Send) -> bool:
        self.net.send(s.t_s, self.sending, s.message, s.lossless)
        return True

    def due(self, now_s: float) -> list[Message]:
        return self.net.due(now_s, self.receiving)


# ---------------------------------------------------------------- one touch
MODES = ("compensated", "naive", "oracle")


@dataclass
class NetworkTouch:
    summary: dict
    trace: dict


def run_network_touch(scene, material: str, identifier, curves: dict, config,
                      network: NetworkSpec = NetworkSpec(), seed: int = 0,
                      contact_s: float = 2.0, mode: str = "compensated",
                      object_id: str | None = None, memory: ObjectMemory | None = None,
                      network_seed: int | None = None) -> NetworkTouch:
    """One touch of ``material`` through the simulated network.

    ``mode``: "compensated" (the master renders from the slave's estimates
    and trajectories, ``config.before`` until a decision), "naive" (the
    master tracks the latest streamed flux setpoint) or "oracle" (no
    network: the master knows the material at its contact onset; the floor
    any compensation can reach). ``memory``: the slave's object memory
    (shared across touches by the caller); ``object_id`` names the object.
    The touch's physics and sensor noise depend only on ``seed``; the
    network's draws on ``network_seed`` (default: ``seed``)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    scene = with_finger(scene)
    config = replace(config, source="setpoints" if mode == "naive" else "trajectory")
    pad = Slave(scene, material, identifier, slave_rng(seed), contact_s=contact_s + 1.0)
    slave = SimSlaveService(pad, curves, network.estimates, object_id, memory,
                            scene.sample_rate_hz)
    world = MasterWorld(scene, seed)
    operator = world.operator
    net = SimNetwork(network, np.random.default_rng([seed if network_seed is None
                                                     else network_seed, 15]))
    master = SimMasterService(scene, config, curves, pad.classes,
                              slave.announcement(-PRE_CONTACT_S), operator.finger_ir_c,
                              oracle=material if mode == "oracle" else None)
    session = master.session
    touch = world.display(config.rate_hz, contact_s, master.idle_c)
    from telethermal.devices.display import SimDisplay    # not the drivers, at import

    t = run_touch_loop(touch, SimDisplay(touch), slave, master, net.end("slave"),
                       net.end("master"), config.rate_hz).t_end_s
    slave.lift(t)
    display = master.display
    metrics = compare_with_direct(scene, material, pad.object_true_c, operator, touch.trace,
                                  contact_s, display.rendered_from_s)
    news_s = 0.0 if mode == "oracle" else session.first_news_s
    # What the slave decided on this touch, as the master heard it (never
    # the memory's recollection the display may have rendered): teleop/decision.py.
    decision = touch_decision(session.link.estimates)
    est = decision.estimate
    summary = {
        "material": material, "seed": seed, "mode": mode, "object_id": object_id,
        "before_identification": config.before, "estimates": network.estimates,
        "first_news_s": news_s, "master_onset_s": master.onset_s, "slave_onset_s": (
            None if pad.onset_s is None or slave.touch_t0 is None
            else slave.touch_t0 + pad.onset_s),
        **decision.fields(),            # identified, decision_time_s, identified_at_s
        "decision_reason": est.reason if est is not None else Reason.NO_ESTIMATE,
        "render_start_s": display.rendered_from_s,
        "rendered": display.rendering,
        **windowed_errors(touch.trace, contact_s, news_s),
        "temp_rms_error_c": metrics["temp_rms_error_c"],
        **safety_summary(display), "link_counters": dict(session.link.counters),
        "memory_counts": memory_counts(session.link.counters, slave.session.counters),
        "lossless": {d: net.counters(d) for d in ENDS},
        "channel": {d: dict(c.counters) for d, c in net.channels.items()},
    }
    return NetworkTouch(summary, touch.trace)


def windowed_errors(trace: dict, contact_s: float, first_news_s: float | None) -> dict:
    """Flux RMS error relative to the direct contact's peak over the blind
    window (contact until the first news reached the master), after it,
    and over the whole contact. No news at all: the whole contact is blind."""
    t = trace["t_s"]
    during = (t >= 0) & (t < contact_s)
    err = trace["flux_w_m2"] - trace["direct_flux_w_m2"]
    peak = float(np.max(np.abs(trace["direct_flux_w_m2"][during])))
    news = contact_s if first_news_s is None else max(first_news_s, 0.0)

    def rms(mask):
        return float(np.sqrt(np.mean(err[mask] ** 2)) / peak) if mask.any() else math.nan

    return {"flux_rms_error_rel_blind": rms(during & (t < news)),
            "flux_rms_error_rel_after_news": rms(during & (t >= news)),
            "flux_rms_error_rel_whole": rms(during),
            "blind_s": news}
