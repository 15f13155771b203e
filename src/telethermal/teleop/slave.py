"""The slave: the sensing pad touching the remote object, its contact
detection and its streaming identification.

Before contact the pad is driven to the object's temperature (measured by
the session's calibrated object thermometer) plus the scene's gap: a Peltier pad is held there; a water pad is
pre-conditioned by its PI and pump loop (:class:`~telethermal.physics.waterpad.WaterPad`,
active-heat-flow-sensing eq. 11-13), the pump off at contact. The pad's
contact is open loop (the pad does not react to what the master does), so
its whole trace is simulated at once by the databases' own generator, and
then read sample by sample as a pad would deliver it: the pressure sensor
finds the onset (hysteresis and debounce), the samples from the onset feed
a :class:`~telethermal.ident.anytime.StreamingIdentifier`.

With ``devices`` (:class:`~telethermal.devices.slave_pad.EmulatedSlavePad`)
the object is measured by the IR thermometer through the sensor board, the
Peltier pad is pre-conditioned by a closed loop through the board and the
pad's CAN driver, and the contact's samples reach the identifier as the
board's frames, decoded by the driver, as they arrive: the identifier sees
what a board would send. An IR reading the driver refuses (flagged, out of
range) ends the touch ``unknown`` ("no object temperature") before contact;
the board lost mid-contact ends it ``unknown`` ("sensor board lost") and the
pad goes to its safe state.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from telethermal.control.contact import ContactDetector
from telethermal.data.generate import pad_database
from telethermal.errors import SceneError
from telethermal.ident.anytime import UNKNOWN, Estimate, Reason, StreamingIdentifier
from telethermal.physics.scene import Scene


#: Reasons of a touch the slave refused on its devices' account (also its fault).
NO_OBJECT_TEMPERATURE = Reason.NO_OBJECT_TEMPERATURE
BOARD_LOST = Reason.BOARD_LOST


def slave_rng(seed: int) -> np.random.Generator:
    """The slave side's draws for a simulated touch (object, pad, sensors),
    the same in every driver of one (the service, the in-process run, the
    simulated network)."""
    return np.random.default_rng([seed, 0])


def instruments_rng(seed: int) -> np.random.Generator:
    """The slave service's draws of its instruments and of their
    calibration on the simulator, once per process started with ``seed``
    (the touches' draws are :func:`slave_rng`'s, one per placed seed)."""
    return np.random.default_rng((seed, 0xCA1))


class _ObjectRefused(Exception):
    def __init__(self, true_c: float):
        self.true_c = true_c


@dataclass(frozen=True, slots=True)
class SlaveEvent:
    t_s: float                 # session time (s) at which the slave knows it
    estimate: Estimate


class Slave:
    """One touch of the slave pad on ``material``; ``advance_to(t)`` reads
    every sample up to session time ``t`` and returns new estimates."""

    def __init__(self, scene: Scene, material: str, identifier, rng: np.random.Generator,
                 contact_s: float | None = None, on_n: float = 2.0, off_n: float = 1.0,
                 debounce_s: float = 0.02, session=None, devices=None):
        objs = [o for o in scene.objects if o.name == material]
        if not objs:
            raise SceneError(f"scene {scene.name} has no object of {material!r}; it has "
                             f"{', '.join(scene.materials)}")
        from telethermal.ident.registry import check_scene
        check_scene(identifier, scene.name, scene_materials=scene.materials)
        if abs(identifier.sample_rate_hz_ - scene.sample_rate_hz) > 1e-9:
            raise SceneError(f"the identifier expects {identifier.sample_rate_hz_:g} Hz samples, "
                             f"the scene's pad gives {scene.sample_rate_hz:g} Hz")
        pad = replace(scene.pad, trials_per_material=1,
                      contact_duration_s=contact_s or scene.pad.contact_duration_s)
        one = replace(scene, pad=pad, objects=(objs[0],))
        # ``session``: the slave's instruments and thermometer calibration,
        # kept across touches by a service; drawn for this touch if not given.
        self.devices = devices
        contact = None
        if devices is None:
            self.trial = pad_database(one, rng, session)[0]
            channels = self.trial.channels
        else:
            if session is None:
                raise SceneError("a slave on devices needs its sensor session (instruments "
                                 "and thermometer calibration)")
            try:
                self.trial = pad_database(one, rng, session,
                                          measure=self._measure_on(devices, session),
                                          pad_loop=devices.pad_loop)[0]
            except _ObjectRefused as refused:
                self._refuse(identifier, refused.true_c, on_n, off_n, debounce_s)
                return
            ch = self.trial.channels
            contact = devices.start_contact(ch["t_s"], ch["heat_flux_W_m2"],
                                            ch["temperature_C"], ch["force_N"])
            # The identifier reads these, filled as the board's frames arrive.
            channels = {"t_s": ch["t_s"], "heat_flux_W_m2": contact.flux_w_m2,
                        "temperature_C": contact.temp_c, "force_N": contact.force_n,
                        "measured": contact.measured}
        self._load(channels, identifier, self.trial.T_object_C,
                   float(self.trial.extra["T_object_true_C"]), self.trial.T_pad_C,
                   self.trial.gap_k, on_n, off_n, debounce_s, contact=contact)

    @classmethod
    def on_hardware(cls, scene: Scene, identifier, devices, session, contact_s: float | None = None,
                    on_n: float = 2.0, off_n: float = 1.0,
                    debounce_s: float = 0.02) -> "Slave":
        """A touch on real devices (no simulator): the object measured by the
        board's IR channel and corrected by the session's calibration, the
        pad pre-conditioned to it plus the scene's gap through the pad's
        driver, and from the first :meth:`advance_to` (the pad goes down)
        every sample the board sends, ``t_s = 0`` at that instant."""
        from telethermal.physics.scene import ONSET_MARGIN_S

        self = cls.__new__(cls)
        self.trial, self.devices = None, devices
        if abs(identifier.sample_rate_hz_ - devices.rate_hz) > 1e-9:
            raise SceneError(f"the identifier expects {identifier.sample_rate_hz_:g} Hz samples, "
                             f"the slave's board is read at {devices.rate_hz:g} Hz")
        raw = devices.object_reading_c()
        if not np.isfinite(raw):
            self._refuse(identifier, float("nan"), on_n, off_n, debounce_s)
            return self
        object_c = float(session.calibration.correct_c(raw))
        loop = devices.precondition(scene.pad_temp_c(object_c))
        duration = (contact_s or scene.pad.contact_duration_s) + scene.pre_contact_s + \
            ONSET_MARGIN_S
        n = int(round(duration * devices.rate_hz)) + 1
        contact = devices.contact(n)
        channels = {"t_s": np.arange(n) / devices.rate_hz,
                    "heat_flux_W_m2": contact.flux_w_m2, "temperature_C": contact.temp_c,
                    "force_N": contact.force_n, "measured": contact.measured}
        pad_c = float(loop["reading_c"])
        self._load(channels, identifier, object_c, float("nan"), pad_c, pad_c - object_c,
                   on_n, off_n, debounce_s, contact=contact)
        return self

    @staticmethod
    def _measure_on(devices, session):
        def measure(true_c, rng):
            raw = devices.measure_object(true_c, rng)
            if not np.all(np.isfinite(raw)):
                raise _ObjectRefused(float(np.asarray(true_c).ravel()[0]))
            return session.calibration.correct_c(raw)
        return measure

    def _refuse(self, identifier, object_true_c, on_n, off_n, debounce_s) -> None:
        """No object temperature: no pre-conditioning, no contact; the touch
        is unknown at once (never identified against a wrong temperature)."""
        empty = {"t_s": np.zeros(0), "force_N": np.zeros(0),
                 **{c: np.zeros(0) for c in identifier.channels}}
        self._load(empty, identifier, float("nan"), object_true_c, float("nan"), float("nan"),
                   on_n, off_n, debounce_s)
        self.fault = NO_OBJECT_TEMPERATURE
        n = len(identifier.classes_)
        self.events.append(SlaveEvent(0.0, Estimate(0.0, (1.0 / n,) * n, UNKNOWN, 0.0, True,
                                                    NO_OBJECT_TEMPERATURE)))
        self._fault_sent = False

    @classmethod
    def from_samples(cls, channels: dict, identifier, object_ir_c: float, gap_k: float,
                     object_true_c: float = float("nan"), pad_before_c: float = float("nan"),
                     on_n: float = 2.0, off_n: float = 1.0, debounce_s: float = 0.02) -> "Slave":
        """A slave reading recorded samples (``t_s``, ``force_N`` and the
        identifier's channels; ``measured``, 1/0 per sample, where the
        recording holds it: a frame lost on the line is then read as it was
        live) instead of a simulated trial: a replay."""
        self = cls.__new__(cls)
        self.trial = None
        self.devices = None
        self._load({k: np.asarray(v, dtype=np.float64) for k, v in channels.items()},
                   identifier, object_ir_c, object_true_c, pad_before_c, gap_k, on_n, off_n,
                   debounce_s)
        return self

    def _load(self, ch, identifier, object_ir_c, object_true_c, pad_before_c, gap_k, on_n,
              off_n, debounce_s, contact=None):
        """Every piece of the slave's state (each constructor sets ``trial``
        and ``devices`` first); ``contact``: the devices' contact being read."""
        self.channels = ch
        self.t_s = ch["t_s"]
        self._sample_channels = [ch[c] for c in identifier.channels]
        #: All samples at once (simulated or recorded); None on devices,
        #: whose samples are read as the board's frames arrive.
        self.samples = np.stack(self._sample_channels, axis=1) if self.devices is None \
            else None
        self._contact = contact
        #: Per sample: delivered by the sensor (False: filled in by the
        #: driver); the devices' contact's, or a recording's ``measured``
        #: channel (1/0); None: all were (a simulated trial, an older recording).
        self._measured = ch.get("measured")
        self.force_n = ch["force_N"]
        self.object_ir_c = object_ir_c
        self.object_true_c = object_true_c
        self.pad_before_c = pad_before_c
        self.gap_k = gap_k
        self.identifier = identifier
        self.detector = ContactDetector(on_n, off_n, debounce_s)
        self.stream: StreamingIdentifier | None = None
        self.onset_s: float | None = None
        self._onset_index: int | None = None
        self._next = 0
        self.events: list[SlaveEvent] = []
        self.fault: str | None = None
        #: False while a fault's event is still to be returned by advance_to.
        self._fault_sent = True
        self.detected_index: int | None = None
        #: An observer called with each sample's index once the identifier
        #: has it (a bench times the path from the board to the identifier).
        self.on_push: Callable[[int], None] | None = None

    @property
    def classes(self) -> tuple[str, ...]:
        return tuple(self.identifier.classes_)

    @property
    def samples_read(self) -> int:
        """How many samples of the trial have been read so far."""
        return self._next

    @property
    def onset_index(self) -> int | None:
        """Index of the contact-onset sample, once detected."""
        return self._onset_index

    @property
    def received_s(self) -> np.ndarray | None:
        """Per sample, when the devices' driver decoded it
        (``time.perf_counter``; NaN: never received); None without devices."""
        return self._contact.received_s if self._contact is not None else None

    @property
    def committed_at_s(self) -> float | None:
        """Time after contact of the first commitment (to a material or a
        group, later refined), or None."""
        return next((ev.estimate.t_s for ev in self.events
                     if ev.estimate.decided and not ev.estimate.label.is_unknown), None)

    @property
    def first_commitment(self) -> Estimate | None:
        """The first committed estimate (a material, or a group later
        refined), or None: :attr:`committed_at_s` is its time."""
        return next((ev.estimate for ev in self.events
                     if ev.estimate.decided and not ev.estimate.label.is_unknown), None)

    def decided_at_s(self, label: str) -> float | None:
        """Time after contact at which ``label`` itself was first decided
        (later than :attr:`committed_at_s` when a group came first)."""
        return next((ev.estimate.t_s for ev in self.events
                     if ev.estimate.decided and ev.estimate.label == label), None)

    @property
    def estimate(self) -> Estimate | None:
        return self.events[-1].estimate if self.events else None

    def _sample(self, i: int) -> np.ndarray:
        if self.devices is None:
            return self.samples[i]
        return np.array([c[i] for c in self._sample_channels])

    def _push(self, j: int):
        # On devices, a sample the driver filled in (a lost frame held) is
        # pushed as such: the pad-model check does not count it as measured.
        measured = self._measured is None or bool(self._measured[j])
        est = self.stream.push(self._sample(j), float(self.force_n[j]), measured)
        if self.on_push is not None:
            self.on_push(j)
        return est

    def _onset_across_lost(self, k: int) -> int:
        """The onset, ``k`` the first sample past the threshold, moved back
        onto a frame lost just before it (held by the driver at the previous,
        lower force) whose force, interpolated linearly between its measured
        neighbours, was past it too: a lost frame delays the onset no more
        than the force says (the identifier reads the lost one as missing)."""
        if self._measured is None:
            return k
        measured, j = self._measured, k - 1
        while j >= 0 and not measured[j]:
            j -= 1
        if j < 0 or j == k - 1:
            return k
        f0, f1 = float(self.force_n[j]), float(self.force_n[k])
        return next((i for i in range(j + 1, k)
                     if f0 + (f1 - f0) * (i - j) / (k - j) > self.detector.on_n), k)

    def advance_to(self, t_s: float) -> list[SlaveEvent]:
        if self.fault is not None:
            if not self._fault_sent:
                self._fault_sent = True
                return [self.events[-1]]
            return []
        end = len(self.t_s)
        if self.devices is not None:
            if not self.devices.feed(t_s):
                return self._board_lost(t_s)
            end = self._contact.available
        new = []
        while self._next < end and self.t_s[self._next] <= t_s + 1e-12:
            i = self._next
            self._next += 1
            event = self.detector.update(float(self.t_s[i]), float(self.force_n[i]))
            if event is not None and event.touching and self.stream is None:
                self._onset_index = self._onset_across_lost(
                    int(np.searchsorted(self.t_s, event.t_s)))
                self.onset_s = float(self.t_s[self._onset_index])
                self.detected_index = i          # the debounce's backlog is pushed now
                self.stream = StreamingIdentifier(self.identifier, self.gap_k, self.object_ir_c)
                if self.stream.decided:                       # gap too small: unknown at once
                    new.append(SlaveEvent(float(self.t_s[i]), self.stream.estimate))
                # Samples between the onset and the debounced detection.
                for j in range(self._onset_index, i + 1):
                    est = self._push(j)
                    if est is not None:
                        new.append(SlaveEvent(float(self.t_s[i]), est))
            elif self.stream is not None and self.detector.touching:
                est = self._push(i)
                if est is not None:
                    new.append(SlaveEvent(float(self.t_s[i]), est))
        self.events += new
        return new

    def _board_lost(self, t_s: float) -> list[SlaveEvent]:
        """The board went silent mid-contact: the devices made the pad safe;
        the touch ends unknown, whatever was estimated before."""
        self.fault, self._fault_sent = BOARD_LOST, True
        n = len(self.identifier.classes_)
        t = max(0.0, t_s - (self.onset_s or 0.0))
        ev = SlaveEvent(t_s, Estimate(t, (1.0 / n,) * n, UNKNOWN, 0.0, True, BOARD_LOST))
        self.events.append(ev)
        return [ev]
