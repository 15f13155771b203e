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
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from telethermal.control.contact import ContactDetector
from telethermal.data.generate import pad_database
from telethermal.errors import SceneError
from telethermal.ident.anytime import Estimate, StreamingIdentifier
from telethermal.physics.scene import Scene


@dataclass(frozen=True, slots=True)
class SlaveEvent:
    t_s: float                 # session time (s) at which the slave knows it
    estimate: Estimate


class Slave:
    """One touch of the slave pad on ``material``; ``advance_to(t)`` reads
    every sample up to session time ``t`` and returns new estimates."""

    def __init__(self, scene: Scene, material: str, identifier, rng: np.random.Generator,
                 contact_s: float | None = None, on_n: float = 2.0, off_n: float = 1.0,
                 debounce_s: float = 0.02, session=None):
        objs = [o for o in scene.objects if o.material == material]
        if not objs:
            raise SceneError(f"scene {scene.name} has no object of {material!r}; it has "
                             f"{', '.join(scene.materials)}")
        from telethermal.ident.registry import check_scene
        check_scene(identifier, scene.name)
        if abs(identifier.sample_rate_hz_ - scene.sample_rate_hz) > 1e-9:
            raise SceneError(f"the identifier expects {identifier.sample_rate_hz_:g} Hz samples, "
                             f"the scene's pad gives {scene.sample_rate_hz:g} Hz")
        pad = replace(scene.pad, trials_per_material=1,
                      contact_duration_s=contact_s or scene.pad.contact_duration_s)
        one = replace(scene, pad=pad, objects=(objs[0],))
        # ``session``: the slave's instruments and thermometer calibration,
        # kept across touches by a service; drawn for this touch if not given.
        self.trial = pad_database(one, rng, session)[0]
        self._load(self.trial.channels, identifier, self.trial.T_object_C,
                   float(self.trial.extra["T_object_true_C"]), self.trial.T_pad_C,
                   self.trial.gap_k, on_n, off_n, debounce_s)

    @classmethod
    def from_samples(cls, channels: dict, identifier, object_ir_c: float, gap_k: float,
                     object_true_c: float = float("nan"), pad_before_c: float = float("nan"),
                     on_n: float = 2.0, off_n: float = 1.0, debounce_s: float = 0.02) -> "Slave":
        """A slave reading recorded samples (``t_s``, ``force_N`` and the
        identifier's channels) instead of a simulated trial: a replay."""
        self = cls.__new__(cls)
        self.trial = None
        self._load({k: np.asarray(v, dtype=np.float64) for k, v in channels.items()},
                   identifier, object_ir_c, object_true_c, pad_before_c, gap_k, on_n, off_n,
                   debounce_s)
        return self

    def _load(self, ch, identifier, object_ir_c, object_true_c, pad_before_c, gap_k, on_n,
              off_n, debounce_s):
        self.channels = ch
        self.t_s = ch["t_s"]
        self.samples = np.stack([ch[c] for c in identifier.channels], axis=1)
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
    def committed_at_s(self) -> float | None:
        """Time after contact of the first commitment (to a material or a
        group, later refined), or None."""
        return next((ev.estimate.t_s for ev in self.events
                     if ev.estimate.decided and ev.estimate.label != "unknown"), None)

    @property
    def estimate(self) -> Estimate | None:
        return self.events[-1].estimate if self.events else None

    def advance_to(self, t_s: float) -> list[SlaveEvent]:
        new = []
        while self._next < len(self.t_s) and self.t_s[self._next] <= t_s + 1e-12:
            i = self._next
            self._next += 1
            event = self.detector.update(float(self.t_s[i]), float(self.force_n[i]))
            if event is not None and event.touching and self.stream is None:
                self.onset_s = event.t_s
                self._onset_index = int(np.searchsorted(self.t_s, event.t_s))
                self.stream = StreamingIdentifier(self.identifier, self.gap_k, self.object_ir_c)
                if self.stream.decided:                       # gap too small: unknown at once
                    new.append(SlaveEvent(float(self.t_s[i]), self.stream.estimate))
                # Samples between the onset and the debounced detection.
                for j in range(self._onset_index, i + 1):
                    est = self.stream.push(self.samples[j], float(self.force_n[j]))
                    if est is not None:
                        new.append(SlaveEvent(float(self.t_s[i]), est))
            elif self.stream is not None and self.detector.touching:
                est = self.stream.push(self.samples[i], float(self.force_n[i]))
                if est is not None:
                    new.append(SlaveEvent(float(self.t_s[i]), est))
        self.events += new
        return new
