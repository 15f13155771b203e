"""``telethermal slave --config F``: the sensing side as a process.

Owns: the transport's slave end (control ROUTER and stream PUB, bound), the
simulated sensing pad and the object under it, the identifier and the flux
generator, and a loop at the scene's sample rate on the real clock (slowed by
``time_scale``). Each period
it reads the network, the admin socket and, in a contact, the pad's new samples;
it streams estimates and then the flux trajectory (``proto/PROTOCOL.md`` 6).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import NamedTuple

import zmq

from telethermal.control.loop import RealClock
from telethermal.devices.kinds import DeviceKind
from telethermal.errors import CalibrationError, ModelFileError, TelethermalError
from telethermal.ident.fitted import clear_cache as clear_fits
from telethermal.physics.scene import load_scene, with_finger
from telethermal.record.recorder import open_recorder
from telethermal.render.sampled import sample_curves
from telethermal.services.admin import ErrorCount, open_service_sockets
from telethermal.services.background import Background
from telethermal.services.slave_admin import (answer_place, handle_admin, slave_status,
                                              touch_report)
from telethermal.services.config import SlaveConfig
from telethermal.services.slave_devices import calibrate, flat_counters, open_devices
from telethermal.teleop.decision import pad_decision
from telethermal.teleop.memory import ObjectMemory
from telethermal.teleop.slave import BOARD_LOST, Slave, instruments_rng, slave_rng
from telethermal.teleop.links import EndpointLink
from telethermal.teleop.session import ContactRequest, Send, ServiceState, SlaveSession
from telethermal.wire.messages import (ContactEvent, FluxTrajectory, Hello, Message,
                                       SessionConfig, given)

log = logging.getLogger("telethermal.slave")


class NextTouch(NamedTuple):
    """What the loop needs with a touch prepared in the background."""
    material: str
    seed: int
    object_id: str | None
    reply: bool                 # an admin ``place`` waits for it


class SlaveService:
    def __init__(self, config: SlaveConfig, identifier=None, generator=None):
        from telethermal.teleop.models import train_generator, train_identifier
        from telethermal.ident.fitted import register_scene
        from telethermal.ident.pad_calibration import check_model_calibration, pad_calibration
        from telethermal.ident.registry import load_model
        from telethermal.render.generator import load_generator

        self.config = config
        self.scene = with_finger(load_scene(config.scene))
        # A model that fits the pad's model finds it by the scene's name
        # (a scene file's name is not a path load_scene knows).
        register_scene(self.scene)
        for key, passed in (("identifier", identifier), ("generator", generator)):
            value = getattr(config, key)
            if passed is None and value and not Path(value).is_file():
                raise ModelFileError(f"{value}: no such model file ({key} in the slave's "
                                     "config): make both with `telethermal models --out DIR` "
                                     "(deploy/README.md, step 3), or leave it empty to train "
                                     "at start")
        pad_cal = pad_calibration(config.pad_calibration, self.scene)
        if identifier is None:
            identifier = load_model(config.identifier) if config.identifier else \
                train_identifier(self.scene, config.seed, calibration=pad_cal)
        check_model_calibration(identifier, pad_cal, config.identifier or "the identifier")
        if generator is None:
            generator = load_generator(config.generator) if config.generator else \
                train_generator(self.scene, config.seed)
        # Whatever the identifier builds on first use, built now and not in
        # the first touch's loop.
        prepare = getattr(identifier, "prepare", None)
        self.identifier, self.generator = (prepare() if prepare else identifier), generator
        renderable = [c for c in identifier.classes_ if c in generator.materials]
        self.curves = sample_curves(generator, renderable)
        self.rate_hz = self.scene.sample_rate_hz
        #: The service's clock: the machine's, or slowed by ``time_scale``.
        self.clock = RealClock(scale=config.time_scale)
        self.endpoint, self.admin = open_service_sockets("slave", config, self.clock)
        # Opened once the sockets are: a slave refused (a busy port) writes nothing.
        self.recorder = None
        #: The typed link to the master over that endpoint (what arrives
        #: recorded as it arrives, handled later maybe).
        self.wire = EndpointLink(self.endpoint, log, self._record_arrival)
        self.stop_requested = False
        #: The service's own error counters, reported with the transport's
        #: (status messages and the admin socket); the session counts the
        #: memory's (``memory_overruled``, ``memory_kept``) in them.
        self.counters = self.endpoint.extra_counters
        self.counters.update(masters_lost=0, contacts_superseded=0, contact_ignored=0,
                             lifted_by_place=0)
        #: The session's rules (what goes out, when; bench faults runs it too).
        self.session = SlaveSession(self.curves, self.rate_hz, counters=self.counters)
        self.state = ServiceState.IDLE
        self.masters_lost = 0          # contacts ended because the master went silent
        self._count_error = ErrorCount(self.counters, log)
        self.object_id: str | None = None
        self.material = ""                          # under the pad (``place``)
        self.sensors = None                         # this process's instruments
        self._session_rng = None
        self._seed = config.seed
        self.calibration_error: str | None = None
        self.pad: Slave | None = None
        self.devices = None
        #: The devices' counters when the object was placed (a touch's report
        #: gives what each counted since).
        self.counters_at_place: dict = {}
        self.last_touch: dict = {}
        self._next = Background("slave-next-touch")   # the simulated pad's next touch
        self._inbox: list[Message] = []         # arrived while devices held the loop
        try:
            self.recorder = open_recorder(config, "slave", identifier, generator)
            self._start_sensor_session(config.seed)
            self.place(config.place or self.scene.materials[0], config.seed)
        except BaseException:
            self._close_devices()
            if self.recorder is not None:
                self.recorder.discard()
            self.endpoint.close()
            self.admin.close()
            raise

    # ------------------------------------------------------------ the session
    @property
    def memory(self) -> ObjectMemory:
        """What this slave decided per object (in this process only: a
        restarted slave has forgotten; PROTOCOL.md section 6b)."""
        return self.session.memory

    @property
    def touch_t0(self) -> float | None:
        """When the pad went down on the object (None: no contact)."""
        return self.session.touch_t0

    @property
    def contact_id(self) -> int:
        return self.session.contact_id

    def _send(self, sends) -> None:
        for s in self.wire.send_all(sends):
            if isinstance(s.message, FluxTrajectory):
                material = s.message.material
                log.info("decided contact_id=%d material=%s (%s)", self.contact_id, material,
                         pad_decision(self.pad).text())

    # ------------------------------------------------------------ instruments
    def _start_sensor_session(self, seed: int) -> None:
        """This process's instruments (a session: the object thermometer's
        bias is drawn once for it), calibrated against the pad at start."""
        from telethermal.data.generate import SensorSession
        from telethermal.physics.sensors import draw_instruments

        self._session_rng = instruments_rng(seed)
        self.sensors = SensorSession(draw_instruments(self.scene.sensors, self._session_rng))
        self.devices = open_devices(self.config, self.scene, self.sensors.instruments, seed,
                                    self.rate_hz)
        if self.devices is not None:
            self.devices.on_wait = self._keep_alive
        self.calibrate_thermometer()

    def calibrate_thermometer(self, drift_k_per_reading: float = 0.0) -> dict:
        """Aim the object thermometer at the pad at three pad temperatures
        and remove its bias and gain error. On failure the previous
        calibration stays in force (none at start: readings are then used
        as they are, and status says so); the error is logged and returned."""
        from dataclasses import replace as dc_replace

        self._next_prepared(wait=True)       # the seed and object after the last lift
        try:
            cal = calibrate(self.devices, self.sensors, self.scene, self._session_rng,
                            drift_k_per_reading)
        except CalibrationError as exc:
            self.calibration_error = str(exc)
            log.error("object thermometer calibration failed: %s (%s in force)", exc,
                      "the previous calibration" if self.sensors.calibration.calibrated
                      else "NO calibration: readings carry the thermometer's bias")
            return {"calibrated": False, "error": str(exc),
                    "in_force": self.sensors.calibration.to_dict()}
        self.sensors = dc_replace(self.sensors, calibration=cal)
        self.calibration_error = None
        if self.pad is not None and self.touch_t0 is None:
            self.place(self.material, self._seed, self.object_id)   # measured anew, announced
        log.info("object thermometer (%s) calibrated: offset %+.3f K, gain %.4f, residual %.3f K, "
                 "offset standard error %.3f K", self.scene.sensors.object_thermometer,
                 cal.offset_k, cal.gain, cal.residual_k, cal.offset_sd_k)
        if self.recorder is not None:
            self.recorder.note("thermometer_calibration", cal.to_dict())
        return cal.to_dict()

    # ------------------------------------------------------------ the object
    def place(self, material: str, seed: int, object_id: str | None = None,
              background: bool = False, reply: bool = False) -> None:
        """Put ``material`` under the pad and measure it (IR) before contact.
        ``object_id``: the object's name (its object memory's key); by default
        the name of the scene object holding ``material`` (the scene names
        its objects by their material). ``background`` (the simulator alone):
        built on a worker thread (replacing one not placed), placed by the
        loop once ready; ``reply``: the admin request waiting answered then."""
        if self.devices is None and background:
            self._next.start(lambda: self._simulated_pad(material, seed),
                             NextTouch(material, seed, object_id, reply))
            return
        self._next.drop()
        if self.devices is not None:
            self.counters_at_place = flat_counters(self.devices.all_counters())
        if self.devices is not None and self.devices.kind == DeviceKind.HARDWARE:
            pad = Slave.on_hardware(self.scene, self.identifier, self.devices, self.sensors)
        else:
            pad = self._simulated_pad(material, seed)
        self._placed(pad, material, seed, object_id)

    def _simulated_pad(self, material: str, seed: int) -> Slave:
        return Slave(self.scene, material, self.identifier, slave_rng(seed),
                     session=self.sensors, devices=self.devices)

    def next_seed(self) -> int:
        """A fresh trial's seed: after the one being prepared, else the placed one."""
        tag = self._next.tag
        return (tag.seed if tag is not None else self._seed) + 1

    def _next_prepared(self, wait: bool = False) -> None:
        """The touch prepared in the background placed once ready (``wait``:
        now); the admin request that asked for it answered."""
        taken = self._next.take(wait)
        if taken is None:
            return
        pad, error, tag = taken
        try:
            if error is None:
                self._placed(pad, tag.material, tag.seed, tag.object_id)
            elif isinstance(error, TelethermalError):
                log.error("next touch not prepared: %s", error)
            else:                        # a bug: counted; the next touch places afresh
                self._count_error("next touch's preparation", error)
        except Exception as exc:         # placing it failed: counted, and answered below
            error = exc
            self._count_error("placing the prepared touch", exc)
        if tag.reply:
            answer_place(self, error)

    def _placed(self, pad: Slave, material: str, seed: int, object_id: str | None) -> None:
        self.pad = pad
        self.object_id = object_id or material
        self.session.place(self.pad, self.object_id)
        self.material = material
        self._seed = seed
        log.info("object placed material=%s object_id=%s object_ir_c=%.2f", material,
                 self.object_id, self.pad.object_ir_c)
        if self.endpoint.peer_version is not None:
            self.announce_object()

    def _keep_alive(self) -> None:
        """Each period the devices hold this thread (the pad pre-conditioned,
        a second or more): heartbeats go on; what arrives is recorded now and
        waits for the loop."""
        self.endpoint.state = self.state
        self._inbox.extend(self.wire.due(self.clock.monotonic()))

    def _record_arrival(self, raw: dict) -> None:
        """A message from the master, recorded as it arrives."""
        if self.recorder is not None:
            self.recorder.wire(self.clock.monotonic(), "in", raw)

    def announce_object(self) -> None:
        """The object under the pad (and the memory of it) told to the master."""
        self._send([self.session.announcement(self.clock.monotonic())])

    # ------------------------------------------------------------ loop
    def _on_message(self, m: Message, now: float) -> None:
        if isinstance(m, Hello):
            self._send([Send(now, SessionConfig(
                scene=self.scene.name, sample_rate_hz=self.rate_hz,
                classes=list(self.identifier.classes_), identifier=self.identifier.method,
                threshold=float(self.identifier.threshold), curves=self.curves))])
            if self.touch_t0 is not None and m.session_id != self.session.owner:
                self._superseded(now, m.session_id)       # lifts; the new object announced
            else:
                self.announce_object()
        elif isinstance(m, ContactEvent):
            self._on_contact_event(m, now)

    def _on_contact_event(self, m: ContactEvent, now: float) -> None:
        """Only the session that opened a contact may lift it, and only by its
        id; a touch while a contact is going on, or a lift of another
        contact, changes nothing and is counted (``contact_ignored``)."""
        owner = self.endpoint.peer_session      # before a place's pre-conditioning polls
        verdict = self.session.classify(m, owner)
        if verdict == ContactRequest.TOUCH:
            self._next_prepared(wait=True)
            if self.pad.samples_read or self.pad.fault == BOARD_LOST:
                # This trial was used (its touch ended without a lift that
                # prepared the next, e.g. the board was away): a fresh one.
                try:
                    self.place(self.material, self._seed + 1)
                except TelethermalError as exc:
                    log.error("touch on an unprepared pad: %s", exc)
            # A live slave fits every window of a touch afresh: none kept
            # from an earlier touch (a simulated pad's repeated seed gives
            # the same samples, whose fits would then cost nothing).
            clear_fits()
            # The operator touched: the slave's pad goes down on the object now.
            self.session.touch(m.contact_id, now, given(m.finger_temp_c), owner=owner)
            self.state = ServiceState.TOUCHING
            log.info("touch contact_id=%d material=%s", self.contact_id, self.material)
        elif verdict == ContactRequest.LIFT:
            self._lift(now)
        else:
            self.counters["contact_ignored"] += 1
            log.debug("contact event ignored: contact_id=%d touching=%s (going on: %s)",
                      m.contact_id, m.touching,
                      self.contact_id if self.touch_t0 is not None else None)

    def _lift(self, now: float, prepare_next: bool = True) -> None:
        """The touch ends (its last estimate, lift, report); the next one
        prepared unless ``prepare_next`` is False (the service stopping)."""
        if self.recorder is not None:
            self.recorder.slave(self.pad, self.contact_id)
        contact_id = self.contact_id
        sends, _ = self.session.lift(now)
        self._send(sends)       # the final estimate if unsent (6a), the lift event
        if self.endpoint.peer_version is not None:
            self.announce_object()     # the memory's update at once (6b), the object again
        if self.devices is not None:
            self.devices.hold()                 # the pad leaves the object, held
        self.last_touch = touch_report(self)
        r = self.last_touch
        log.info("touch over contact_id=%d material=%s identified=%s (%s)", contact_id,
                 r["material"], r["identified"], "no decision: " + str(r["reason"])
                 if r["decision_time_s"] is None else pad_decision(self.pad).text())
        self.state = ServiceState.IDLE
        if not prepare_next:
            return
        # A fresh trial of the same object (the simulator's: off the loop).
        try:
            self.place(self.material, self._seed + 1, self.object_id,   # a fresh trial
                       background=True)
        except TelethermalError as exc:
            # The devices could not prepare the next touch (the pad did not
            # settle, the board is away): the pad is safe; an admin place or
            # the next lift tries again.
            log.error("next touch not prepared: %s", exc)

    def _master_lost(self, now: float) -> None:
        """The master went silent mid-contact (crashed, or the link is down
        for longer than ``dead_after_s``): the pad leaves the object and goes
        to its safe state; the next contact event starts afresh."""
        log.warning("master lost mid-contact contact_id=%d after %.3f s of silence: pad "
                    "lifted, safe state", self.contact_id, self.endpoint.silent_s or 0.0)
        self.masters_lost += 1
        self.counters["masters_lost"] = self.masters_lost
        self._lift(now)

    def _superseded(self, now: float, session: str) -> None:
        """A new master session took over (the contact's owner is dead or
        restarted): the pad leaves the object at once, safe state."""
        log.warning("contact_id=%d of session %s superseded by session %s: pad lifted, "
                    "safe state", self.contact_id, self.session.owner, session[:32])
        self.counters["contacts_superseded"] += 1
        self._lift(now)

    def lift_for_place(self) -> None:
        """A ``place`` during a contact ends it first (its lift may still be
        on the way), preparing no next touch on the object left. Counted
        (PROTOCOL.md 5a): ``contacts_superseded`` (a new session owns it),
        ``masters_lost`` (its owner silent two heartbeats or more: a killed
        master's restart is refused "busy" until then) or ``lifted_by_place``."""
        e = self.endpoint
        silent_s = e.silent_s
        if e.peer_session != self.session.owner:
            cause = "contacts_superseded"
        elif silent_s is not None and silent_s >= 2 * self.config.transport.heartbeat_s:
            cause = "masters_lost"
            self.masters_lost += 1
        else:
            cause = "lifted_by_place"
        log.warning("place during contact_id=%d: the pad is lifted first (%s)",
                    self.contact_id, cause)
        self.counters[cause] += 1
        self._lift(self.clock.monotonic(), prepare_next=False)

    def _internal_error(self, what: str, exc: BaseException) -> None:
        """An unexpected error in one message, request or sample period:
        counted, logged with its traceback (a few lines per 10 s); a contact
        going on is lifted (the pad to its safe state); the service goes on."""
        self._count_error(what, exc)
        if self.touch_t0 is not None:
            try:
                self._lift(self.clock.monotonic())
            except Exception as lift_exc:       # the pad safe whatever the lift did
                self._count_error("lift after an error", lift_exc)
                self.session.touch_t0 = self.session.owner = None
                if self.devices is not None:
                    self.devices.safe()

    def _sample(self, now: float) -> None:
        self._send(self.session.step(now))
        if self.recorder is not None:           # streamed: a kill -9 keeps what came
            self.recorder.slave_stream(self.pad, self.contact_id)

    def _on_admin(self, request: dict) -> None:
        handle_admin(self, request)

    def _close_devices(self) -> None:
        """The active pad to its safe state, the devices released."""
        if self.devices is not None:
            try:
                self.devices.safe()
            finally:
                self.devices.close()
                self.devices = None

    @property
    def next_touch_preparing(self) -> bool:
        """A touch is being prepared in the background (not yet placed)."""
        return self._next.pending

    def status(self) -> dict:
        return slave_status(self)

    def run(self) -> None:
        """Wake at every sample period, and at once when a message arrives
        (waiting in the socket poll, not in a sleep), so the slave reacts to
        the master's contact event without a period's delay."""
        self.endpoint.poller.register(self.admin.sock, zmq.POLLIN)
        period = 1.0 / self.rate_hz
        deadline = self.clock.monotonic()
        try:
            while not self.stop_requested:
                deadline = self._step(deadline, period)
        finally:
            self.shutdown()

    def _step(self, deadline: float, period: float) -> float:
        """One wake of :meth:`run`: the sample period if due, the messages and
        the admin request waiting; an unexpected error in any of them is the
        piece's (``_internal_error``), not the service's. Returns the next
        sample deadline."""
        now = self.clock.monotonic()
        if now >= deadline:
            deadline = max(deadline + period, now)
            try:
                self._next_prepared()
                if self.touch_t0 is None and self.devices is not None:
                    self.devices.hold()      # the pad held at temperature, frames read
                if self.touch_t0 is not None:
                    self._sample(now)
            except Exception as exc:
                self._internal_error("sample period", exc)
        inbox, self._inbox = self._inbox, []      # what came while the devices held the loop
        wait = 0.0 if inbox else max(0.0, min(deadline - self.clock.monotonic(),
                                              self.config.transport.heartbeat_s))
        for message in inbox + self.wire.due(self.clock.monotonic(), wait):
            try:
                self._on_message(message, self.clock.monotonic())
            except Exception as exc:
                self._internal_error(f"message {message.kind}", exc)
        # The master judged lost after what arrived is read (a stall of this
        # process is not the master's silence).
        if self.touch_t0 is not None and not self.endpoint.peer_alive:
            try:
                self._master_lost(self.clock.monotonic())
            except Exception as exc:
                self._internal_error("master lost", exc)
        request = self.admin.receive()
        if request is not None:
            self._on_admin(request)
        self.endpoint.state = self.state
        return deadline

    def shutdown(self) -> None:
        # The sensing pad to its safe state first (simulated: nothing to hold).
        log.info("stopping: pad to safe state, sockets closed")
        try:
            if self.touch_t0 is not None:           # the master hears the pad left
                self._lift(self.clock.monotonic(), prepare_next=False)
            self.endpoint.say_stopping("slave stopping")
        finally:
            self._close_devices()
            self.endpoint.close()
            tag = self._next.tag
            if tag is not None and tag.reply and self.admin.pending:
                self.admin.reply(ok=False, error="place: the slave is stopping")
            self.admin.close()
            if self.recorder is not None:
                closed = self.recorder.close()
                log.info("recording %s closed: %d messages%s", closed["path"], closed["written"],
                         f"; {closed['error']}" if closed["error"] else "")
            self._next.close()          # a touch being prepared: not waited for
