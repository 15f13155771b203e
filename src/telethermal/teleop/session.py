"""The session's rules, once: what goes out on which message, when.

:class:`SlaveSession` (below, :class:`MasterSession` for the master) holds no socket and no clock: its driver passes
``now`` and the master's contact events in, and gets back the messages to
send (:class:`Send`, with the time the rule sends them at). Two drivers run
it: the services (``services/``, on ZeroMQ and the real clock) and the
simulator's sides (``sim/sides.py``: the in-process run and ``bench
faults``' simulated network, in one loop over their link), so the
latency figures are measured on the rules the product runs
(``proto/PROTOCOL.md`` section 6).

The rules:

* The master's touching ``contact_event`` puts the pad down (one contact at
  a time; only the session that opened a contact may lift it, by its id;
  anything else is ignored and counted by the driver).
* At the pad's own onset: a touching ``contact_event`` naming the object
  and what the memory holds for it (6b).
* No object temperature (the thermometer's reading was refused): nothing is
  identified or sent from the touch beyond its onset.
* Every estimate on the lossy stream (``posterior_estimate``); a lossless
  ``material_estimate`` for a change of the decided label and for the
  contact's final estimate (6a). ``estimates="lossless"`` sends every
  estimate lossless (the protocol before issue 15; kept so its cost can be
  measured).
* A ``flux_trajectory`` when the decided label changes to a renderable
  material or pair.
* For the naive baseline, a ``flux_setpoint`` per new sample once the
  operator's finger temperature is known.
* A ``measurement_batch`` per ``batch`` samples.
* At the lift: the contact's final estimate if it was not sent, then the
  non-touching ``contact_event``; the touch's decision is judged against
  what the memory announced for the object (:func:`~telethermal.teleop.memory.judge`,
  the master's rule: ``memory_overruled``, ``memory_kept`` counted in
  ``counters``), then the object memory learns it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from telethermal.choices import choice
from telethermal.ident.openset import effusivity_of
from telethermal.render.generator import naive_setpoint
from telethermal.render.sampled import SampledGenerator
from telethermal.teleop.link import SlaveLink
from telethermal.teleop.master import SlaveNews
from telethermal.teleop.memory import Judgement, ObjectMemory, Verdict, judge, learnable
from telethermal.wire.messages import (ContactEvent, FluxSetpoint, FluxTrajectory,
                                       ESTIMATES, MaterialEstimate, MeasurementBatch,
                                       Message, PosteriorEstimate, given)
from telethermal.wire.schema import MessageKind

#: The session's time before the finger's contact (s): the slave's
#: announcement reaches the master then, the display idles from then (the
#: services' touch and every simulated driver of one).
PRE_CONTACT_S = 0.2

#: Samples per ``measurement_batch``.
BATCH = 10
#: How long the master may render a trajectory with the link lost (s).
TRAJECTORY_VALID_S = 60.0


class EstimateRoute(StrEnum):
    """How the slave sends its estimates (PROTOCOL.md 6a)."""
    #: On the stream socket, latest value wins; the contact's final one lossless.
    STREAM = "stream"
    #: Every estimate on the lossless control socket (an ordered route).
    LOSSLESS = "lossless"


def estimate_route(value: str) -> EstimateRoute:
    """``value`` as an :class:`EstimateRoute`; ``ValueError`` naming them."""
    return choice(EstimateRoute, value, "estimates")


class ContactRequest(StrEnum):
    """What a master's ``contact_event`` asks of the slave's session."""
    TOUCH = "touch"              # the pad goes down
    LIFT = "lift"                # of the contact going on, by its owner
    IGNORED = "ignored"          # anything else (counted by the driver)


class ServiceState(StrEnum):
    """A service's state, as ``status.state`` carries it (PROTOCOL.md)."""
    IDLE = "idle"
    TOUCHING = "touching"
    RENDERING = "rendering"
    STOPPING = "stopping"


@dataclass(frozen=True)
class Send:
    """One message the session sends and the time (the sender's clock) the
    rule sends it at."""

    t_s: float
    message: Message

    @property
    def kind(self) -> MessageKind:
        return self.message.KIND

    @property
    def lossless(self) -> bool:
        return self.message.lossless


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


class SlaveSession:
    """The slave's side of one session; see the module docstring.

    ``curves``: the flux generator's sampled curves (what a trajectory
    carries); ``rate_hz``: the pad's sample rate; ``memory``: the object memory (shared across touches).
    ``measurements``: send ``measurement_batch`` (a driver that models no
    reader of them may leave them out). ``counters``: where the memory's
    counters go (the service passes its own; PROTOCOL.md section 4)."""

    def __init__(self, curves: dict, rate_hz: float, memory: ObjectMemory | None = None,
                 estimates: EstimateRoute | str = EstimateRoute.STREAM, batch: int = BATCH,
                 measurements: bool = True, counters: dict | None = None):
        estimates = estimate_route(estimates)
        if batch < 1:
            raise ValueError(f"batch must be >= 1 sample, got {batch}")
        self.curves, self.rate_hz = curves, float(rate_hz)
        self.generator = SampledGenerator(curves)
        self.memory = memory if memory is not None else ObjectMemory()
        #: Touches whose decision disagreed with the memory, and classes named
        #: early on a remembered new material (:func:`judge`).
        self.counters = counters if counters is not None else {}
        for name in (Judgement.OVERRULED, Judgement.KEPT):
            self.counters.setdefault(str(name), 0)
        self.estimates, self.batch, self.measurements = estimates, batch, measurements
        self.pad = None
        self.object_id: str | None = None
        self.contact_id = 0
        self.owner: str | None = None          # the master session that opened the contact
        self.touch_t0: float | None = None
        self.finger_c: float | None = None
        #: The memory's judgement of the last touch (counted in ``counters``:
        #: OVERRULED or KEPT), None when it judged none; reset at a touch.
        self.judgement: Judgement | None = None
        self._decided_label: str | None = None
        self._decision_sent = None             # the last estimate sent lossless
        self._sent = 0                         # samples sent in measurement batches
        self._sp_sample = -1                   # the sample of the last setpoint

    # ------------------------------------------------------------ the object
    @property
    def touching(self) -> bool:
        return self.touch_t0 is not None

    def place(self, pad, object_id: str | None) -> None:
        """A fresh trial under the pad (``teleop.slave.Slave``), on ``object_id``."""
        if self.touching:
            raise ValueError("cannot place an object during a contact: lift first")
        self.pad, self.object_id, self._sent = pad, object_id, 0

    def object_temp_c(self) -> float | None:
        """The object's measured temperature; None when the thermometer gave none."""
        return _finite_or_none(float(self.pad.object_ir_c))

    def object_fields(self) -> dict:
        """The object under the pad and what the memory holds for it (6b):
        the object fields of a :class:`ContactEvent`."""
        known = self.memory.recall(self.object_id)
        remembered_e = {} if known is None or known.effusivity is None else \
            {f"object_{k}": v for k, v in known.effusivity.fields.items()}
        return {"object_id": self.object_id,
                "object_material": None if known is None else str(known.material),
                "object_confidence": None if known is None else float(known.confidence),
                **remembered_e}

    def announcement(self, now: float) -> Send:
        """The object announcement (on ``place`` and to a new master)."""
        return Send(now, ContactEvent(contact_id=0, touching=False, t_s=now, force_n=0.0,
                                      object_temp_c=self.object_temp_c(),
                                      **self.object_fields()))

    # ------------------------------------------------------------ contacts
    def classify(self, m: ContactEvent, peer_session: str | None = None) -> ContactRequest:
        """What a master's ``contact_event`` asks of this session."""
        if m.touching and not self.touching:
            return ContactRequest.TOUCH
        if not m.touching and self.touching and m.contact_id == self.contact_id and \
                peer_session == self.owner:
            return ContactRequest.LIFT
        return ContactRequest.IGNORED

    def on_contact_event(self, m: ContactEvent, now: float, peer_session: str | None = None
                         ) -> tuple[ContactRequest, list[Send], Verdict | None]:
        """A master's ``contact_event``, acted on: the pad goes down (a
        touch), or leaves the object (its owner's lift), or nothing. Returns
        what it asked, what goes out for it and, for a lift, the memory's
        verdict on the touch."""
        request = self.classify(m, peer_session)
        if request == ContactRequest.TOUCH:
            self.touch(m.contact_id, now, given(m.finger_temp_c), owner=peer_session)
            return request, [], None
        if request == ContactRequest.LIFT:
            return (request, *self.lift(now))
        return request, [], None

    def touch(self, contact_id: int, now: float, finger_c: float | None,
              owner: str | None = None) -> None:
        """The pad goes down on the object now."""
        if self.pad is None:
            raise ValueError("no object placed under the pad")
        self.contact_id, self.touch_t0, self.owner = contact_id, now, owner
        self.finger_c = finger_c
        self._decided_label = self._decision_sent = None
        self._sp_sample = -1
        self.judgement = None

    def lift(self, now: float) -> tuple[list[Send], Verdict]:
        """The pad leaves the object: the final estimate if unsent, the
        lift event; returns those and the memory's verdict on the touch."""
        if not self.touching:
            return [], Verdict.IGNORED
        out = []
        est = self.pad.estimate
        if est is not None and est is not self._decision_sent:
            out.append(self._decision(now, est))      # the contact's final estimate (6a)
        out.append(Send(now, ContactEvent(contact_id=self.contact_id, touching=False, t_s=now,
                                          force_n=0.0, object_temp_c=self.object_temp_c())))
        self.touch_t0 = self.owner = None
        held = self.memory.recall(self.object_id)
        verdict = None if held is None or not learnable(est) else \
            judge(held.material, held.effusivity, est)
        if verdict in (Judgement.OVERRULED, Judgement.KEPT):
            self.counters[str(verdict)] += 1
            self.judgement = verdict
        return out, self.memory.learn(self.object_id, est, now, classes=self.pad.classes)

    @property
    def onset_at_s(self) -> float | None:
        """The pad's contact onset on the slave's clock (a trajectory's anchor)."""
        if not self.touching or self.pad.onset_s is None:
            return None
        return self.touch_t0 + float(self.pad.onset_s)

    # ------------------------------------------------------------ per period
    def step(self, now: float) -> list[Send]:
        """Read the pad up to ``now``; what goes out for it."""
        if not self.touching:
            return []
        pad, out = self.pad, []
        at = lambda slave_t: self.touch_t0 + float(slave_t)          # noqa: E731
        before = pad.onset_s
        events = pad.advance_to(now - self.touch_t0)
        if before is None and pad.onset_s is not None:
            out.append(Send(at(pad.onset_s), ContactEvent(
                contact_id=self.contact_id, touching=True, t_s=at(pad.onset_s),
                force_n=float(pad.force_n[pad.onset_index]),
                object_temp_c=self.object_temp_c(), **self.object_fields())))
        if self.object_temp_c() is None:
            return out
        finished = pad.stream is not None and pad.stream.finished
        for ev in events:
            out += self._estimate(at(ev.t_s), ev.estimate, ev is events[-1] and finished)
        if pad.onset_s is not None and (events or pad.samples_read > self._sp_sample):
            out += self._setpoint(now)
        if self.measurements and pad.samples_read - self._sent >= self.batch:
            out.append(self._batch(now))
        return out

    def _estimate_fields(self, e) -> dict:
        return dict(contact_id=self.contact_id, t_since_contact_s=float(e.t_s),
                    classes=list(self.pad.classes), posteriors=[float(p) for p in e.posteriors],
                    label=str(e.label), confidence=float(e.confidence), decided=bool(e.decided),
                    reason=str(e.reason), object_temp_c=float(self.pad.object_ir_c),
                    **effusivity_of(e))

    def _decision(self, t: float, e) -> Send:
        self._decision_sent = e
        return Send(t, MaterialEstimate(**self._estimate_fields(e)))

    def _estimate(self, t: float, e, final: bool) -> list[Send]:
        changed = e.decided and e.label != self._decided_label
        if self.estimates == EstimateRoute.LOSSLESS:
            out = [self._decision(t, e)]
        else:
            out = [Send(t, PosteriorEstimate(**self._estimate_fields(e)))]
            if changed or final:
                out.append(self._decision(t, e))
        if changed and not e.label.is_unknown and e.label in self.curves:
            c = self.curves[e.label]
            out.append(Send(t, FluxTrajectory(
                contact_id=self.contact_id, material=str(e.label),
                object_temp_c=float(self.pad.object_ir_c),
                t_s=[0.0] + list(c["t_s"]), g_w_m2k=[0.0] + list(c["g_w_m2k"]),
                valid_s=TRAJECTORY_VALID_S, t0_s=self.onset_at_s)))
        if e.decided:
            self._decided_label = e.label
        return out

    def _setpoint(self, now: float) -> list[Send]:
        """The naive path: the display flux for "now" from what the slave
        believes at this instant (the fault benchmark's baseline)."""
        pad = self.pad
        self._sp_sample = pad.samples_read
        if self.finger_c is None:
            return []
        t = max(now - self.touch_t0 - pad.onset_s, 0.0)
        flux = naive_setpoint(self.generator, pad.classes, pad.estimate, t,
                              pad.object_ir_c - self.finger_c)
        if flux is None:
            return []
        return [Send(now, FluxSetpoint(contact_id=self.contact_id, t_since_contact_s=t,
                                       flux_w_m2=flux))]

    def _batch(self, now: float) -> Send:
        pad, read = self.pad, self.pad.samples_read
        i, ch = slice(self._sent, read), self.pad.channels
        send = Send(now, MeasurementBatch(
            contact_id=self.contact_id, t0_s=self.touch_t0 + float(pad.t_s[self._sent]),
            rate_hz=self.rate_hz,
            flux_w_m2=[float(v) for v in ch["heat_flux_W_m2"][i]],
            temp_c=[float(v) for v in ch["temperature_C"][i]],
            force_n=[float(v) for v in ch["force_N"][i]]))
        self._sent = read
        return send



class MasterSession:
    """The master's session rules, once: what it reads of the slave and
    what it tells the slave. Three periods' worth of rules, driven by the
    master service (both its simulated touches and the hardware display)
    and by the simulated network:

    * every message goes to the :class:`~telethermal.teleop.link.SlaveLink`
      (estimates, trajectories, the object announcement); the naive
      baseline's ``flux_setpoint`` is kept newest by ``t_since_contact_s``
      for the contact going on;
    * the display's contact onset (its own force sensor) opens a contact
      with the next id: the link begins it at that onset, the slave hears a
      touching ``contact_event`` with the operator's finger temperature;
    * the display's release ends it: the slave hears the lift, and what
      comes for that contact afterwards is stale.

    Times: ``now`` is the driver's clock; a display step's contact instant
    is on the display's own clock, ``clock_offset_s`` behind the driver's."""

    def __init__(self, link: SlaveLink | None = None, first_contact_id: int = 1):
        self.link = link if link is not None else SlaveLink()
        self.next_contact_id = first_contact_id
        self.contact_id: int | None = None
        self.setpoint_w_m2: float | None = None
        self.setpoint_t_s = -math.inf
        #: This contact's first estimate and first trajectory (driver's clock).
        self.first_news_s: float | None = None
        self.trajectory_at_s: float | None = None

    def on_message(self, m: Message, now: float, offset_s: float | None = None) -> None:
        """One message from the slave; ``offset_s``: slave clock minus ours."""
        link = self.link
        if isinstance(m, FluxSetpoint):
            if self.contact_id is not None and m.contact_id == self.contact_id and \
                    m.t_since_contact_s >= self.setpoint_t_s:
                self.setpoint_w_m2, self.setpoint_t_s = m.flux_w_m2, m.t_since_contact_s
            return
        had = link.trajectory
        link.on_message(m, now, offset_s)
        if self.contact_id is None or not isinstance(m, (*ESTIMATES, FluxTrajectory)) or \
                m.contact_id != self.contact_id:
            return
        if isinstance(m, ESTIMATES) and self.first_news_s is None:
            self.first_news_s = now
        if link.trajectory is not had and self.trajectory_at_s is None:
            self.trajectory_at_s = now

    def news(self, now: float, link_alive: bool) -> SlaveNews:
        """What the display reads this period."""
        return self.link.news(now, link_alive, self.setpoint_w_m2)

    def period(self, step, clock_offset_s: float, force_n: float,
               finger_c: float | None) -> list[Send]:
        """After the display's step: the contact it opened or closed."""
        event = step.contact
        if event is None:
            return []
        t = clock_offset_s + float(event.t_s)
        if event.touching:
            self.contact_id = self.next_contact_id
            self.next_contact_id += 1
            self.link.begin(self.contact_id)
            self.link.onset(t)
            self.setpoint_w_m2, self.setpoint_t_s = None, -math.inf
            self.first_news_s = self.trajectory_at_s = None
            return [Send(t, ContactEvent(contact_id=self.contact_id, touching=True, t_s=t,
                                         force_n=max(float(force_n), 0.0),
                                         finger_temp_c=finger_c))]
        return self.close_contact(t, finger_c)

    def close_contact(self, t_s: float, finger_c: float | None) -> list[Send]:
        """The contact going on ends (the display's release, or the driver's
        touch is over with no release detected): the slave hears the lift,
        and what comes for this contact from now on is stale."""
        if self.contact_id is None:
            return []
        out = [Send(t_s, ContactEvent(contact_id=self.contact_id, touching=False, t_s=t_s,
                                      force_n=0.0, finger_temp_c=finger_c))]
        self.link.end()
        self.contact_id = None
        return out
