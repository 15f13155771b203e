"""The inner loop of a Peltier pad: the module's current that brings its cold
junction to a target temperature, within what the module and its driver
allow.

What a TEC controller board does (a PI on the junction's thermistor), with
two things a board's loop does not know and this one does, because the
host has them: a feed-forward of the current that would hold the target
with the present hot side and load (the smaller root of ``Qc(I) = load``,
:func:`~telethermal.physics.thermoelectric.hold_current_a`), and the
H-bridge's limits (``|I| <= Imax`` and the supply voltage), against which the
integral does not wind up (it integrates only while the output is free, or
when the error would take it back inside).

Gains: :class:`JunctionGains`' defaults (``kp`` = 10 A/K, ``ki`` = 500
A/(K s)) are the plain loop's, for a junction read with no lag (the
simulated sensing pad's held loop, :mod:`telethermal.physics.held_pad`): the
junction behind the pad's layers is a thermal mass of about 1.4 J/K on a
20 x 20 mm module, and a current pumps about ``S Tc`` = 3.5 W/A at room
temperature, so 10 A/K puts the crossover near 25 rad/s (4 Hz). The
display's loop (:class:`DisplayJunctionLoop`) reads a bonded sensor with a
lag and does not use them: its gains are designed for that lag by
:mod:`telethermal.control.junction_design` (on the shipped scene, with the
sensor's 0.1 s, ``kp`` about 1.56 A/K and ``ki`` about 1.14 A/(K s), a
crossover of 3.7 rad/s at a 60 degree phase margin).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from telethermal.control.junction_probe import JunctionProbe, ProbeVerdict
from telethermal.errors import ControlError
from telethermal.physics.thermoelectric import HBridge, ModuleParams, hold_current_a

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class JunctionGains:
    kp_a_k: float = 10.0
    ki_a_ks: float = 500.0

    def __post_init__(self):
        if not (self.kp_a_k >= 0 and self.ki_a_ks >= 0 and
                math.isfinite(self.kp_a_k) and math.isfinite(self.ki_a_ks)):
            raise ControlError(f"junction gains must be finite and >= 0, got {self}")


@dataclass(frozen=True, slots=True)
class JunctionOutput:
    current_a: float           # what the driver is asked for (inside its limits)
    saturated: bool            # the limits cut the request


class JunctionLoop:
    """One :meth:`update` per control period; pure (no device, no clock)."""

    def __init__(self, params: ModuleParams, driver: HBridge,
                 gains: JunctionGains = JunctionGains()):
        self.params, self.driver, self.gains = params, driver, gains
        self.integral_a = 0.0
        self.saturated_periods = 0

    def reset(self) -> None:
        self.integral_a = 0.0

    def update(self, target_c: float, junction_c: float, hot_c: float, dt_s: float,
               load_w: float = 0.0) -> JunctionOutput:
        """The current for this period. ``junction_c``/``hot_c``: the board's
        readings of the cold junction and of the hot side (its heat sink);
        ``load_w``: heat flowing into the junction from the pad, W, as far as
        the caller knows it (0 if not). A reading that is not finite gives
        0 A: the module then only conducts, and the caller's supervisor
        decides what is safe."""
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ControlError(f"junction loop needs a positive period, got {dt_s}")
        if not (math.isfinite(target_c) and math.isfinite(junction_c) and math.isfinite(hot_c)
                and math.isfinite(load_w)):
            self.integral_a = 0.0
            return JunctionOutput(0.0, False)
        error = junction_c - target_c        # positive: too warm, cool (positive current)
        ff = hold_current_a(self.params, target_c, hot_c, load_w)
        free = ff + self.gains.kp_a_k * error + self.integral_a
        current, cut = self.driver.limit(self.params, free, junction_c, hot_c)
        # Integrate while free, or when the error drives the output back inside.
        if not cut or (free > current) != (error > 0):
            self.integral_a += self.gains.ki_a_ks * error * dt_s
        if cut:
            self.saturated_periods += 1
        return JunctionOutput(current, cut)


# ---------------------------------------------------------------- the display's loop
#: The share of the driver's current the smoothed target may use; the rest
#: is the PI's, to correct what the model misses.
HEADROOM = 0.8

@dataclass(frozen=True, slots=True)
class DisplayJunctionStep:
    current_a: float           # what the driver is asked for (inside every limit)
    saturated: bool            # a limit (slew, Imax, supply) cut the request
    requested_a: float         # the controller's request before any limit
    #: The junction the controller expects over the coming period: the
    #: smoothed target corrected by what the sensor reads against what it
    #: would read on that target (what the display's models advance with).
    estimate_c: float


@dataclass
class LimitCounts:
    """Where the display's limits bind, counted on the controller's request
    before any clamp (the driver's clamp would make them 0 by construction)."""

    periods: int = 0
    requested_over_imax_periods: int = 0
    largest_request_a: float = 0.0
    #: ``|S (Th - Tc) + I R|`` of the request over the driver's supply / the module's Vmax.
    voltage_over_supply_periods: int = 0
    voltage_over_vmax_periods: int = 0
    largest_request_v: float = 0.0
    slew_limited_periods: int = 0
    saturated_periods: int = 0


class DisplayJunctionLoop:
    """The display's junction loop, designed for its bonded sensor
    (:mod:`telethermal.control.junction_design`): a target smoothed over
    ``reference_tau_s``; the feed-forward current that holds the smoothed
    target under the load and moves the modelled heat capacity at its rate;
    a PI on the sensor's reading against the sensor model's reading of the
    smoothed target (anti-windup: it integrates only while the output is
    free or the error takes it back inside); the current's slew bounded at
    ``slew_a_s``; then the H-bridge's limits. Every constant comes from the
    configuration it is given (module parameters, design model).
    One :meth:`update` per period; pure (no device, no clock).
    """

    #: The sensor disagreeing with what its model expects by more than this
    #: for longer than ``IMPLAUSIBLE_S``: the loop stops (0 A, latched until
    #: :meth:`reset`); a debonded sensor lags many times its stated value.
    IMPLAUSIBLE_K = 3.0
    IMPLAUSIBLE_S = 0.5
    #: A stopped loop re-arms (:meth:`rearm_if_settled`, called by its owner
    #: only while nothing touches the pad) once the sensor agrees with the
    #: stopped module's model, the junction only conducting to its hot side
    #: (0 A, no load: it settles at the hot side), within ``REARM_K`` for
    #: ``REARM_S`` on end, and then follows the module: a small warming
    #: current for a second moves its reading as the module's model says
    #: (:mod:`telethermal.control.junction_probe`; a debonded sensor reads
    #: the air, which agrees with the settled module as well). A sensor that
    #: does not follow is refused, with the reason (:attr:`rearm_refused`),
    #: and probed again after the module settles once more.
    REARM_K = 1.0
    REARM_S = 1.0

    def __init__(self, params: ModuleParams, driver: HBridge, model, gains: JunctionGains,
                 reference_tau_s: float = 0.02, slew_a_s: float = 100.0):
        if not (reference_tau_s > 0 and slew_a_s > 0):
            raise ControlError(f"reference_tau_s and slew_a_s must be > 0, got "
                               f"{reference_tau_s}, {slew_a_s}")
        self.params, self.driver, self.model, self.gains = params, driver, model, gains
        self.reference_tau_s, self.slew_a_s = reference_tau_s, slew_a_s
        self.limits = LimitCounts()
        self.rearms = 0                            # re-armed by rearm_if_settled
        self.rearm_refusals = 0                    # probes whose sensor did not follow
        self.rearm_refused = ""                    # the last refusal's reason
        #: Latched by an implausible sensor (not by reset(): rearm() clears it).
        self.stopped = False
        self.reset()

    def rearm(self) -> None:
        """Clear a stop (the sensor has been checked) and start afresh."""
        self.stopped = False
        self.reset()

    def rearm_if_settled(self, sensed_c: float, hot_c: float, dt_s: float) -> bool:
        """While stopped, with nothing on the pad, after this period's
        :meth:`update`: once the junction sensor has read within ``REARM_K``
        of the hot side (what the stopped module settles at) for
        ``REARM_S``, probe whether it follows the module (the next periods'
        :meth:`update` drive the probe's current); re-arm if it does. True
        when it re-armed now. A period without this call ends a probe."""
        if not self.stopped:
            return False
        if self.probe is not None:
            return self._probe_step(sensed_c, hot_c, dt_s)
        agrees = math.isfinite(sensed_c) and math.isfinite(hot_c) and \
            abs(sensed_c - hot_c) <= self.REARM_K
        if not agrees:
            self.agree_s, self._settle = 0.0, [math.nan, 0.0, 0]
            return False
        last, d2, n = self._settle
        self._settle = [sensed_c, d2 + (0.0 if math.isnan(last) else (sensed_c - last) ** 2),
                        n + (0 if math.isnan(last) else 1)]
        self.agree_s += dt_s
        if self.agree_s >= self.REARM_S:
            scatter_k = math.sqrt(self._settle[1] / max(self._settle[2], 1) / 2.0)
            self.probe = JunctionProbe(self.params, self.driver, self.model.heat_j_k,
                                       self.model.sensor_tau_s, sensed_c, hot_c, scatter_k)
            self._probe_pending, self._probe_prev_a = True, 0.0
        return False

    def cancel_probe(self) -> None:
        """No probe current from the next :meth:`update` on (a finger came
        down: nothing but the loop's own command under it)."""
        self.probe, self._probe_pending = None, False

    def _probe_step(self, sensed_c: float, hot_c: float, dt_s: float) -> bool:
        """One period of the probe: its verdict at the end; re-armed or refused."""
        if self._probe_pending or not (math.isfinite(sensed_c) and math.isfinite(hot_c)):
            self.probe, self._probe_pending = None, False      # not driven, or no reading
            self.agree_s, self._settle = 0.0, [math.nan, 0.0, 0]
            return False
        verdict = self.probe.observe(sensed_c, hot_c, self._probe_prev_a, dt_s)
        self._probe_prev_a = self.current_a
        if verdict is None:
            self._probe_pending = True
            return False
        self.probe = None
        if verdict.follows:
            self.rearm()
            self.rearms += 1
            return True
        self._refuse(verdict)
        return False

    def _refuse(self, verdict: ProbeVerdict) -> None:
        """The sensor did not follow: stay stopped, say why (once per stop)."""
        self.rearm_refusals += 1
        self.rearm_refused = verdict.reason
        self.agree_s, self._settle = 0.0, [math.nan, 0.0, 0]
        log.log(logging.DEBUG if self._refusal_logged else logging.WARNING,
                "module kept stopped, not re-armed: %s", verdict.reason)
        self._refusal_logged = True

    def _judge(self, dt_s: float, implausible: bool) -> bool:
        """Time the sensor's disagreement; True once the loop is stopped."""
        self.implausible_s = self.implausible_s + dt_s if implausible else 0.0
        self.stopped = self.stopped or self.implausible_s > self.IMPLAUSIBLE_S
        return self.stopped

    def _coast(self, dt_s: float, hot_c: float, load_w: float) -> None:
        """A period the loop cannot run: its model follows the junction as
        the model says it moves at 0 A (conducting to the hot side, last
        read if not now, under the load if known), and the sensor's model
        follows that; a bonded sensor agrees with it when readings return."""
        hot_c = hot_c if math.isfinite(hot_c) else self.hot_c
        if self.reference_c is None or not math.isfinite(hot_c):
            return
        qc_w = float(self.params.heat_w(0.0, self.reference_c, hot_c)[0])
        load_w = load_w if math.isfinite(load_w) else 0.0
        self.reference_c += dt_s * (load_w - qc_w) / self.model.heat_j_k
        tau = self.model.sensor_tau_s
        self.sensor_model_c += (1.0 if tau <= 0 else -math.expm1(-dt_s / tau)) * \
            (self.reference_c - self.sensor_model_c)

    def _unrun(self, dt_s: float, implausible: bool | None,
               probe: bool = False) -> DisplayJunctionStep:
        """A period the loop does not run (a value missing, or stopped): 0 A,
        the PI emptied; ``implausible`` (None: already judged) goes to the
        sensor's check, which only a plausible reading clears. ``probe``
        (stopped, readings whole): the re-arm probe's current if one is
        asked for this period (inside the slew limit); else a probe ends."""
        if implausible is not None:
            self._judge(dt_s, implausible)
        current = 0.0
        if self.probe is not None and probe and self._probe_pending and self.stopped:
            step = self.slew_a_s * dt_s
            current = min(max(self.probe.current_a, self.current_a - step), self.current_a + step)
        elif self.probe is not None:
            self.probe = None                      # its owner stopped asking (a touch)
        self._probe_pending = False
        self.current_a, self.integral_a = current, 0.0
        return DisplayJunctionStep(current, self.stopped, current, math.nan)

    @property
    def saturated_periods(self) -> int:
        return self.limits.saturated_periods

    def reset(self) -> None:
        """Forget the loop's state (not its counts): the next update starts afresh."""
        self.integral_a = 0.0
        self.implausible_s = 0.0                   # how long the sensor has disagreed
        self.agree_s = 0.0                         # stopped: how long it has agreed
        self.reference_c: float | None = None      # the smoothed target
        self.sensor_model_c = math.nan             # what the sensor would read on it
        self.current_a = 0.0                       # the last current asked for
        #: Stopped: the re-arm probe, whether the next update drives it, the
        #: current that acted before this period's reading, and the settled
        #: readings' [last, sum of squared steps, steps] for their scatter.
        self.probe: JunctionProbe | None = None
        self._probe_pending, self._probe_prev_a = False, 0.0
        self._settle = [math.nan, 0.0, 0]
        self._refusal_logged = False
        self.hot_c = math.nan                      # the hot side's last reading

    def _count(self, requested_a: float, sensed_c: float, hot_c: float) -> None:
        lim, spec = self.limits, self.params.spec
        volts = abs(float(self.params.voltage_v(requested_a, sensed_c, hot_c)))
        lim.periods += 1
        lim.requested_over_imax_periods += int(abs(requested_a) > spec.imax_a)
        lim.largest_request_a = max(lim.largest_request_a, abs(requested_a))
        lim.voltage_over_supply_periods += int(volts > self.driver.supply_v)
        lim.voltage_over_vmax_periods += int(volts > spec.vmax_v)
        lim.largest_request_v = max(lim.largest_request_v, volts)

    def _feasible_rates_k_s(self, junction_c: float, hot_c: float, load_w: float):
        """(fastest cooling, fastest heating) of the junction, K/s, with
        ``HEADROOM`` of the current the driver can force: the smoothed
        target moves no faster, so the feed-forward stays inside the limits
        and the PI keeps the rest (a target the module cannot follow would
        leave the lagging sensor to stop the junction: overshoot)."""
        p, d = self.params, self.driver
        emf = p.seebeck_v_k * (hot_c - junction_c)
        cool = HEADROOM * min(d.current_limit_a, (d.supply_v - emf) / p.resistance_ohm)
        heat = HEADROOM * min(d.current_limit_a, (d.supply_v + emf) / p.resistance_ohm)
        qc_cool, _, _ = p.heat_w(max(cool, 0.0), junction_c, hot_c)
        qc_heat, _, _ = p.heat_w(-max(heat, 0.0), junction_c, hot_c)
        c = self.model.heat_j_k
        return min((load_w - float(qc_cool)) / c, 0.0), max((load_w - float(qc_heat)) / c, 0.0)

    def update(self, target_c: float, sensed_c: float, hot_c: float, dt_s: float,
               load_w: float = 0.0) -> DisplayJunctionStep:
        """This period's current. ``sensed_c``: the junction sensor's reading;
        ``hot_c``: the hot side's (the heat sink's thermistor); ``load_w``:
        heat into the junction from the pad as far as the caller knows it.
        A value that is not finite gives 0 A for the period and no fresh
        start (which would take the next reading, however implausible, as
        its reference): the loop's model coasts (:meth:`_coast`), a missing
        junction reading goes on timing a disagreement already begun, and
        with another value missing the reading is still held against the
        model; so a sensor alternating nan with an implausible value stops
        the loop ``IMPLAUSIBLE_S`` after its first implausible reading."""
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ControlError(f"junction loop needs a positive period, got {dt_s}")
        if not all(math.isfinite(v) for v in (target_c, sensed_c, hot_c, load_w)):
            self._coast(dt_s, hot_c, load_w)
            begun = self.implausible_s > 0
            return self._unrun(dt_s, begun if not math.isfinite(sensed_c) else
                               self.reference_c is not None and
                               abs(sensed_c - self.sensor_model_c) > self.IMPLAUSIBLE_K)
        self.hot_c = hot_c
        if self.reference_c is None:
            self.reference_c, self.sensor_model_c = sensed_c, sensed_c
        previous = self.reference_c
        rate_k_s = -math.expm1(-dt_s / self.reference_tau_s) * (target_c - previous) / dt_s
        lo, hi = self._feasible_rates_k_s(previous, hot_c, load_w)
        rate_k_s = min(max(rate_k_s, lo), hi)
        self.reference_c = previous + rate_k_s * dt_s
        tau = self.model.sensor_tau_s
        self.sensor_model_c += (1.0 if tau <= 0 else -math.expm1(-dt_s / tau)) * \
            (self.reference_c - self.sensor_model_c)
        error = sensed_c - self.sensor_model_c          # positive: warmer than meant, cool
        if self._judge(dt_s, abs(error) > self.IMPLAUSIBLE_K):
            return self._unrun(dt_s, None, probe=True)
        ff = hold_current_a(self.params, self.reference_c, hot_c,
                            load_w - self.model.heat_j_k * rate_k_s)
        requested = ff + self.gains.kp_a_k * error + self.integral_a
        self._count(requested, sensed_c, hot_c)
        step = self.slew_a_s * dt_s
        slewed = min(max(requested, self.current_a - step), self.current_a + step)
        current, cut = self.driver.limit(self.params, slewed, sensed_c, hot_c)
        cut = cut or slewed != requested
        self.limits.slew_limited_periods += int(slewed != requested)
        self.limits.saturated_periods += int(cut)
        if not cut or (requested > current) != (error > 0):
            self.integral_a += self.gains.ki_a_ks * error * dt_s
        self.current_a = current
        return DisplayJunctionStep(current, cut, requested, self.reference_c + error)
