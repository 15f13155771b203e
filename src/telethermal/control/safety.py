"""The safety supervisor: a pure function every pad setpoint passes through.

``supervise(state, reading, request, limits, dt_s)`` returns what was
actually applied and the next state; it never touches a device and never
reads a clock. It guards what the skin touches: the pad's **surface**, as the
sensor's thermocouple at the contact face reads it, inside a band (default
15-43 C: ISO 13732-1 gives 43 C as the burn threshold of a contact of 8 h,
41-43 C for shorter ones being painless; ISO 13732-3 gives 15 C as the pain
threshold of a long fingertip contact with a cold conductive surface). The
junction behind the pad's layers may go past the band to move the surface
faster; it is bounded by the module's own limits (current, voltage, hot
side), not by a temperature band. While the surface is at an end of the
band, no request drives the junction past it (it is held at the
edge; short of it, the junction's excursion past the edge
shrinks with the surface's margin). It limits the rate of change of the junction's
setpoint, clamps the flux setpoint (and refuses flux that would drive the
pad further past either end of the band), and enters a **safe state** —
hold the pad at a neutral 33 C, since "off" is not neutral for a Peltier —
within the same control period on:

- a temperature or flux reading that is NaN, infinite or outside the
  plausible range;
- a stuck sensor: readings bit-for-bit unchanged for ``stuck_after_s`` (a
  live sensor always shows noise);
- no setpoint, a non-finite one, or one older than ``setpoint_lifetime_s``;
- the surface past the band by more than ``surface_margin_k``.

It leaves the safe state when every condition has cleared, logs entering
and leaving, and counts every event.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from enum import StrEnum

from telethermal.errors import ControlError

log = logging.getLogger(__name__)


class Fault(StrEnum):
    """Why the safe state: the values are the event names summaries and
    recordings hold."""
    READING_OUT_OF_RANGE = "temperature reading out of range"
    SURFACE_OUT_OF_BAND = "surface out of band"
    FLUX_NOT_FINITE = "flux reading not finite"
    STUCK_SENSOR = "stuck sensor"
    NO_SETPOINT = "no setpoint"
    SETPOINT_NOT_FINITE = "setpoint not finite"
    SETPOINT_EXPIRED = "setpoint expired"


class Clamp(StrEnum):
    """What a healthy request had limited; counted as ``clamped: <value>``."""
    SURFACE_BAND = "surface band"
    RATE = "rate"
    FLUX = "flux"
    FLUX_AT_TEMPERATURE_LIMIT = "flux at temperature limit"

    @property
    def event(self) -> str:
        return f"clamped: {self.value}"


class Transition(StrEnum):
    ENTERED_SAFE_STATE = "entered safe state"
    LEFT_SAFE_STATE = "left safe state"


#: The events a session's ``safety_events`` counts: every entry into the
#: safe state and every limited setpoint (faults are counted by name beside).
SAFETY_EVENTS = frozenset({Transition.ENTERED_SAFE_STATE.value,
                           *(c.event for c in Clamp)})


def safety_event_count(events: dict) -> int:
    """The number of safety events in a supervisor's ``events`` counts."""
    return int(sum(n for name, n in events.items() if name in SAFETY_EVENTS))


@dataclass(frozen=True, slots=True)
class SafetyLimits:
    skin_min_c: float = 15.0
    skin_max_c: float = 43.0
    neutral_c: float = 33.0
    max_rate_k_s: float = 5.0
    max_flux_w_m2: float = 10_000.0
    setpoint_lifetime_s: float = 0.5
    stuck_after_s: float = 0.5
    reading_min_c: float = -20.0
    reading_max_c: float = 80.0
    #: The surface this far past the band is a fault (the safe state), not
    #: only a limit: the controller failed to hold it.
    surface_margin_k: float = 1.0
    #: K the junction may go past a band edge per K of the surface's margin
    #: to it (see ``_limit``).
    barrier_gain: float = 0.5

    def __post_init__(self):
        if not self.skin_min_c <= self.neutral_c <= self.skin_max_c:
            raise ControlError("the neutral temperature must lie inside the skin band")


@dataclass(frozen=True, slots=True)
class Reading:
    t_s: float
    pad_temp_c: float
    flux_w_m2: float


@dataclass(frozen=True, slots=True)
class Request:
    """A setpoint: the pad temperature and the flux wanted, issued at ``issued_s``."""

    temp_c: float
    flux_w_m2: float
    issued_s: float


@dataclass(frozen=True, slots=True)
class Applied:
    temp_c: float                    # pad temperature setpoint actually applied
    flux_w_m2: float | None          # flux setpoint applied; None in the safe state
    safe: bool
    reasons: tuple[str, ...] = ()    # why safe
    clamps: tuple[str, ...] = ()     # what was limited


@dataclass(frozen=True)
class SafetyState:
    applied_temp_c: float
    safe: bool = False
    last_reading: tuple[float, float] | None = None
    unchanged_since_s: float = math.inf      # when the current reading was first seen
    events: dict = field(default_factory=dict)

    def count(self, name: str) -> int:
        return self.events.get(name, 0)


def initial_state(limits: SafetyLimits = SafetyLimits()) -> SafetyState:
    """Start in the safe state at the neutral temperature until told otherwise."""
    return SafetyState(applied_temp_c=limits.neutral_c, safe=True)


def _faults(state: SafetyState, reading: Reading, request: Request | None,
            limits: SafetyLimits) -> list[Fault]:
    faults = []
    temp_ok = math.isfinite(reading.pad_temp_c) and \
        limits.reading_min_c <= reading.pad_temp_c <= limits.reading_max_c
    if not temp_ok:
        faults.append(Fault.READING_OUT_OF_RANGE)
    elif not (limits.skin_min_c - limits.surface_margin_k <= reading.pad_temp_c
              <= limits.skin_max_c + limits.surface_margin_k):
        faults.append(Fault.SURFACE_OUT_OF_BAND)
    if not math.isfinite(reading.flux_w_m2):
        faults.append(Fault.FLUX_NOT_FINITE)
    if reading.t_s - state.unchanged_since_s >= limits.stuck_after_s:
        faults.append(Fault.STUCK_SENSOR)
    if request is None:
        faults.append(Fault.NO_SETPOINT)
    elif not (math.isfinite(request.temp_c) and math.isfinite(request.flux_w_m2)):
        faults.append(Fault.SETPOINT_NOT_FINITE)
    elif reading.t_s - request.issued_s > limits.setpoint_lifetime_s:
        faults.append(Fault.SETPOINT_EXPIRED)
    return faults


def surface_barrier(limits: SafetyLimits, surface_c: float) -> tuple[float, float]:
    """(lowest, highest) junction allowed with the pad's surface at
    ``surface_c``: past a band edge by ``barrier_gain`` K per K of the
    surface's margin to it, at the edge not past it. The display's
    controller stays inside it itself; the supervisor enforces it."""
    g = limits.barrier_gain
    return (limits.skin_min_c - g * max(surface_c - limits.skin_min_c, 0.0),
            limits.skin_max_c + g * max(limits.skin_max_c - surface_c, 0.0))


def _limit(state, reading, request, limits, dt_s):
    """Band, rate and flux limits on a healthy request: (temp, flux, clamps)."""
    clamps = []
    # A barrier on the junction from the surface's margin to the band: the
    # junction may go past an edge by barrier_gain K per K the surface still
    # has, so the film's lag cannot carry the surface past the edge; at the
    # edge, no further.
    lo, hi = surface_barrier(limits, reading.pad_temp_c)
    temp = min(max(request.temp_c, lo), hi)
    if temp != request.temp_c:
        clamps.append(Clamp.SURFACE_BAND)
    step = limits.max_rate_k_s * dt_s
    limited = min(max(temp, state.applied_temp_c - step), state.applied_temp_c + step)
    if limited != temp:
        clamps.append(Clamp.RATE)
    flux = min(max(request.flux_w_m2, -limits.max_flux_w_m2), limits.max_flux_w_m2)
    if flux != request.flux_w_m2:
        clamps.append(Clamp.FLUX)
    # Positive flux heats the skin: none at or past the top of the band, and
    # no cooling flux at or past its bottom.
    if (reading.pad_temp_c >= limits.skin_max_c and flux > 0) or \
            (reading.pad_temp_c <= limits.skin_min_c and flux < 0):
        flux = 0.0
        clamps.append(Clamp.FLUX_AT_TEMPERATURE_LIMIT)
    return limited, flux, clamps


def supervise(state: SafetyState, reading: Reading, request: Request | None,
              limits: SafetyLimits, dt_s: float) -> tuple[Applied, SafetyState]:
    """One control period. Returns (what is applied, the next state)."""
    if not (dt_s > 0 and math.isfinite(dt_s)):
        raise ControlError(f"supervise needs a positive control period, got {dt_s}")
    pair = (reading.pad_temp_c, reading.flux_w_m2)
    first_seen = state.unchanged_since_s if pair == state.last_reading else reading.t_s
    tracked = replace(state, last_reading=pair, unchanged_since_s=first_seen)
    faults = _faults(tracked, reading, request, limits)
    events = dict(state.events)
    if faults:
        for fault in faults:
            events[fault.value] = events.get(fault.value, 0) + 1
        if not state.safe:
            key = Transition.ENTERED_SAFE_STATE.value
            events[key] = events.get(key, 0) + 1
            log.warning("safe state entered: %s", ", ".join(faults))
        applied = Applied(limits.neutral_c, None, True, tuple(faults))
        return applied, replace(tracked, applied_temp_c=limits.neutral_c, safe=True,
                                events=events)
    if state.safe:
        key = Transition.LEFT_SAFE_STATE.value
        events[key] = events.get(key, 0) + 1
        log.info("safe state left")
    temp, flux, clamps = _limit(state, reading, request, limits, dt_s)
    for clamp in clamps:
        events[clamp.event] = events.get(clamp.event, 0) + 1
    if clamps:
        log.info("setpoint limited (%s)", ", ".join(clamps))
    return (Applied(temp, flux, False, (), tuple(clamps)),
            replace(tracked, applied_temp_c=temp, safe=False, events=events))
