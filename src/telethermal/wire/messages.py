"""The protocol's messages as typed values: one frozen dataclass per kind.

The codec (:mod:`telethermal.wire.codec`) validates and packs maps; these
classes are what the session code holds instead of those maps. A class's
fields are its kind's fields in :mod:`telethermal.wire.schema`'s order (a
test checks names, order and which are optional), so nothing about the wire
changes: ``message.fields()`` is the map the codec encodes, byte for byte
the golden vectors, and :func:`parse` turns a decoded map back into its
class.

The envelope (``kind``, ``v``, ``seq``, ``sent_s``) is the transport's and
is not part of a message value: ``kind`` is the class (:attr:`Message.KIND`).

An optional field not sent holds :data:`ABSENT`, which is not ``None``: on
the wire a nil and a missing field may mean different things (a slave's
``contact_event`` with ``object_temp_c`` nil says its thermometer refused;
one without it says nothing). Read an optional field with :func:`given`.

Sequences are kept as the lists the codec gives and takes (its fast path),
not copied into tuples: a message is frozen (its fields cannot be rebound),
and nothing here mutates the lists it holds.
"""

from __future__ import annotations

from dataclasses import dataclass, fields as dc_fields
from typing import Any, ClassVar

from telethermal.errors import ProtocolError, UnknownKindError
from telethermal.wire.schema import ENVELOPE, KINDS, LOSSLESS, MessageKind


class _Absent:
    """The value of an optional field that was not sent."""

    _instance = None

    def __new__(cls):
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "ABSENT"

    def __bool__(self) -> bool:
        return False

    def __reduce__(self):                     # copies stay the one instance
        return (_Absent, ())


ABSENT: Any = _Absent()


def given(value, default=None):
    """``value``, or ``default`` when the optional field was not sent."""
    return default if value is ABSENT else value


@dataclass(frozen=True, slots=True)
class Message:
    """One protocol message, without its envelope."""

    KIND: ClassVar[MessageKind]

    @property
    def kind(self) -> MessageKind:
        return self.KIND

    @property
    def lossless(self) -> bool:
        """Sent on the lossless, ordered stream (PROTOCOL.md section 4)."""
        return self.KIND in LOSSLESS

    def fields(self) -> dict:
        """The kind's fields, as the codec encodes them (absent ones left out)."""
        return {f.name: v for f in dc_fields(self)
                if (v := getattr(self, f.name)) is not ABSENT}

    def to_dict(self) -> dict:
        """``{"kind": ..., **fields}``: the map a recording or a log holds."""
        return {"kind": str(self.KIND), **self.fields()}


@dataclass(frozen=True, slots=True)
class Hello(Message):
    KIND: ClassVar[MessageKind] = MessageKind.HELLO
    role: str
    versions: list
    software: str
    session_id: str
    resume_from: int


@dataclass(frozen=True, slots=True)
class Heartbeat(Message):
    KIND: ClassVar[MessageKind] = MessageKind.HEARTBEAT
    ack: int
    echo_sent_s: float | None
    echo_held_s: float | None
    last_seq: int = ABSENT


@dataclass(frozen=True, slots=True)
class Resend(Message):
    KIND: ClassVar[MessageKind] = MessageKind.RESEND
    from_seq: int


@dataclass(frozen=True, slots=True)
class SessionConfig(Message):
    KIND: ClassVar[MessageKind] = MessageKind.SESSION_CONFIG
    scene: str
    sample_rate_hz: float
    classes: list
    identifier: str
    threshold: float
    curves: dict


@dataclass(frozen=True, slots=True)
class ContactEvent(Message):
    """The master's operator touched or lifted; the slave's pad touched or
    left; with ``contact_id`` 0, the slave's object announcement."""

    KIND: ClassVar[MessageKind] = MessageKind.CONTACT_EVENT
    contact_id: int
    touching: bool
    t_s: float
    force_n: float
    object_temp_c: float | None = ABSENT
    finger_temp_c: float | None = ABSENT
    object_id: str | None = ABSENT
    object_material: str | None = ABSENT
    object_confidence: float | None = ABSENT
    object_effusivity_w_s05_m2k: float | None = ABSENT
    object_effusivity_lo_w_s05_m2k: float | None = ABSENT
    object_effusivity_hi_w_s05_m2k: float | None = ABSENT

    @property
    def names_object(self) -> bool:
        """Carries the slave's object fields (an announcement, or its touching event)."""
        return self.object_id is not ABSENT


@dataclass(frozen=True, slots=True)
class _EstimateFields(Message):
    contact_id: int
    t_since_contact_s: float
    classes: list
    posteriors: list
    label: str
    confidence: float
    decided: bool
    reason: str
    object_temp_c: float
    effusivity_w_s05_m2k: float = ABSENT
    effusivity_lo_w_s05_m2k: float = ABSENT
    effusivity_hi_w_s05_m2k: float = ABSENT
    nearest: str = ABSENT


@dataclass(frozen=True, slots=True)
class MaterialEstimate(_EstimateFields):
    """A decision (lossless)."""

    KIND: ClassVar[MessageKind] = MessageKind.MATERIAL_ESTIMATE


@dataclass(frozen=True, slots=True)
class PosteriorEstimate(_EstimateFields):
    """Every estimate (latest value, lossy)."""

    KIND: ClassVar[MessageKind] = MessageKind.POSTERIOR_ESTIMATE


#: Both estimate classes (``isinstance(m, ESTIMATES)``).
ESTIMATES = (MaterialEstimate, PosteriorEstimate)


@dataclass(frozen=True, slots=True)
class FluxTrajectory(Message):
    KIND: ClassVar[MessageKind] = MessageKind.FLUX_TRAJECTORY
    contact_id: int
    material: str
    object_temp_c: float
    t_s: list
    g_w_m2k: list
    valid_s: float
    t0_s: float | None = ABSENT


@dataclass(frozen=True, slots=True)
class FluxSetpoint(Message):
    KIND: ClassVar[MessageKind] = MessageKind.FLUX_SETPOINT
    contact_id: int
    t_since_contact_s: float
    flux_w_m2: float


@dataclass(frozen=True, slots=True)
class MeasurementBatch(Message):
    KIND: ClassVar[MessageKind] = MessageKind.MEASUREMENT_BATCH
    contact_id: int
    t0_s: float
    rate_hz: float
    flux_w_m2: list
    temp_c: list
    force_n: list
    setpoint_w_m2: float | None = ABSENT
    skin_temp_c: float | None = ABSENT
    phase: str = ABSENT
    safe: bool = ABSENT
    events: dict = ABSENT
    link: dict = ABSENT
    rtt_s: float | None = ABSENT
    classes: list = ABSENT
    posteriors: list = ABSENT
    label: str = ABSENT
    decided: bool = ABSENT
    estimate_t_s: float | None = ABSENT
    reason: str = ABSENT
    effusivity_w_s05_m2k: float = ABSENT
    effusivity_lo_w_s05_m2k: float = ABSENT
    effusivity_hi_w_s05_m2k: float = ABSENT
    nearest: str = ABSENT


@dataclass(frozen=True, slots=True)
class Status(Message):
    KIND: ClassVar[MessageKind] = MessageKind.STATUS
    state: str
    counters: dict
    message: str = ABSENT


@dataclass(frozen=True, slots=True)
class Fault(Message):
    KIND: ClassVar[MessageKind] = MessageKind.FAULT
    code: str
    message: str
    safe_state: bool


#: Kind -> class, one per kind of the schema (checked at import).
CLASSES: dict[str, type[Message]] = {c.KIND.value: c for c in (
    Hello, Heartbeat, Resend, SessionConfig, ContactEvent, MaterialEstimate, FluxTrajectory,
    FluxSetpoint, PosteriorEstimate, MeasurementBatch, Status, Fault)}
if set(CLASSES) != set(KINDS):
    raise RuntimeError("wire.messages and the schema's KINDS disagree")   # caught at import
_ENVELOPE = frozenset(f.name for f in ENVELOPE)


def parse(message: dict) -> Message:
    """The typed value of a map the codec decoded (envelope keys and fields
    of a newer minor revision are left out). A map that is not a valid
    message raises :class:`ProtocolError` naming the kind and field: run it
    through :func:`telethermal.wire.codec.validate` first."""
    kind = message.get("kind") if isinstance(message, dict) else None
    cls = CLASSES.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise UnknownKindError(f"unknown message kind {str(kind)[:64]!r}")
    values = {}
    for f in dc_fields(cls):
        if f.name in message:
            values[f.name] = message[f.name]
        elif f.default is ABSENT:
            continue
        else:
            raise ProtocolError(f"{kind}.{f.name}: missing")
    return cls(**values)
