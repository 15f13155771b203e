"""What the master knows from the slave, message by message.

:class:`SlaveLink` turns the slave's messages into the :class:`SlaveNews`
the display loop reads each period. It holds no socket and no clock of its
own (the caller passes ``now``), so the hard cases of a network (late,
reordered, duplicated messages, a clock offset, a lost link) are tested
here without one.

The rules, each a hard case of issue 6:

* Everything is keyed by ``contact_id``. A message for another contact than
  the one going on (an estimate that arrives after the finger lifted, the
  previous contact's messages reordered behind the next one's) is counted as
  ``stale`` and changes nothing.
* Estimates of one contact are kept newest by ``t_since_contact_s``: an
  older one arriving late does not replace a newer one. They come two ways:
  every posterior on the lossy stream (``posterior_estimate``: newest wins,
  a lost one costs nothing) and the decisions on the lossless control
  stream (``material_estimate``). A decision is never replaced by a newer
  undecided posterior, and a decision that arrives late (it was resent)
  still counts if no newer decision is held.
* Object memory: the slave announces the object it is at (``contact_event``
  with ``object_id``) and what it identified there before
  (``object_material``). A contact that begins after such an announcement
  renders the remembered material from t = 0 (an estimate with reason
  "object memory"), until the slave's own decision for this touch: the
  fresh decision wins and a disagreement is logged; a class named early on
  a remembered new material, its estimate consistent with the remembered
  one, leaves the memory in force. The contact's last decision is counted
  once at its end (``memory_overruled``, ``memory_kept``: :meth:`SlaveLink.end`). The rule is the slave's (:func:`~telethermal.teleop.memory.judge`). The slave's touching event names its object: another object
  than the announced one drops the memory for this contact
  (``memory_mismatch``).
* A trajectory is played from the master's own contact onset. Its anchor
  (the slave's onset, on the slave's clock) only says how far behind the
  slave touched; an anchor that lands in the master's future (a wrong clock
  offset) is counted and never waited for.
* A duplicated trajectory (same contact, same material, same curve) changes
  nothing; a different one for the same contact replaces it (the slave
  changed its mind) and is counted.
* Link loss: what is held stays valid for the trajectory's ``valid_s`` after
  the onset. A final estimate without a trajectory (the slave ended its
  identification "unknown": the display renders that estimate's posterior
  mixture) is as good as one, valid for ``final_valid_s``. Past that, or
  with only streaming (not final) posteriors, the news says the link is lost
  and the display decays to its safe state (it resumes when the link
  returns).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from telethermal.ident.anytime import Estimate, Label
from telethermal.ident.openset import EFFUSIVITY_KEYS
from telethermal.render.sampled import SampledGenerator
from telethermal.teleop.master import SlaveNews
from telethermal.teleop.memory import Effusivity, Judgement, judge, remembered_estimate
from telethermal.wire.messages import (ESTIMATES, ContactEvent, FluxTrajectory, Message,
                                       SessionConfig, given)

log = logging.getLogger(__name__)


@dataclass
class Trajectory:
    material: str
    t_s: np.ndarray
    g_w_m2k: np.ndarray
    valid_s: float
    anchor_lag_s: float | None       # slave onset - master onset, master clock


@dataclass
class SlaveLink:
    generator: SampledGenerator | None = None
    classes: tuple[str, ...] = ()
    object_temp_c: float | None = None
    contact_id: int | None = None
    onset_s: float | None = None       # master clock, of the contact going on
    estimates: list[Estimate] = field(default_factory=list)   # accepted, in arrival order
    latest: Estimate | None = None          # the newest by t_since_contact_s
    decision: Estimate | None = None        # the newest decided one
    trajectory: Trajectory | None = None
    final_valid_s: float = 60.0
    #: The object the slave announced it is at, and what it remembers of it.
    object_id: str | None = None
    remembered: tuple[str, float] | None = None      # (material, confidence)
    #: A remembered new material's estimate (the estimate's effusivity field
    #: names), announced with it (section 6b); None otherwise.
    remembered_effusivity: dict | None = None
    memory: Estimate | None = None          # the recollection this contact renders
    recalled: Estimate | None = None        # what this contact began with, for reports
    #: The memory the contact's decision is judged on at its end (None: none,
    #: or the slave's pad was on another object than announced).
    _judged: Estimate | None = field(default=None, repr=False)
    counters: dict[str, int] = field(default_factory=lambda: dict.fromkeys(
        ("stale", "older_estimate", "duplicate_trajectory", "replaced_trajectory",
         "anchor_in_future", "memory_used", "memory_overruled", "memory_mismatch",
         "memory_kept"), 0))

    # ------------------------------------------------------------ contacts
    def begin(self, contact_id: int) -> None:
        """A new contact is going on (the master's onset is not yet known)."""
        self.contact_id, self.onset_s = contact_id, None
        self.estimates, self.trajectory = [], None
        self.latest = self.decision = self.memory = self.recalled = self._judged = None
        if self.remembered is not None and (
                Label(self.remembered[0]).within(self.classes) or
                (Label(self.remembered[0]).is_new and self.remembered_effusivity)):
            self.memory = remembered_estimate(*self.remembered, self.classes,
                                              self.remembered_effusivity)
            self.recalled = self.memory          # kept for the report, never cleared
            self._judged = self.memory           # what the touch's decision is judged on
            self._memory_object = self.object_id
            self.counters["memory_used"] += 1

    def onset(self, t_s: float) -> None:
        self.onset_s = t_s

    def end(self) -> None:
        """The contact ends: the decision it held, judged once against the
        memory it began with (the slave's rule at its lift, so both sides
        count a touch alike: ``memory_overruled``, ``memory_kept``)."""
        held = self._judged
        if held is not None and self.decision is not None:
            verdict = judge(held.label, Effusivity.of(held), self.decision)
            if verdict in (Judgement.KEPT, Judgement.OVERRULED):
                self.counters[str(verdict)] += 1
        self.contact_id, self._judged = None, None

    # ------------------------------------------------------------ messages
    def on_message(self, m: Message, now_s: float, offset_s: float | None = None) -> None:
        """``now_s``: the master's clock; ``offset_s``: slave clock minus
        master clock, if known."""
        if isinstance(m, SessionConfig):
            self.generator = SampledGenerator(m.curves)
            self.classes = tuple(m.classes)
            return
        if isinstance(m, ContactEvent):
            # The slave always says what it measured; nil: it has no object
            # temperature (its thermometer's reading was refused), so the
            # display holds neutral rather than the previous object's.
            self.object_temp_c = given(m.object_temp_c, self.object_temp_c)
            self._on_object(m)
            return
        if not isinstance(m, (*ESTIMATES, FluxTrajectory)):
            return
        if self.contact_id is None or m.contact_id != self.contact_id:
            self.counters["stale"] += 1
            return
        self.object_temp_c = m.object_temp_c
        if isinstance(m, FluxTrajectory):
            self._on_trajectory(m, now_s, offset_s)
            return
        # An older slave sends no effusivity: the fields stay None.
        self._on_estimate(Estimate(m.t_since_contact_s, tuple(m.posteriors), m.label,
                                   m.confidence, m.decided, m.reason,
                                   *(given(getattr(m, k)) for k in EFFUSIVITY_KEYS)))

    def _on_object(self, m: ContactEvent) -> None:
        if not m.names_object:
            return                       # a slave that does not name its objects
        if m.touching and m.contact_id == self.contact_id:
            # The slave's pad is down: on the object the memory was for?
            if self.memory is not None and m.object_id != self._memory_object:
                log.warning("contact %s is on object %s, not the announced %s: its memory "
                            "is not used", self.contact_id, m.object_id, self._memory_object)
                self.counters["memory_mismatch"] += 1
                self.memory = self._judged = None
            return
        self.object_id = m.object_id
        material = given(m.object_material)
        self.remembered = None if material is None else \
            (material, float(given(m.object_confidence) or 0.0))
        self.remembered_effusivity = _remembered_effusivity(m) \
            if material is not None and Label(material).is_new else None

    def _on_estimate(self, e: Estimate) -> None:
        newest = self.latest is None or e.t_s >= self.latest.t_s
        newest_decision = e.decided and (self.decision is None or e.t_s >= self.decision.t_s)
        if not (newest or newest_decision):
            self.counters["older_estimate"] += 1
            return
        self.estimates.append(e)
        if newest:
            self.latest = e
        if newest_decision:
            self.decision = e
            mem = self.memory
            # One rule with the slave's (memory.judge): "unknown", or a
            # decision vaguer than the memory (a pair that holds the
            # remembered material), leaves the memory in force; so does a
            # class named early whose estimate holds the remembered new
            # material's (a closed set's early guess, revised later: not
            # evidence against the memory). The counters judge the
            # contact's last decision, once, at its end (:meth:`end`).
            verdict = None if mem is None else judge(mem.label, Effusivity.of(mem), e)
            if verdict == Judgement.OVERRULED:
                log.warning("contact %s: the slave decided %s, memory said %s: the fresh "
                            "decision wins", self.contact_id, e.label, mem.label)
                self.memory = None
            elif verdict == Judgement.AGREES:
                self.memory = None             # the decision takes over

    @property
    def estimate(self) -> Estimate | None:
        """What the display renders from: the memory while no fresh decision
        contradicts it; else the newest posterior, unless it is undecided and a
        decision is held."""
        if self.memory is not None:
            return self.memory
        if self.latest is not None and self.latest.decided:
            return self.latest
        return self.decision or self.latest

    def _on_trajectory(self, m: FluxTrajectory, now_s: float, offset_s: float | None) -> None:
        t = np.asarray(m.t_s, dtype=np.float64)
        g = np.asarray(m.g_w_m2k, dtype=np.float64)
        if len(t) and t[0] == 0:          # the explicit (0, 0) knot: the ramp is implied
            t, g = t[1:], g[1:]
        old = self.trajectory
        if old is not None and old.material == m.material and \
                np.array_equal(old.t_s, t) and np.array_equal(old.g_w_m2k, g):
            self.counters["duplicate_trajectory"] += 1
            return
        if old is not None:
            self.counters["replaced_trajectory"] += 1
        lag = None
        if given(m.t0_s) is not None and offset_s is not None and self.onset_s is not None:
            anchor = m.t0_s - offset_s                     # the slave's onset, our clock
            if anchor > now_s:
                self.counters["anchor_in_future"] += 1     # a wrong offset; not waited for
            else:
                lag = anchor - self.onset_s
        self.trajectory = Trajectory(m.material, t, g, float(m.valid_s), lag)
        self.generator.set_curve(m.material, t, g)

    # ------------------------------------------------------------ per period
    def news(self, now_s: float, link_alive: bool, setpoint_w_m2: float | None = None
             ) -> SlaveNews:
        # Between contacts nothing held is news: the last contact's decision
        # must not reach the display at the next onset, before ``begin``.
        estimate = self.estimate if self.contact_id is not None else None
        valid = link_alive
        if not link_alive and self.onset_s is not None:
            if self.trajectory is not None:
                valid = now_s - self.onset_s <= self.trajectory.valid_s
            elif estimate is not None and estimate.decided:
                valid = now_s - self.onset_s <= self.final_valid_s
        return SlaveNews(self.object_temp_c, estimate, self.classes, setpoint_w_m2,
                         link_ok=valid, expected_material=self.expected_material,
                         generator=self.generator)

    @property
    def expected_material(self) -> str | None:
        """What the slave announced for the object under its pad (object
        memory): one material, or a pair (its group label) when the memory
        holds one, if its materials are classes; None for an unknown object
        (the display then idles by the policy for an unknown object)."""
        if self.remembered is None:
            return None
        label = Label(self.remembered[0])
        return label if label.within(self.classes) else None

    @property
    def anchor_lag_s(self) -> float:
        tr = self.trajectory
        return math.nan if tr is None or tr.anchor_lag_s is None else tr.anchor_lag_s


def _remembered_effusivity(m: ContactEvent) -> dict | None:
    """A remembered new material's estimate from an announcement (the
    estimate's field names), None when absent or unusable
    (:meth:`Effusivity.of_fields`)."""
    keys = EFFUSIVITY_KEYS[:3]
    values = [given(getattr(m, "object_" + k, None)) for k in keys]
    if Effusivity.of_fields(*values) is None:
        return None
    return dict(zip(keys, (float(v) for v in values)))
