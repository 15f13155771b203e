"""The master: the operator's finger on a Peltier display pad, a heat-flux
PID loop, force-based contact detection and the safety supervisor.

One :meth:`MasterDisplay.step` per control period. It is given the time,
the period actually elapsed, what its own sensors read and what the slave
has said so far (object temperature, material estimate); it returns the
Peltier junction temperature the supervisor let through. It never touches a
device or a clock, so the same object runs in the in-process session, in the
master service and under test.

Phases of a touch:

``idle``
    No contact. The junction is held at the standby temperature: the
    object's temperature as the slave measured it (so the pad's own contact
    carries the first instants with the right sign and a plausible size,
    as in learning-based-thermal-rendering Fig. 3), or neutral while it is
    unknown.
``contact``
    Touching, the slave not yet decided. ``before="hold"``: keep the
    junction at standby (the paper's choice). ``before="prior"``: track the
    flux of the scene's materials weighted by the slave's streaming
    posteriors.
``render``
    The slave has committed to a material: track the generator's flux for
    it, timed from the master's own contact onset.
``link lost``
    During a contact, the link is down and nothing held is valid any more
    (``SlaveNews.link_ok``): the pad goes to neutral at the slew limit, and
    back to ``contact``/``render`` when the link returns.

The controller: the flux setpoint is what the pad's sensor should read (the
generator was trained on sensor readings, so both carry the same lag). The
feed-forward inverts the sensor lag (``q + tau dq/dt``) and the pad's layers
(``T_junction = T_pad_surface + q R_pad``); the PID on the measured flux
removes what the model misses (the operator's own skin, contact, drift).
That is the ``"static"`` controller; the default, ``"impedance"``
(:mod:`telethermal.control.feedforward`), renders the object instead: the
pad's surface is steered to the object's surface temperature under the
measured flux, and the flux PID is not used.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace


from telethermal.control.contact import ContactDetector
from telethermal.control.feedforward import ImpedanceController
from telethermal.control.pid import Pid, PidGains
from telethermal.control.safety import (Reading, Request, SafetyLimits, initial_state,
                                        supervise)
from telethermal.errors import ControlError, UnknownMaterialError
from telethermal.ident.anytime import UNKNOWN, Estimate
from telethermal.physics.materials import get_material
from telethermal.render.generator import mixture, posterior_weights
from telethermal.devices.readings import PadSensors

log = logging.getLogger(__name__)

BEFORE_MODES = ("hold", "prior")
#: "trajectory": render the slave's curves from the master's own onset (the
#: compensated path); "setpoints": track the latest flux setpoint streamed
#: by the slave sample by sample (the naive baseline of the fault benchmark).
SOURCES = ("trajectory", "setpoints")
FEEDFORWARD_MODELS = ("static", "impedance")

#: PID gains of the flux loop: K of junction per W/m^2 of flux error. Chosen
#: by ``telethermal bench render`` (bench/results/render.json): the lowest
#: mean flux error with the pad model right and with it 30 % off (ki 3e-3:
#: 0.61 / 0.65 %; 1e-2: 0.69 / 0.70 %). A smaller integral gain rings less
#: after a late hand-over (tracking that starts after a long hold, as under
#: network delay); ten times it oscillates through the flux sensor's 0.15 s
#: lag. The derivative term bought nothing measurable, so it is off.
DEFAULT_GAINS = PidGains(kp=1e-3, ki=3e-3, kd=0.0, derivative_filter_s=0.01,
                         output_min=-25.0, output_max=25.0)


@dataclass(frozen=True)
class DisplayConfig:
    rate_hz: float = 1000.0
    gains: PidGains = DEFAULT_GAINS
    feedforward: bool = True
    #: "impedance": the pad's surface made to behave as the rendered object's
    #: (control/feedforward.py; needs the pad's layers, else "static");
    #: "static": ``T_pad + q R_pad`` plus the flux PID on the generator's flux.
    feedforward_model: str = "impedance"
    #: The impedance controller's prediction horizon.
    impedance_horizon_s: float = 0.1
    before: str = "prior"
    source: str = "trajectory"
    #: The controller's own slew limit on the junction command; the
    #: supervisor's rate limit above it is the independent backstop.
    slew_k_s: float = 100.0
    #: After a hand-over (hold -> render), the step between what was applied
    #: and what the controller asks for is closed at this slope.
    handover_k_s: float = 50.0
    #: From the posterior mixture to the decided material: weights blended over this long.
    blend_s: float = 0.1
    limits: SafetyLimits = field(default_factory=lambda: SafetyLimits(
        max_rate_k_s=200.0, max_flux_w_m2=20_000.0))
    #: For robustness studies: the controller's pad resistance relative to
    #: the true one (1: the model is right).
    r_pad_belief: float = 1.0
    contact_on_n: float = 2.0
    contact_off_n: float = 1.0
    debounce_s: float = 0.02

    def __post_init__(self):
        if not (self.rate_hz > 0 and math.isfinite(self.rate_hz)):
            raise ControlError(f"display rate_hz must be > 0, got {self.rate_hz}")
        if not (self.slew_k_s > 0 and self.handover_k_s > 0 and self.blend_s > 0):
            raise ControlError("slew_k_s, handover_k_s and blend_s must be > 0")
        if self.source not in SOURCES:
            raise ControlError(f"source must be one of {SOURCES}, got {self.source!r}")
        if self.feedforward_model not in FEEDFORWARD_MODELS:
            raise ControlError(f"feedforward_model must be one of {FEEDFORWARD_MODELS}, "
                               f"got {self.feedforward_model!r}")
        if not self.impedance_horizon_s > 0:
            raise ControlError("impedance_horizon_s must be > 0, got "
                               f"{self.impedance_horizon_s}")
        if self.before not in BEFORE_MODES:
            raise ControlError(f"before must be one of {BEFORE_MODES}, got {self.before!r}")


@dataclass(frozen=True, slots=True)
class SlaveNews:
    """What the master knows from the slave at this instant."""

    object_temp_c: float | None = None
    estimate: Estimate | None = None
    classes: tuple[str, ...] = ()
    setpoint_w_m2: float | None = None       # latest streamed setpoint (naive path)
    #: False when the link is down and nothing the master holds is valid any
    #: more: the display decays to its safe state (neutral) at its slew limit
    #: and resumes, bumplessly, when this is True again.
    link_ok: bool = True


@dataclass(frozen=True, slots=True)
class MasterStep:
    t_s: float
    phase: str
    touching: bool
    desired_flux_w_m2: float        # what the loop tracks (nan when holding)
    junction_cmd_c: float           # the controller's request
    junction_applied_c: float       # what the supervisor let through
    safe: bool


class MasterDisplay:
    """The display's control logic, one period per :meth:`step`."""

    def __init__(self, config: DisplayConfig, generator, pad_resistance_m2k_w: float,
                 sensor_lag_s: float, finger_temp_c: float, idle_c: float | None = None,
                 pad_layers=None, contact_conductance_w_m2k: float | None = None):
        self.config = config
        self.generator = generator
        self.r_pad = pad_resistance_m2k_w * config.r_pad_belief
        self.tau = sensor_lag_s
        self.finger_c = finger_temp_c           # measured before contact
        self.dt_nominal = 1.0 / config.rate_hz
        self.pid = Pid(config.gains, self.dt_nominal)
        self.detector = ContactDetector(config.contact_on_n, config.contact_off_n,
                                        config.debounce_s)
        # Start in the safe state (neutral), or, when told the pad has been
        # idling at ``idle_c`` already, from there.
        self.safety = initial_state(config.limits) if idle_c is None else \
            replace(initial_state(config.limits), applied_temp_c=idle_c, safe=False)
        self._command_c = self.safety.applied_temp_c
        self._offset = 0.0
        self._held = False      # the pad was held (not tracking) during this contact
        self._band_limited = False
        self._blend = None
        self.events: dict[str, int] = {}
        self.onset_s: float | None = None          # of the contact going on
        self.last_onset_s: float | None = None
        self.last_release_s: float | None = None
        self.phase = "idle"
        self.rendering: str | None = None       # material being rendered
        self.rendered_from_s: float | None = None
        self._pid_running = False
        # The impedance controller, when the pad's layers are known.
        self.impedance = ImpedanceController(pad_layers, contact_conductance_w_m2k,
                                             sensor_lag_s, self.dt_nominal,
                                             config.impedance_horizon_s) \
            if (config.feedforward and config.feedforward_model != "static" and pad_layers
                and contact_conductance_w_m2k) else None

    # ------------------------------------------------------------ pieces
    @staticmethod
    def standby_c_for(limits: SafetyLimits, object_temp_c: float | None) -> float:
        """The object's temperature inside the skin band; neutral if unknown."""
        if object_temp_c is None or not math.isfinite(object_temp_c):
            return limits.neutral_c
        return min(max(object_temp_c, limits.skin_min_c), limits.skin_max_c)

    def standby_c(self, news: SlaveNews) -> float:
        return self.standby_c_for(self.config.limits, news.object_temp_c)

    def _mixture_weights(self, news: SlaveNews) -> dict[str, float]:
        return posterior_weights(news.classes, news.estimate.posteriors if news.estimate
                                 else None, self.generator.materials)

    def _desired(self, t_s: float, t_contact: float, news: SlaveNews, gap: float):
        """(flux setpoint, flux for the feed-forward) at time since onset."""
        if self.rendering is not None:
            weights = {self.rendering: 1.0}
            if self._blend is not None:
                # Hand-over from the posterior mixture to the decided material:
                # a linear blend of the weights over blend_s, no setpoint step.
                t_switch, before = self._blend
                a = min(1.0, (t_s - t_switch) / self.config.blend_s)
                weights = {n: (1 - a) * before.get(n, 0.0) + a * weights.get(n, 0.0)
                           for n in sorted(set(before) | set(weights))}
                if a >= 1.0:
                    self._blend = None
        else:
            weights = self._mixture_weights(news)
            self._last_weights = weights
        names = list(weights)
        g, dg = mixture(self.generator, names, [weights[n] for n in names], t_contact)
        q = g * gap
        return q, q + self.tau * dg * gap

    def _inverse_effusivity(self, news: SlaveNews) -> float | None:
        """1/e of what is rendered: the decided material's, or the posteriors'
        mean; None when a material is not in the materials table."""
        weights = {self.rendering: 1.0} if self.rendering is not None else \
            self._mixture_weights(news)
        try:
            return sum(w / get_material(n).effusivity for n, w in weights.items())
        except UnknownMaterialError:
            return None

    # ------------------------------------------------------------ the period
    def step(self, t_s: float, dt_s: float, sensors: PadSensors, news: SlaveNews) -> MasterStep:
        cfg, lim = self.config, self.config.limits
        event = None
        if self.impedance is not None:
            self.impedance.observe(sensors.flux_w_m2, dt_s)
        if math.isfinite(sensors.force_n):
            event = self.detector.update(t_s, sensors.force_n)
        if event is not None and event.touching:
            self._held = False
            self.onset_s, self.phase, self.rendering = event.t_s, "contact", None
            self.last_onset_s, self.rendered_from_s = event.t_s, None
            self._pid_running = False
            if self.impedance is not None:
                applied = self.safety.applied_temp_c
                self.impedance.start(applied, self.finger_c, t_s - event.t_s, applied)
        elif event is not None:
            self.onset_s, self.phase, self.rendering = None, "idle", None
            self.last_release_s = event.t_s
            self._pid_running = False
            if self.impedance is not None:
                self.impedance.reset()

        est = news.estimate
        naive = cfg.source == "setpoints"
        if not naive and self.phase == "contact" and est is not None and est.decided and \
                est.label != UNKNOWN and self.generator is not None and \
                est.label in self.generator.materials:
            self.phase, self.rendering, self.rendered_from_s = "render", est.label, t_s
            last = getattr(self, "_last_weights", None)
            self._blend = (t_s, last) if self._pid_running and last else None
        elif not naive and self.phase == "render" and est is not None and est.decided and \
                est.label not in (UNKNOWN, self.rendering) and est.label in self.generator.materials:
            # The slave changed its mind: blend to the new material, no step.
            log.info("rendering changes from %s to %s at t=%.3f s", self.rendering, est.label, t_s)
            self.events["decision changed"] = self.events.get("decision changed", 0) + 1
            self._blend = (t_s, {self.rendering: 1.0})
            self.rendering = est.label

        if self.phase in ("contact", "render") and not news.link_ok:
            self._lost_from = self.phase
            self.phase = "link lost"
            self.events["link lost"] = self.events.get("link lost", 0) + 1
            log.warning("link lost mid-contact at t=%.3f s: display to neutral", t_s)
        elif self.phase == "link lost" and news.link_ok:
            self.phase = self._lost_from
            log.info("link back at t=%.3f s: rendering resumes", t_s)

        standby = self.standby_c(news)
        desired = math.nan
        command = lim.neutral_c if self.phase == "link lost" else standby
        obj_c = news.object_temp_c
        if naive:
            tracking = self.phase == "contact" and news.setpoint_w_m2 is not None
        else:
            # The prior starts with the slave's first posterior: until then the
            # pad's own contact carries the touch (a uniform prior over the
            # scene measured worse than holding when posteriors come late).
            tracking = self.phase == "render" or (self.phase == "contact" and
                                                  cfg.before == "prior" and news.classes and
                                                  self.generator is not None and
                                                  news.estimate is not None)
        readings_ok = math.isfinite(sensors.flux_w_m2) and math.isfinite(sensors.pad_temp_c)
        if self.phase != "idle" and not (tracking and readings_ok):
            self._held = True
        if tracking and not readings_ok:
            # The supervisor puts the pad in its safe state this very period;
            # the controller stands still and restarts bumplessly afterwards.
            self._pid_running = False
        elif tracking and obj_c is not None and math.isfinite(obj_c):
            gap = obj_c - self.finger_c        # display flux = g(t) (T_object - T_finger)
            t_contact = max(t_s - self.onset_s, 0.0)
            if naive:
                desired = ff_flux = float(news.setpoint_w_m2)
            else:
                desired, ff_flux = self._desired(t_s, t_contact, news, gap)
            measured = sensors.flux_w_m2
            inverse_e = self._inverse_effusivity(news) if self.impedance is not None and \
                self.impedance.running and not naive else None
            if inverse_e is not None:
                # The pad's surface behaves as the object's would; the loop is
                # closed on the measured flux and surface inside the controller.
                ff = self.impedance.command_impedance(sensors.pad_temp_c, obj_c,
                                                      inverse_e) - standby
                desired_for_pid = measured
            else:
                ff = (sensors.pad_temp_c + ff_flux * self.r_pad - standby) \
                    if cfg.feedforward else 0.0
                desired_for_pid = desired
            if not self._pid_running:
                # Saturate where the junction would leave the skin band, so the
                # integral does not wind up against the supervisor.
                g = cfg.gains
                self.pid.gains = replace(g, output_min=max(g.output_min, lim.skin_min_c - standby),
                                         output_max=min(g.output_max, lim.skin_max_c - standby))
                self.pid.reset(sensors.flux_w_m2)
            out = self.pid.update(desired_for_pid, measured, dt_s, feedforward=ff)
            command = standby + out.output
            if out.saturated and not self._band_limited:
                # The flux asked for would take the pad past the skin band:
                # the controller stops at the band; counted and logged.
                self.events["rendering limited by the skin band"] = \
                    self.events.get("rendering limited by the skin band", 0) + 1
                log.info("rendering limited by the skin band at t=%.3f s (junction %.1f C)",
                         t_s, command)
            self._band_limited = out.saturated
            if not self._pid_running:
                # Hand-over from holding (or from the safe state) during a
                # contact: start from what is applied and close the step at a
                # bounded slope (no jump, no offset left in the integral). At
                # the start of a contact the pad should move at once: no offset.
                self._offset = self.safety.applied_temp_c - command if self._held else 0.0
                self._pid_running = True
            step = cfg.handover_k_s * dt_s
            self._offset -= min(max(self._offset, -step), step)
            command += self._offset

        # The controller's own slew limit (the supervisor's is looser).
        step = cfg.slew_k_s * min(dt_s, 2 * self.dt_nominal)   # a stall buys no bigger jump
        wanted = command
        command = min(max(command, self._command_c - step), self._command_c + step)
        self._command_c = command
        request = Request(command, 0.0 if math.isnan(desired) else desired, t_s)
        reading = Reading(t_s, sensors.pad_temp_c, sensors.flux_w_m2)
        applied, self.safety = supervise(self.safety, reading, request, lim, dt_s)
        if self.impedance is not None:
            self.impedance.advance(applied.temp_c, dt_s)
        if self._pid_running:
            self.pid.limited_downstream(wanted, applied.temp_c)
        return MasterStep(t_s, self.phase, self.detector.touching, desired, command,
                          applied.temp_c, applied.safe)
