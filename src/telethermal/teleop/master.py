"""The master: the operator's finger on a Peltier display pad, a heat-flux
PID loop, force-based contact detection and the safety supervisor.

One :meth:`MasterDisplay.step` per control period: given the time, the
period elapsed, its own sensors' readings and the slave's news, it returns
what the supervisor let through and the contact event of the period. It
never touches a device or a clock (in-process, in the service, under test).

Phases of a touch (:class:`Phase`, a ``str`` enum: the names below are its
values, which recordings, the view stream and the status hold):

``idle``
    No contact. The pad is held at the standby temperature: the object's as
    the slave measured it (neutral while unknown), shifted by the idle
    policy (``DisplayConfig.idle``): pre-conditioned for the material the
    slave expects, else the minimax idle for an unknown object.
``contact``
    Touching, the slave not yet decided. ``before="hold"``: keep the
    junction at standby (the paper's choice). ``before="prior"``: track the
    flux of the scene's materials weighted by the slave's streaming
    posteriors.
``render``
    The slave has committed to a material: track the generator's flux for
    it, timed from the master's own contact onset; or to a new material:
    render its effusivity estimate (:mod:`telethermal.teleop.rendering`).
``link lost``
    During a contact, the link is down and nothing held is valid any more
    (``SlaveNews.link_ok``): the pad goes to neutral at the slew limit, and
    back to ``contact``/``render`` when the link returns.

The controller: the flux setpoint is what the pad's sensor should read (the
generator was trained on sensor readings). The ``"static"`` feed-forward
inverts the sensor lag (``q + sensor_lag_s dq/dt``) and the pad's layers
(``T_junction = T_pad_surface + q R_pad``); a PID on the measured flux removes
what the model misses. The default, ``"impedance"`` (control/feedforward.py),
renders the object instead: the pad's surface is steered to the object's
surface temperature under the measured flux, and the flux PID is not used.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from enum import StrEnum

from telethermal.control.contact import ContactChange, ContactDetector
from telethermal.control.junction_design import design_display_loop
from telethermal.control.feedforward import ImpedanceController
from telethermal.control.pid import Pid
from telethermal.control.safety import (Reading, Request, SafetyLimits, initial_state,
                                        supervise, surface_barrier)
from telethermal.errors import ControlError
from telethermal.ident.anytime import Estimate
from telethermal.physics.thermoelectric import (DEFAULT_JUNCTION_SENSOR, JunctionSensorSpec,
                                                ModuleParams, get_junction_sensor)
from telethermal.render.generator import posterior_weights
from telethermal.devices.readings import PadSensors
from telethermal.teleop.display_config import (JUNCTION_REARMED, JUNCTION_STOPPED, Before,
                                               DisplayConfig, FeedforwardModel, Source)
from telethermal.teleop.rendering import (Estimated, Handover, blended, estimated_target,
                                          generator_flux, has_estimate, inverse_effusivity)

log = logging.getLogger(__name__)


class Phase(StrEnum):
    """The display's phase (see the module's docstring). A ``str``: its
    value is what recordings, the view's state and the status hold."""

    IDLE = "idle"
    CONTACT = "contact"
    RENDER = "render"
    LINK_LOST = "link lost"


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
    #: The material or pair the slave expects this object to be (its object
    #: memory): the display pre-conditions its pad for it (a pair: the pair's
    #: minimax idle); None: unknown, the idle policy's choice.
    expected_material: str | None = None
    #: The curves to render (the slave's, anew when it restarts); None: its own.
    generator: object | None = None


@dataclass(frozen=True, slots=True)
class MasterStep:
    t_s: float
    phase: str                      # a Phase; its value is what recordings hold
    touching: bool
    desired_flux_w_m2: float        # what the loop tracks (nan when holding)
    junction_cmd_c: float           # the controller's request
    junction_applied_c: float       # what the supervisor let through
    safe: bool
    #: The module's current the junction loop asks for (inside the driver's
    #: limits); 0 when the display has no module model or no junction reading.
    current_a: float = 0.0
    #: The contact detector's news this period: a touch began or ended
    #: (its ``t_s`` the onset or release instant), else None.
    contact: ContactChange | None = None


class MasterDisplay:
    """The display's control logic, one period per :meth:`step`."""

    def __init__(self, config: DisplayConfig, generator, pad_resistance_m2k_w: float,
                 sensor_lag_s: float, finger_temp_c: float, idle_c: float | None = None,
                 pad_layers=None, contact_conductance_w_m2k: float | None = None,
                 module: ModuleParams | None = None, precondition=None, pad_area_m2=None,
                 junction_sensor: JunctionSensorSpec | None = None,
                 dew_floor_c: float | None = None, flux_gain: float = 1.0,
                 impedance_horizon_scale: float = 1.0):
        self.config = config
        self.generator = generator
        self.nominal_dt_s = 1.0 / config.rate_hz
        #: The lowest standby: the room's dew point plus its margin (control/dew.py).
        self.dew_floor_c = -math.inf if dew_floor_c is None else dew_floor_c
        self._lifted = False            # the last standby was lifted to the dew floor
        # The face the module pumps over: the scene's size_mm, or the module's.
        self._module_area_m2 = 0.0 if module is None else (pad_area_m2 or module.spec.area_m2)
        #: The junction sensor as the configuration states it (its lag is what
        #: the junction loop is designed for).
        self.junction_sensor = junction_sensor or get_junction_sensor(DEFAULT_JUNCTION_SENSOR)
        #: The pad's layers as the controllers model them (a recording keeps them).
        self.pad_layers = tuple(pad_layers or ())
        #: junction target -> module current (control/junction.py); None: no module model.
        self.junction_loop = self._junction_loop(module, pad_layers or ()) if module else None
        #: When (session clock, s) the junction loop first stopped on an
        #: implausible sensor; None: it has not.
        self.junction_stopped_at_s: float | None = None
        self._junction_stop_counted = False     # this stop counted and logged
        #: One re-arm per idle: set again by the next touch.
        self._junction_rearm_allowed = True
        #: ``precondition(material or None, object_temp_c) -> idle offset, K``:
        #: where the pad idles relative to the object before (and, holding,
        #: during) a touch (control/preconditioning.py); None: at the object.
        self.precondition = precondition
        self.r_pad_m2k_w = pad_resistance_m2k_w * config.r_pad_belief   # as believed
        self.sensor_lag_s = sensor_lag_s
        #: The flux sensor's gain against its stated sensitivity (a display
        #: calibration's, 1: none): each reading is divided by it.
        if not (flux_gain > 0 and math.isfinite(flux_gain)):
            raise ControlError(f"flux_gain must be a finite number > 0, got {flux_gain}")
        self.flux_gain = flux_gain
        self.finger_temp_c = finger_temp_c           # measured before contact
        self.pid = Pid(config.gains, self.nominal_dt_s)
        self.detector = ContactDetector(config.contact_on_n, config.contact_off_n,
                                        config.debounce_s)
        # Start in the safe state (neutral), or from ``idle_c`` (idling there).
        self.safety = initial_state(config.limits) if idle_c is None else \
            replace(initial_state(config.limits), applied_temp_c=idle_c, safe=False)
        self._command_c = self.safety.applied_temp_c
        self.handover = Handover()
        self._band_limited = False      # the last PID output was saturated
        self.events: dict[str, int] = {}
        self.onset_s: float | None = None          # of the contact going on
        self.last_onset_s: float | None = None
        self.last_release_s: float | None = None
        self.phase = Phase.IDLE
        self.rendering: str | None = None       # material being rendered (its label)
        #: A new material's estimate being rendered (``rendering`` is then
        #: "new material"); None for a known material or none.
        self.rendered_estimate: Estimated | None = None
        self.rendered_from_s: float | None = None
        #: The weights rendered at the last tracked period (the start of a blend).
        self._period_weights: dict | None = None
        # The finger's contact conductance, for a new material's closed form.
        self._conductance_w_m2k = contact_conductance_w_m2k or math.inf
        # The impedance controller needs the pad model (no silent static PID).
        wants_impedance = config.feedforward and config.feedforward_model == FeedforwardModel.IMPEDANCE
        if wants_impedance and not (pad_layers and contact_conductance_w_m2k):
            raise ControlError("the impedance controller (feedforward_model 'impedance', the "
                               "default) needs the display's pad model: pad_layers and "
                               "contact_conductance_w_m2k (the scene's [pad] layers and finger "
                               "contact conductance); give both, or choose 'static'")
        #: The impedance horizon's stretch (teleop/display_setup.horizon_scale).
        self.impedance_horizon_scale = float(impedance_horizon_scale)
        self.impedance = ImpedanceController(pad_layers, contact_conductance_w_m2k,
                                             sensor_lag_s, self.nominal_dt_s,
                                             config.impedance_horizon_s * impedance_horizon_scale,
                                             flux_inverse_s=config.flux_inverse_s,
                                             bias_filter_s=config.impedance_bias_filter_s) \
            if wants_impedance else None

    def _junction_loop(self, module: ModuleParams, pad_layers):
        """The junction loop designed on the configured module, pad and sensor
        (control/junction_design.py); its design kept in :attr:`junction_design`."""
        loop, self.junction_design = design_display_loop(
            module, pad_layers, self._module_area_m2, self.junction_sensor.tau_s,
            self.nominal_dt_s, self.config.junction_reference_s, self.config.current_slew_a_s)
        return loop

    # ------------------------------------------------------------ pieces
    @staticmethod
    def standby_c_for(limits: SafetyLimits, object_temp_c: float | None) -> float:
        """The object's temperature inside the skin band; neutral if unknown."""
        if object_temp_c is None or not math.isfinite(object_temp_c):
            return limits.neutral_c
        return min(max(object_temp_c, limits.skin_min_c), limits.skin_max_c)

    def standby_c(self, news: SlaveNews) -> float:
        """Where the pad idles: the object's temperature, shifted by the idle
        policy for the material expected (or an unknown), in the skin band."""
        obj = news.object_temp_c
        if self.precondition is not None and obj is not None and math.isfinite(obj):
            obj = obj + self.precondition(news.expected_material, obj)
        standby = self.standby_c_for(self.config.limits, obj)
        lifted = standby < self.dew_floor_c
        if lifted and not self._lifted:
            self._count("idle lifted above the dew point")
            log.info("standby lifted from %.2f C to %.2f C (the dew point plus its margin)",
                     standby, self.dew_floor_c)
        self._lifted = lifted
        return max(standby, self.dew_floor_c)

    def _count(self, event: str) -> None:
        self.events[event] = self.events.get(event, 0) + 1

    def _mixture_weights(self, news: SlaveNews) -> dict[str, float]:
        return posterior_weights(news.classes, news.estimate.posteriors if news.estimate
                                 else None, self.generator.materials)

    def _weights(self, t_s: float, news: SlaveNews) -> dict[str, float]:
        """The materials rendered now and their weights."""
        h = self.handover
        if self.rendering is None:
            h.last_weights = self._mixture_weights(news)
            return h.last_weights
        # Hand-over from the posterior mixture to the decided material: a
        # linear blend of the weights over blend_s, no setpoint step.
        return blended(h, t_s, {self._target(): 1.0}, self.config.blend_s)

    def _target(self):
        """The key of what is rendered: the material, or the new one's estimate."""
        return self.rendered_estimate if self.rendered_estimate is not None else self.rendering

    def _desired(self, t_s: float, t_contact_s: float, news: SlaveNews, gap_k: float):
        """(flux setpoint, flux for the feed-forward) at time since onset."""
        self._period_weights = self._weights(t_s, news)
        g, dg = generator_flux(self.generator, self._period_weights, t_contact_s,
                               self._conductance_w_m2k, self.sensor_lag_s)
        q = g * gap_k
        return q, q + self.sensor_lag_s * dg * gap_k

    def _inverse_effusivity(self, news: SlaveNews) -> float | None:
        """1/e of what is rendered: the decided material's, or the posteriors'
        mean; None when a material is not in the materials table."""
        if has_estimate(self._period_weights):      # a new material: the blend's own 1/e
            return inverse_effusivity(self._period_weights)
        weights = {self.rendering: 1.0} if self.rendering is not None else \
            self._mixture_weights(news)
        return inverse_effusivity(weights)

    # ------------------------------------------------------------ the phases
    def _on_contact(self, t_s: float, force_n: float) -> ContactChange | None:
        """The contact detector's news: a touch begins or ends (returned)."""
        if not math.isfinite(force_n):
            return None
        event = self.detector.update(t_s, force_n)
        if event is None:
            return None
        self.handover.pid_running = False
        if event.touching:
            self._junction_rearm_allowed = True      # a new touch: its idle may re-arm
            self.handover.held = False
            self.onset_s, self.phase, self.rendering = event.t_s, Phase.CONTACT, None
            self.rendered_estimate, self._period_weights = None, None
            self.last_onset_s, self.rendered_from_s = event.t_s, None
            if self.impedance is not None:
                applied = self.safety.applied_temp_c
                self.impedance.start(applied, self.finger_temp_c, t_s - event.t_s, applied)
        else:
            self.onset_s, self.phase, self.rendering = None, Phase.IDLE, None
            self.rendered_estimate, self._period_weights = None, None
            self.last_release_s = event.t_s
            if self.impedance is not None:
                self.impedance.reset()
        return event

    def _on_decision(self, t_s: float, est: Estimate | None) -> None:
        """The slave's decision: render it (a known material from its curve, a
        new one from its estimate), or blend to a changed one."""
        if est is None or not est.decided:
            return
        h = self.handover
        estimated = estimated_target(est)
        known = not est.label.is_unknown and self.generator is not None and \
            est.label in self.generator.materials
        if not (known or estimated is not None):
            return
        target = estimated if estimated is not None else est.label
        if self.phase == Phase.CONTACT:
            self.phase, self.rendering, self.rendered_from_s = Phase.RENDER, est.label, t_s
            self.rendered_estimate = estimated
            h.blend = (t_s, h.last_weights) if h.pid_running and h.last_weights else None
        elif self.phase == Phase.RENDER and target != self._target():
            # The slave changed its mind (or its estimate): blend from what
            # was rendered at the last period to the new target, no step.
            log.info("rendering changes from %s to %s at t=%.3f s", self._target(), target, t_s)
            self._count("decision changed" if est.label != self.rendering else
                        "estimate changed")
            h.blend = (t_s, self._period_weights or {self._target(): 1.0})
            self.rendering, self.rendered_estimate = est.label, estimated

    def _on_link(self, t_s: float, link_ok: bool) -> None:
        """The link lost mid-contact (to neutral), or back (rendering resumes)."""
        if self.phase in (Phase.CONTACT, Phase.RENDER) and not link_ok:
            self.handover.lost_from = self.phase
            self.phase = Phase.LINK_LOST
            self._count("link lost")
            log.warning("link lost mid-contact at t=%.3f s: display to neutral", t_s)
        elif self.phase == Phase.LINK_LOST and link_ok:
            self.phase = self.handover.lost_from
            log.info("link back at t=%.3f s: rendering resumes", t_s)

    def _tracking(self, news: SlaveNews, naive: bool) -> bool:
        """Whether the pad tracks a flux this period (else it holds)."""
        if naive:
            return self.phase == Phase.CONTACT and news.setpoint_w_m2 is not None
        # The prior starts with the slave's first posterior: until then the
        # pad's own contact carries the touch (a uniform prior over the
        # scene measured worse than holding when posteriors come late).
        return self.phase == Phase.RENDER or bool(
            self.phase == Phase.CONTACT and self.config.before == Before.PRIOR and news.classes
            and self.generator is not None and news.estimate is not None)

    # ------------------------------------------------------------ tracking
    def _feedforward(self, sensors: PadSensors, news: SlaveNews, standby: float,
                     desired: float, ff_flux: float, naive: bool) -> tuple[float, float]:
        """(feed-forward, what the PID tracks) of the junction, K above standby."""
        inverse_e = self._inverse_effusivity(news) if self.impedance is not None and \
            self.impedance.running and not naive else None
        if inverse_e is not None:
            # The pad's surface behaves as the object's would; the loop is
            # closed on the measured flux and surface inside the controller.
            ff = self.impedance.command_impedance(sensors.pad_temp_c, news.object_temp_c,
                                                  inverse_e) - standby
            return ff, sensors.flux_w_m2
        ff = (sensors.pad_temp_c + ff_flux * self.r_pad_m2k_w - standby) \
            if self.config.feedforward else 0.0
        return ff, desired

    def _pid_output(self, t_s: float, dt_s: float, measured: float, target: float,
                    standby: float, ff: float) -> float:
        """The flux PID's output, K above standby; started bumplessly."""
        if not self.handover.pid_running:
            self.pid.reset(measured)
        out = self.pid.update(target, measured, dt_s, feedforward=ff)
        if out.saturated and not self._band_limited:
            # The junction asked for is past the PID's output range around
            # the standby: the controller stops there; counted and logged.
            self._count("rendering limited by the junction range")
            log.info("rendering limited by the junction range at t=%.3f s (junction %.1f C)",
                     t_s, standby + out.output)
        self._band_limited = out.saturated
        return out.output

    def _handover_offset(self, dt_s: float, command: float) -> float:
        """What is added to the command: at a hand-over from holding (or from
        the safe state) during a contact, start from what is applied and
        close the step at a bounded slope (no jump, no offset left in the
        integral). At the start of a contact the pad moves at once: none."""
        h = self.handover
        if not h.pid_running:
            h.offset_k = self.safety.applied_temp_c - command if h.held else 0.0
            h.pid_running = True
        return h.close_offset(self.safety.applied_temp_c, command, self.config.handover_k_s * dt_s)

    def _track(self, t_s: float, dt_s: float, sensors: PadSensors, news: SlaveNews,
               standby: float, naive: bool) -> tuple[float, float]:
        """(flux setpoint, junction command) while tracking."""
        gap_k = news.object_temp_c - self.finger_temp_c   # display flux = g(t) (T_obj - T_fing)
        t_contact_s = max(t_s - self.onset_s, 0.0)
        if naive:
            desired = ff_flux = float(news.setpoint_w_m2)
        else:
            desired, ff_flux = self._desired(t_s, t_contact_s, news, gap_k)
        ff, target = self._feedforward(sensors, news, standby, desired, ff_flux, naive)
        command = standby + self._pid_output(t_s, dt_s, sensors.flux_w_m2, target, standby, ff)
        command += self._handover_offset(dt_s, command)
        return desired, command

    def _apply(self, t_s: float, dt_s: float, sensors: PadSensors, desired: float,
               command: float, contact: ContactChange | None = None) -> MasterStep:
        """The controller's own slew limit (the supervisor's is looser), then
        the supervisor; what it let through."""
        # A stall buys no bigger jump.
        step = self.config.slew_k_s * min(dt_s, 2 * self.nominal_dt_s)
        wanted = command
        command = min(max(command, self._command_c - step), self._command_c + step)
        if math.isfinite(sensors.pad_temp_c):
            # The surface barrier, kept by the controller itself over its own
            # slew limit (the supervisor's copy of it is the backstop).
            lo, hi = surface_barrier(self.config.limits, sensors.pad_temp_c)
            if not lo <= command <= hi:
                command = min(max(command, lo), hi)
                self._count("rendering limited by the surface band")
        request = Request(command, 0.0 if math.isnan(desired) else desired, t_s)
        reading = Reading(t_s, sensors.pad_temp_c, sensors.flux_w_m2)
        applied, self.safety = supervise(self.safety, reading, request, self.config.limits, dt_s)
        self._command_c = applied.temp_c        # the next slew from what the pad was given
        if self.detector.touching and self.junction_loop is not None:
            self.junction_loop.cancel_probe()       # no re-arm probe current under a finger
        current_a, junction_c = self._current(applied.temp_c, sensors, dt_s)
        if self.junction_loop is not None and self.junction_loop.stopped \
                and self.junction_stopped_at_s is None:
            self.junction_stopped_at_s = t_s
        self._rearm_junction_loop(sensors, dt_s)
        if self.impedance is not None:
            # The model advances with the junction as the loop measures it.
            self.impedance.advance(junction_c if math.isfinite(junction_c) else applied.temp_c,
                                   dt_s)
        if self.handover.pid_running:
            self.pid.limited_downstream(wanted, applied.temp_c)
        return MasterStep(t_s, self.phase, self.detector.touching, desired, command,
                          applied.temp_c, applied.safe, current_a, contact)

    def _current(self, junction_c: float, sensors: PadSensors, dt_s: float
                 ) -> tuple[float, float]:
        """(the module's current that brings the junction to ``junction_c``,
        the junction expected over the period as the loop measures it): the
        inner loop; (0 A, ``junction_c``) without a module model, (0 A, nan)
        without a junction reading. The pad's heat into the junction is
        estimated from the measured flux (what the pad gives the finger, it
        takes from the junction)."""
        if self.junction_loop is None:
            return 0.0, junction_c
        load = -self._module_area_m2 * sensors.flux_w_m2 \
            if math.isfinite(sensors.flux_w_m2) else 0.0
        out = self.junction_loop.update(junction_c, sensors.junction_c, sensors.heatsink_c,
                                        min(dt_s, 2 * self.nominal_dt_s), load)
        if out.saturated:
            self._count("module current limited")
        if self.junction_loop.stopped and not self._junction_stop_counted:
            self._junction_stop_counted = True
            self._count(JUNCTION_STOPPED)
            log.error("the junction sensor disagrees with its model by over %.1f K for %.1f s: "
                      "module current stopped (0 A) until the sensor is checked",
                      self.junction_loop.IMPLAUSIBLE_K, self.junction_loop.IMPLAUSIBLE_S)
        return out.current_a, out.estimate_c

    def _rearm_junction_loop(self, sensors: PadSensors, dt_s: float) -> None:
        """A stopped junction loop re-arms at the next idle with nothing on
        the pad, once its sensor agrees with the stopped module again and
        follows a probe current as the loop's model predicts
        (:meth:`~telethermal.control.junction.DisplayJunctionLoop.rearm_if_settled`);
        counted and logged. At most once per idle: a loop that stops again
        before the next touch stays stopped (no stop/re-arm cycle)."""
        loop = self.junction_loop
        if loop is None or not loop.stopped or self.detector.touching or \
                not self._junction_rearm_allowed:
            return
        if loop.rearm_if_settled(sensors.junction_c, sensors.heatsink_c, dt_s):
            self._junction_rearm_allowed = False
            self._count(JUNCTION_REARMED)
            log.warning("the junction sensor agrees with the idle module again (within %.1f K "
                        "of the hot side for %.1f s) and follows a small probe current as "
                        "its model says: module current re-armed", loop.REARM_K, loop.REARM_S)
            self._junction_stop_counted = False

    # ------------------------------------------------------------ the period
    def step(self, t_s: float, dt_s: float, sensors: PadSensors, news: SlaveNews) -> MasterStep:
        """One control period: the phase from the contact, the slave's
        decision and the link; then track or hold; then the limits."""
        self.generator = news.generator or self.generator
        if self.flux_gain != 1.0:
            sensors = replace(sensors, flux_w_m2=sensors.flux_w_m2 / self.flux_gain)
        if self.impedance is not None:
            self.impedance.observe(sensors.flux_w_m2, dt_s)
        contact = self._on_contact(t_s, sensors.force_n)
        naive = self.config.source == Source.SETPOINTS
        if not naive:
            self._on_decision(t_s, news.estimate)
        self._on_link(t_s, news.link_ok)
        standby = self.standby_c(news)
        desired = math.nan
        command = self.config.limits.neutral_c if self.phase == Phase.LINK_LOST else standby
        tracking = self._tracking(news, naive)
        readings_ok = math.isfinite(sensors.flux_w_m2) and math.isfinite(sensors.pad_temp_c)
        if self.phase != Phase.IDLE and not (tracking and readings_ok):
            self.handover.held = True
        obj_c = news.object_temp_c
        if tracking and not readings_ok:
            # The supervisor puts the pad in its safe state this very period;
            # the controller stands still and restarts bumplessly afterwards.
            self.handover.pid_running = False
        elif tracking and obj_c is not None and math.isfinite(obj_c):
            desired, command = self._track(t_s, dt_s, sensors, news, standby, naive)
        return self._apply(t_s, dt_s, sensors, desired, command, contact)
