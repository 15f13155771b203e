"""``telethermal master --config F``: the display side as a process.

Owns: the transport's master end (control DEALER and stream SUB, connecting),
the simulated display pad, operator and force sensor, and the display loop at
``rate_hz`` on the real clock (slowed by ``time_scale``). Each period it reads
the network and the admin socket and, in a touch, runs one period of the
display (teleop/master.py) with what the slave has said. Rendering is timed from the master's own contact onset,
so the network's delay shifts nothing once the trajectory is here.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, replace

from telethermal.control.loop import FixedRateLoop, RealClock, set_realtime
from telethermal.control.preconditioning import prepare_policy
from telethermal.devices.display import open_display
from telethermal.devices.kinds import DeviceKind
from telethermal.devices.simulated import simulated
from telethermal.record.recorder import display_params, open_recorder
from telethermal.errors import TelethermalError
from telethermal.ident.anytime import unknown_reason
from telethermal.ident.openset import EFFUSIVITY_KEYS, effusivity_of, touch_text
from telethermal.physics.scene import load_scene, with_finger
from telethermal.services.admin import ErrorCount, open_service_sockets
from telethermal.services.requests import MASTER as MASTER_REQUESTS
from telethermal.services.config import MasterConfig, parse_cpus
from telethermal.services.touch_figures import log_touch_figures, touch_figures
from telethermal.services.qemu_boards import close_boards, display_boards
from telethermal.view.stream import ViewPublisher
from telethermal.teleop.link import SlaveLink
from telethermal.teleop.display_config import DisplayConfig
from telethermal.teleop.master import MasterDisplay, Phase
from telethermal.teleop.links import EndpointLink
from telethermal.teleop.session import MasterSession, PRE_CONTACT_S, ServiceState
from telethermal.teleop.decision import touch_decision
from telethermal.teleop.memory import judged_of
from telethermal.teleop.display_setup import build_display, safety_summary
from telethermal.teleop.display_calibration import (display_calibration, modelled_scene,
                                                    refuse_on_hardware)
from telethermal.wire.messages import Message, SessionConfig
from telethermal.wire.schema import MessageKind

log = logging.getLogger("telethermal.master")


class Touch:
    """One operator touch in progress."""

    def __init__(self, service: "MasterService", contact_s: float, seed: int, now: float,
                 source: str = "trajectory"):
        scene = service.scene
        cfg = replace(service.display_config, source=source)
        world = simulated("master_touch")(scene, seed)
        self.operator = world.operator
        # Idling before the touch: pre-conditioned for what the slave expects.
        self.display, self.idle_c = build_display(scene, cfg, self.operator.finger_ir_c,
                                                  service.link,
                                                  calibration=service.display_calibration)
        self.sim = world.display(cfg.rate_hz, contact_s, self.idle_c)
        self.devices = open_display(service.config.devices, self.sim, service.clock.monotonic,
                                    realtime=True, seed=seed, **service.display_options)
        #: Session time 0 (the finger's contact) on the service's clock: the display's
        #: time is ``now - origin_s``; its onset goes back at ``origin_s`` plus its time
        #: (as ``t0`` on hardware). From ``now`` here (``now`` may be a test's); the
        #: service's loop moves it to when the touch is set up (:meth:`start_clock`).
        self.origin_s = now + PRE_CONTACT_S
        self.contact_s = contact_s
        # The id the session gives the contact at the display's onset.
        self.contact_id = service.session.next_contact_id
        #: A recording's start of this touch: its display's parameters, made
        #: here (the set-up, not a period), written at its first period (the
        #: time its clock starts: ``origin_s - PRE_CONTACT_S``).
        self.record_params = None if service.recorder is None else display_params(
            scene, cfg, self.operator, self.idle_c, self.display)
        self.start_recorded = False
        self.loop_count0 = service.loop.stats.count
        self.misses0 = service.loop.stats.missed_deadlines
        self.set_aside0 = service.loop.stats.set_aside
        self.gc0 = list(service.loop.stats.gc_collections)
        self.memory0 = judged_of(service.link.counters)
        self.reply_when_done = True          # the admin "touch" request waits for the end
        self.truth: dict | None = None       # the placed object (simulation), for the figures
        self.setup_s = 0.0                   # asked for -> set up, on the service's clock

    def start_clock(self, asked_s: float, ready_s: float) -> None:
        """The touch's clock starts when it is set up (``ready_s``: its
        simulated operator and display pad built, its devices open, QEMU's
        cores restarted in real time), not when it was asked for
        (``asked_s``): its first period is then its first, at
        ``-PRE_CONTACT_S``."""
        self.setup_s = ready_s - asked_s
        self.origin_s = ready_s + PRE_CONTACT_S


@dataclass(frozen=True)
class _Finger:
    """What the display parameters need of an operator on hardware."""
    finger_ir_c: float
    finger_c: float = float("nan")
    skin_k_scale: float = float("nan")
    skin_heat_scale: float = float("nan")
    force_n: float = float("nan")
    conductance_w_m2k: float = float("nan")


class MasterService:
    def __init__(self, config: MasterConfig):
        self.config = config
        self.scene = with_finger(load_scene(config.scene))
        #: The display's calibration (the ``[display]`` table of ``pad_calibration``).
        self.display_calibration = display_calibration(config.pad_calibration, self.scene)
        if config.devices == DeviceKind.HARDWARE:   # before its policy, and any device
            refuse_on_hardware(self.display_calibration)
        self.display_config = DisplayConfig(rate_hz=config.rate_hz, before=config.before,
                                            idle=config.idle)
        if config.idle == "policy":       # before the sockets: no touch waits for it
            prepare_policy(modelled_scene(self.scene, self.display_calibration), log.warning)
        #: The service's clock (the loop's, and its messages'): the
        #: machine's, or slowed by ``time_scale``.
        self.clock = RealClock.for_period(1.0 / config.rate_hz, config.time_scale)
        self.endpoint, self.admin = open_service_sockets("master", config, self.clock)
        # Estimates and setpoints: the lossy stream, newest wins (PROTOCOL.md 6a).
        self.endpoint.deliver_stream = frozenset({MessageKind.POSTERIOR_ESTIMATE,
                                                  MessageKind.FLUX_SETPOINT})
        #: The typed link to the slave over that endpoint; what arrives is
        #: recorded at the period it is read in (``_arrival_now``).
        self.recorder = None                    # opened last (below)
        self.wire = EndpointLink(self.endpoint, log, self._record_arrival)
        self._arrival_now = 0.0
        #: The session's rules (what the master reads, what it tells the
        #: slave): the simulated network of ``bench faults`` runs the same.
        self.session = MasterSession()
        #: The display loop (``run``); its statistics: each touch's report.
        self.loop = FixedRateLoop(1.0 / config.rate_hz, self.clock)
        self.hardware = None
        #: The hardware display's controller and its clock origin (hardware only).
        self.display: MasterDisplay | None = None
        self.t0 = 0.0
        self.view, self.display_options = None, {}
        try:
            self.display_options = display_boards(config)       # "qemu": the cores
            if config.view_port:
                self.view = ViewPublisher(config.view_port,
                                          self.scene.finger.contact_conductance_w_m2k)
                log.info("view stream on tcp://127.0.0.1:%d", self.view.port)
            if config.devices == DeviceKind.HARDWARE:
                self._open_hardware()
            # Last: a master that did not start writes no recording.
            self.recorder = open_recorder(config, "master")
        except TelethermalError:
            close_boards(self.display_options)
            self.endpoint.close()
            self.admin.close()
            if self.view is not None:
                self.view.close()
            raise
        self.touch: Touch | None = None
        self.stop_requested = False
        self.state = ServiceState.IDLE
        self.last_touch: dict = {}
        self.last_period_t_s: float | None = None   # the display's last period (s)
        #: Unexpected errors in one message, one touch or one figure (status).
        self.counters = self.endpoint.extra_counters
        self._internal_error = ErrorCount(self.counters, log)

    @property
    def link(self) -> SlaveLink:
        """What the master knows from the slave (the session's)."""
        return self.session.link

    def _send(self, sends) -> None:
        self.wire.send_all(sends)

    # ------------------------------------------------------------ hardware
    def _open_hardware(self) -> None:
        """The real display: the board and the Peltier driver, and one display
        loop that runs all the time; the operator's force starts each touch."""
        from telethermal.devices.board import Calibration
        from telethermal.devices.display import HardwareDisplay

        cfg = self.config                     # (its calibration checked in __init__)
        calibration = Calibration.load(cfg.calibration) if cfg.calibration else Calibration()
        self.hardware = HardwareDisplay(cfg.board_url, cfg.can_bus, calibration)
        # The module behind the pad: the master commands its current.
        # The pad model (the scene's layers, the finger's contact
        # conductance) and the module behind the pad, as in simulation.
        self.display, _ = build_display(self.scene, self.display_config, cfg.finger_temp_c,
                                        self.link, calibration=self.display_calibration,
                                        idling=False)
        self.t0 = self.clock.monotonic()
        log.info("display on hardware: board %s, Peltier driver on %s", cfg.board_url,
                 cfg.can_bus)

    def _hardware_period(self, now: float, dt_s: float) -> None:
        display, t, session = self.display, now - self.t0, self.session
        self.last_period_t_s = t
        news = session.news(now, self.endpoint.peer_alive)
        sensors = self.hardware.read(t)
        step = display.step(t, dt_s, sensors, news)
        self.hardware.apply(t, step, dt_s, sensors.force_n)
        if self.view is not None:
            self.view.period(now, self.config.rate_hz, sensors.flux_w_m2 / display.flux_gain,
                             sensors.pad_temp_c, sensors.force_n, lambda: self._view_state(
                                 step, display, session.contact_id or 0))
        contact_id = session.contact_id
        self._send(session.period(step, self.t0, sensors.force_n, self.config.finger_temp_c))
        if step.contact is not None and step.contact.touching:
            self.state = ServiceState.TOUCHING
            if self.recorder is not None:
                # (A replay starts a fresh display at this touch; this one has
                # run since the service started, so it may differ slightly.)
                self.recorder.touch_start(now, session.contact_id, display_params(
                    self.scene, self.display_config, _Finger(self.config.finger_temp_c),
                    display.safety.applied_temp_c, display))
        if (session.contact_id is not None or contact_id is not None) and \
                self.recorder is not None:
            self.recorder.period(t, dt_s, sensors, news, step)
        if step.contact is not None and not step.contact.touching and contact_id is not None:
            if self.recorder is not None:
                self.recorder.touch_end({"contact_id": contact_id, **safety_summary(
                    display), "device_counters": self.hardware.counters()}, {})
            self.state = ServiceState.IDLE
        elif display.phase == Phase.RENDER:
            self.state = ServiceState.RENDERING

    # ------------------------------------------------------------ network
    def _on_message(self, m: Message, now: float) -> None:
        if isinstance(m, SessionConfig):
            log.info("session config from slave: %d classes, scene %s", len(m.classes), m.scene)
        self.session.on_message(m, now, self.endpoint.offset.offset_s)

    def _record_arrival(self, raw: dict) -> None:
        """A message from the slave, recorded at the period that reads it."""
        if self.recorder is not None:
            self.recorder.wire(self._arrival_now, "in", raw)

    # ------------------------------------------------------------ loop
    def step(self, t_loop: float, dt_s: float) -> bool:
        now = self.clock.monotonic()
        self._arrival_now = now
        for message in self.wire.due(now):
            try:
                self._on_message(message, now)
            except Exception as exc:            # one message's, not the service's
                self._internal_error(f"message {message.kind} from the slave", exc)
        request = self.admin.receive()
        set_up = False
        if request is not None:
            touch = self.touch
            self._on_admin(request, now)
            set_up = self.hardware is None and self.touch is not None and self.touch is not touch
        if set_up:
            # A touch was set up in this period while nothing was being
            # controlled (a simulated display exists only in a touch): its
            # clock and the loop's deadlines start when it is ready, and its
            # first period is the next one (set-up time: its report).
            self.touch.start_clock(now, self.clock.monotonic())
            self.loop.restart_deadlines()
        elif self.hardware is not None:
            self._hardware_period(now, dt_s)
        elif self.touch is not None:
            try:
                self._touch_period(now, dt_s)
            except Exception as exc:            # the touch's, not the service's
                self._abort_touch(exc)
        elif self.view is not None:
            self.view.idle(now, lambda: self._view_state(None, None, 0))
        self.endpoint.state = self.state          # status: on change and every second
        return not self.stop_requested

    def _view_state(self, step, display, contact_id: int) -> dict:
        """The optional fields of the view stream's batch (its docstring)."""
        e, link = self.endpoint, self.link
        est = link.estimate
        state = {"contact_id": contact_id, "touching": bool(step is not None and step.touching),
                 "phase": step.phase if step is not None else self.state,
                 "safe": bool(step.safe) if step is not None else False,
                 "setpoint_w_m2": step.desired_flux_w_m2 if step is not None and
                 math.isfinite(step.desired_flux_w_m2) else None,
                 "events": dict(display.events) if display is not None else {},
                 "link": dict(e.counters), "rtt_s": e.offset.rtt_s}
        if est is not None:
            state.update(classes=list(link.classes), posteriors=[float(p) for p in
                                                                  est.posteriors],
                         label=est.label, decided=bool(est.decided), estimate_t_s=float(est.t_s),
                         reason=str(est.reason), **effusivity_of(est))
        return state

    def _touch_period(self, now: float, dt_s: float) -> None:
        touch, session = self.touch, self.session
        if self.recorder is not None and not touch.start_recorded:
            self.recorder.touch_start(touch.origin_s - PRE_CONTACT_S, touch.contact_id,
                                      touch.record_params)
            touch.start_recorded = True
        t = self.last_period_t_s = now - touch.origin_s
        news = session.news(now, self.endpoint.peer_alive)
        sensors = touch.devices.read(t)
        step = touch.display.step(t, dt_s, sensors, news)
        touch.devices.apply(t, step, dt_s, sensors.force_n)
        if self.view is not None:
            self.view.period(now, self.config.rate_hz,
                             sensors.flux_w_m2 / touch.display.flux_gain, sensors.pad_temp_c,
                             sensors.force_n, lambda: self._view_state(step, touch.display,
                                                                       touch.contact_id))
        if self.recorder is not None:
            self.recorder.period(t, dt_s, sensors, news, step)
        self._send(session.period(step, touch.origin_s, sensors.force_n,
                                  touch.operator.finger_ir_c))
        if step.contact is not None and step.contact.touching:
            self.state = ServiceState.TOUCHING
        if touch.display.phase == Phase.RENDER:
            self.state = ServiceState.RENDERING
        if touch.sim.done:
            self._finish_touch()

    def _abort_touch(self, exc: BaseException) -> None:
        """A touch ended by an unexpected error: its pad safe first (the Peltier
        driver disabled), the slave told of the lift, the request answered."""
        touch, self.touch, self.state = self.touch, None, ServiceState.IDLE
        self._internal_error(f"touch contact_id={touch.contact_id}", exc)
        error = f"{type(exc).__name__}: {str(exc)[:200]}"
        try:
            touch.devices.close()
        finally:
            try:
                if self.recorder is not None and touch.start_recorded:
                    # (a touch whose start was never recorded has no end there either)
                    self.recorder.touch_end({"contact_id": touch.contact_id, "error": error}, {})
                self._send(self.session.close_contact(self.clock.monotonic(),
                                                      touch.operator.finger_ir_c))
            except Exception as send_exc:
                self._internal_error("lift after an error", send_exc)
            if touch.reply_when_done and self.admin.pending:
                self.admin.reply(ok=False, error=f"touch {touch.contact_id} ended by an "
                                 f"internal error ({error}); the pad is safe")

    def _finish_touch(self) -> None:
        touch, stats = self.touch, self.loop.stats
        devices = touch.devices.counters()
        touch.devices.close()
        link, session = self.link, self.session
        trajectory_at = None if session.trajectory_at_s is None else \
            session.trajectory_at_s - touch.origin_s
        self._send(session.close_contact(self.clock.monotonic(), touch.operator.finger_ir_c))
        # What the slave itself decided on this touch (not the recollection
        # the display may have rendered from; that is reported apart), by
        # the definition every summary uses (teleop/decision.py).
        decision = touch_decision(link.estimates)
        est = decision.estimate
        loop = stats.summary(last=stats.count - touch.loop_count0)
        loop["deadline_misses"] = stats.missed_deadlines - touch.misses0
        # Its set-up's, outside its periods (Touch.start_clock).
        loop["deadlines_set_aside"] = stats.set_aside - touch.set_aside0
        loop["setup_s"] = touch.setup_s
        loop["gc_collections"] = [a - b for a, b in zip(stats.gc_collections, touch.gc0)]
        loop.pop("gc_max_us")                   # the service's run's, not this touch's
        result = {
            "ok": True, "contact_id": touch.contact_id, "contact_s": touch.contact_s,
            "operator": vars(touch.operator), "trace": touch.sim.trace,
            "render_start_s": touch.display.rendered_from_s,
            "master_onset_s": touch.display.last_onset_s,
            **decision.fields(),            # identified, decision_time_s, identified_at_s
            "unknown_reason": unknown_reason(est),
            # a new material's estimate (W s^0.5/(m^2 K)) and nearest class; the
            # last window's estimate otherwise (None: the identifier gives none)
            **dict.fromkeys(EFFUSIVITY_KEYS), **(effusivity_of(est) if est is not None else {}),
            "decision_text": touch_text(est),
            "object_memory": None if link.recalled is None else link.recalled.label,
            "estimates": len(link.estimates), "trajectory_at_s": trajectory_at,
            "anchor_lag_s": None if math.isnan(link.anchor_lag_s) else link.anchor_lag_s,
            "link_counters": dict(link.counters), "devices": self.config.devices,
            "time_scale": self.clock.scale,
            # what the memory's counters counted of this touch (PROTOCOL.md 6b)
            "memory_judged": {k: v - touch.memory0[k]
                              for k, v in judged_of(link.counters).items()},
            "device_counters": devices, **safety_summary(touch.display), "loop": loop,
            "transport": dict(self.endpoint.counters), "rtt_s": self.endpoint.offset.rtt_s,
        }
        try:
            result.update(touch_figures(self.scene, touch, result))
        except Exception as exc:                # the figures', not the touch's
            self._internal_error("figures against direct contact", exc)
            result.update(direct=None, direct_error=f"{type(exc).__name__}: {exc}"[:200])
        if self.recorder is not None:
            self.recorder.touch_end({k: v for k, v in result.items() if k != "trace"},
                                    touch.sim.trace)
        self.touch, self.state = None, ServiceState.IDLE
        log_touch_figures(result)
        self.last_touch = result
        if touch.reply_when_done:
            self.admin.reply(**result)

    def _on_admin(self, request: dict, now: float) -> None:
        def touch(r):
            if self.hardware is not None:
                raise ValueError("the display is on hardware: touches come from the "
                                 "operator's finger, not from this command")
            if self.link.generator is None or not self.endpoint.peer_alive:
                d = self.endpoint.diagnosis
                raise ValueError("no slave session yet" + (
                    f": {d['problem']}; likely: {d['fix']}" if d else
                    " (not connected or no session_config)"))
            contact_s = float(r.get("contact_s", 5.0))       # (0, 60]: MASTER_REQUESTS
            if self.touch is not None:
                raise ValueError(f"touch {self.touch.contact_id} is still in progress "
                                 "(lift it first)")
            self.touch = Touch(self, contact_s, int(r.get("seed", 0)), now,
                               str(r.get("source", "trajectory")))
            self.touch.truth = r.get("truth") or None
            self.touch.reply_when_done = bool(r.get("wait", True))
            log.info("touch contact_id=%d contact_s=%.1f", self.touch.contact_id, contact_s)
            if self.touch.reply_when_done:
                return None                   # the reply is sent when the touch is over
            return {"contact_id": self.touch.contact_id, "contact_s": contact_s}

        def lift(r):
            if self.touch is None:
                raise ValueError("no touch in progress")
            self.touch.sim.release_at(now - self.touch.origin_s)
            self.touch.contact_s = self.touch.sim.contact_s
            return {"contact_id": self.touch.contact_id, "contact_s": self.touch.contact_s}

        def report(r):
            if not self.last_touch:
                raise ValueError("no touch has ended yet")
            return {k: v for k, v in self.last_touch.items()
                    if k != "trace" or r.get("trace")}

        self.admin.handle(request, self, {"touch": touch, "lift": lift, "report": report},
                          MASTER_REQUESTS)

    def status(self) -> dict:
        e = self.endpoint
        return {"role": "master", "state": self.state, "peer_alive": e.peer_alive,
                "slave": f"{self.config.transport.host}:{self.config.transport.control_port}",
                "diagnosis": None if e.peer_alive else e.diagnosis,
                "session": self.link.generator is not None,
                "object_temp_c": self.link.object_temp_c,
                # The object the slave announced and its memory of it (6b).
                "object_id": self.link.object_id,
                "object_material": (self.link.remembered or (None,))[0],
                "rtt_s": e.offset.rtt_s, "offset_s": e.offset.offset_s,
                "counters": e.all_counters(), "admin": dict(self.admin.counters),
                "devices": self.config.devices, "time_scale": self.clock.scale,
                "last_period_t_s": self.last_period_t_s,
                **({"device_counters": self.hardware.counters(),
                    "display_phase": self.display.phase, "contact_id": self.session.contact_id}
                   if self.hardware is not None else {})}

    def _realtime(self) -> None:
        """Real-time scheduling for the display loop, where allowed."""
        cfg = self.config
        if cfg.cpus:
            try:
                os.sched_setaffinity(0, parse_cpus(cfg.cpus))
            except (OSError, ValueError) as exc:
                log.warning("cpus=%r not applied: %s", cfg.cpus, exc)
        if cfg.realtime_priority:
            refused = set_realtime(cfg.realtime_priority)
            if refused:
                log.warning("SCHED_FIFO %d not granted (%s): running at normal priority",
                            cfg.realtime_priority, refused)
            else:
                log.info("display loop at SCHED_FIFO priority %d", cfg.realtime_priority)

    def run(self) -> None:
        self._realtime()
        try:
            self.loop.run(self.step, math.inf, keep_last=100_000)
        finally:
            self.shutdown()

    def shutdown(self) -> None:
        # The display pad to its safe state first: neutral, not off.
        neutral = self.display_config.limits.neutral_c
        log.info("stopping: display pad to the safe state (%.1f C), sockets closed", neutral)
        if self.hardware is not None:
            self.hardware.close()              # the Peltier driver disabled first
        if self.touch is not None:
            self.touch.devices.close()         # the Peltier driver disabled first
            if self.admin.pending:
                self.admin.reply(ok=False, error="master stopping")
        try:
            self.endpoint.say_stopping("master stopping; pad at neutral")
        finally:
            close_boards(self.display_options)
            self.endpoint.close()
            self.admin.close()
            if self.view is not None:
                self.view.close()
            if self.recorder is not None:
                closed = self.recorder.close()
                log.info("recording %s closed: %d messages, %d dropped%s", closed["path"],
                         closed["written"], closed["dropped_queue_full"] +
                         closed["dropped_after_error"] + closed["dropped_unpackable"],
                         f"; {closed['error']}" if closed["error"] else "")
