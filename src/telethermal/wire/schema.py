"""The message kinds of the telethermal wire protocol, version 1.

This table is the single source of truth the codec validates against;
``proto/PROTOCOL.md`` is its normative description (a test checks that every
kind and field here is documented there). Every message is one msgpack map
holding the envelope keys and then its kind's fields.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

PROTOCOL_VERSION = 1
#: Versions this implementation speaks (negotiated by ``hello``).
SUPPORTED_VERSIONS = (1,)
#: Largest encoded message accepted or sent, bytes.
MAX_MESSAGE_BYTES = 256 * 1024
#: Longest array in any field.
MAX_ARRAY = 8192
MAX_STRING = 256


@dataclass(frozen=True)
class Field:
    name: str
    type: str              # str, bool, uint, float, list[str], list[float], curves, counters
    unit: str = "-"
    lo: float = -math.inf
    hi: float = math.inf
    required: bool = True
    nullable: bool = False
    doc: str = ""


@dataclass(frozen=True)
class Kind:
    name: str
    stream: str            # "control" (lossless, ordered) or "stream" (latest value, lossy)
    direction: str         # "master->slave", "slave->master" or "both"
    fields: tuple[Field, ...]
    doc: str = ""


ENVELOPE = (
    Field("kind", "str", doc="message kind, one of the kinds below"),
    Field("v", "uint", lo=1, hi=255, doc="protocol major version of the sender"),
    Field("seq", "uint", doc="lossless kinds: the lossless sequence number (one counter "
                             "per direction, from 1); other kinds: a counter of that kind "
                             "(per direction, from 1 at the sender's start, by one); 0 only "
                             "on a `fault` that refuses a hello (section 3)"),
    Field("sent_s", "float", "s", doc="sender's monotonic clock when sent"),
)

_T = dict(unit="s")
_E = "W s^0.5/m^2/K"


def _effusivity_fields(whose: str = "") -> tuple:
    """An estimate's effusivity (section 6c): optional, a later minor revision."""
    return (
        Field("effusivity_w_s05_m2k", "float", _E, lo=0, required=False,
              doc=f"{whose}the touched object's effusivity estimated at that window (by an "
                  "identifier that estimates it; absent otherwise); a later addition, optional"),
        Field("effusivity_lo_w_s05_m2k", "float", _E, lo=0, required=False,
              doc="its 95 % interval's lower end (with effusivity_w_s05_m2k)"),
        Field("effusivity_hi_w_s05_m2k", "float", _E, lo=0, required=False,
              doc="its 95 % interval's upper end (with effusivity_w_s05_m2k)"),
        Field("nearest", "str", required=False,
              doc="with label 'new material': the class whose effusivity is nearest"),
    )


#: An estimate's fields: ``material_estimate`` (decisions, lossless) and
#: ``posterior_estimate`` (every window, latest value) carry the same.
ESTIMATE_FIELDS = (
    Field("contact_id", "uint"),
    Field("t_since_contact_s", "float", "s", lo=0),
    Field("classes", "list[str]"),
    Field("posteriors", "list[float]", lo=0, hi=1,
          doc="same order and length as classes"),
    Field("label", "str", doc="best class, 'unknown', a group of two classes "
                              "'a|b' (sorted) while committed to the pair, or 'new material' "
                              "(decided: outside every class, with the effusivity fields)"),
    Field("confidence", "float", lo=0, hi=1),
    Field("decided", "bool", doc="true once committed (to a class, a group or "
                                 "'unknown'); never false again in the contact"),
    Field("reason", "str", doc="confident | confident group | outside classes | "
                               "new material | gap too small | not confident | force outside "
                               "trained range | sensor board lost | pad model does not "
                               "fit: recalibrate | pad model does not fit: named by the "
                               "fallback | '' while undecided"),
    Field("object_temp_c", "float", "degC", lo=-50, hi=200),
) + _effusivity_fields()
KINDS: dict[str, Kind] = {k.name: k for k in (
    Kind("hello", "control", "both", (
        Field("role", "str", doc="'master' or 'slave'"),
        Field("versions", "list[uint]", doc="protocol versions the sender speaks"),
        Field("software", "str", doc="name and version of the sender"),
        Field("session_id", "str", doc="random id of this run of the sender; a new id "
                                       "means the peer restarted"),
        Field("resume_from", "uint", doc="the next lossless seq the sender expects from "
                                         "the peer (1 on a fresh start)"),
    ), "first message on a connection and after every reconnection"),
    Kind("heartbeat", "control", "both", (
        Field("ack", "uint", doc="highest lossless seq received in order from the peer"),
        Field("echo_sent_s", "float", "s", nullable=True,
              doc="sent_s of the last heartbeat received from the peer"),
        Field("echo_held_s", "float", "s", lo=0, nullable=True,
              doc="how long the sender held that heartbeat before this one"),
        Field("last_seq", "uint", required=False,
              doc="the highest lossless seq the sender has sent (0: none); a receiver "
                  "that has not received it asks for a resend (a lost tail, section 4)"),
    ), "every heartbeat_s (default 0.1 s); acknowledges the lossless stream and carries "
       "the clock-offset exchange"),
    Kind("resend", "control", "both", (
        Field("from_seq", "uint", doc="resend every lossless message from this seq on"),
    ), "a receiver saw a gap in the lossless sequence"),
    Kind("session_config", "control", "slave->master", (
        Field("scene", "str"),
        Field("sample_rate_hz", "float", "Hz", lo=1, hi=100_000),
        Field("classes", "list[str]", doc="materials the identifier knows"),
        Field("identifier", "str", doc="identification method"),
        Field("threshold", "float", lo=0, hi=1, doc="decision confidence"),
        Field("curves", "curves", "W/m^2/K",
              doc="per material: {t_s: [...], g_w_m2k: [...]} the generator's "
                  "normalised finger flux at log-spaced times since contact"),
    ), "what the slave can identify and render; sent after hello"),
    Kind("contact_event", "control", "both", (
        Field("contact_id", "uint", doc="numbered by the master, echoed by the slave"),
        Field("touching", "bool"),
        Field("t_s", "float", "s", doc="onset or release on the sender's clock"),
        Field("force_n", "float", "N", lo=0, hi=1000),
        Field("object_temp_c", "float", "degC", lo=-50, hi=200, required=False,
              nullable=True, doc="slave: the object's temperature measured before contact "
                                 "(nil: none, its thermometer's reading was refused; the "
                                 "master then holds neutral)"),
        Field("finger_temp_c", "float", "degC", lo=0, hi=50, required=False,
              nullable=True, doc="master: the finger's temperature measured before contact"),
        Field("object_id", "str", required=False, nullable=True,
              doc="slave, in its object announcement (contact_id 0) and its touching event: "
                  "the object under the pad (named by the scene, the operator or a fiducial); "
                  "nil: not known"),
        Field("object_material", "str", required=False, nullable=True,
              doc="slave, with object_id: what it decided on this object before (its "
                  "object memory): a material, a pair 'a|b', or 'new material' (section "
                  "6c); nil: none remembered"),
        Field("object_confidence", "float", lo=0, hi=1, required=False, nullable=True,
              doc="the object memory's posterior of object_material (section 6b); nil "
                  "with object_material"),
        Field("object_effusivity_w_s05_m2k", "float", _E, lo=0, required=False,
              nullable=True,
              doc="with object_material 'new material': the object memory's effusivity "
                  "estimate of it (section 6b); else nil or absent"),
        Field("object_effusivity_lo_w_s05_m2k", "float", _E, lo=0, required=False,
              nullable=True, doc="its 95 % interval's lower end (with "
                                 "object_effusivity_w_s05_m2k)"),
        Field("object_effusivity_hi_w_s05_m2k", "float", _E, lo=0, required=False,
              nullable=True, doc="its 95 % interval's upper end (with "
                                 "object_effusivity_w_s05_m2k)"),
    ), "the master's operator touched or lifted; the slave's pad touched or left"),
    Kind("material_estimate", "control", "slave->master", ESTIMATE_FIELDS,
         "decisions only: sent each time the decided label changes (a commitment to a class, "
         "to a group 'a|b', a group's refinement to a member, a change of mind) and once "
         "for the contact's final estimate (decided, or 'unknown'); every estimate also "
         "goes as posterior_estimate"),
    Kind("flux_trajectory", "control", "slave->master", (
        Field("contact_id", "uint"),
        Field("material", "str"),
        Field("object_temp_c", "float", "degC", lo=-50, hi=200),
        Field("t_s", "list[float]", "s", lo=0,
              doc="times since the contact onset, strictly ascending; as many as g_w_m2k, "
                  "at least 2"),
        Field("g_w_m2k", "list[float]", "W/m^2/K",
              doc="normalised finger flux at t_s; the display flux is "
                  "g (T_object - T_finger), pad -> finger positive"),
        Field("valid_s", "float", "s", lo=0, doc="how long after the onset it may be played"),
        Field("t0_s", "float", "s", required=False, nullable=True,
              doc="the slave's contact onset on the slave's clock (the anchor); the master "
                  "plays from its own onset and uses this only to know the lag"),
    ), "what to render for a contact, anchored to its onset on the master's own clock"),
    Kind("flux_setpoint", "stream", "slave->master", (
        Field("contact_id", "uint"),
        Field("t_since_contact_s", "float", "s", lo=0),
        Field("flux_w_m2", "float", "W/m^2", lo=-1e5, hi=1e5),
    ), "latest-value setpoint, sample by sample (the naive, uncompensated path)"),
    Kind("posterior_estimate", "stream", "slave->master", ESTIMATE_FIELDS,
         "every estimate the slave computes (each identification window), the whole "
         "posterior and its time: newest wins, a lost one costs nothing; the same fields "
         "as material_estimate"),
    Kind("measurement_batch", "stream", "both", (
        Field("contact_id", "uint"),
        Field("t0_s", "float", "s", doc="sender-clock time of the first sample"),
        Field("rate_hz", "float", "Hz", lo=1, hi=100_000),
        Field("flux_w_m2", "list[float]", "W/m^2"),
        Field("temp_c", "list[float]", "degC"),
        Field("force_n", "list[float]", "N"),
        # The master's view stream (section 1): its state at the batch's last sample.
        Field("setpoint_w_m2", "float", "W/m^2", required=False, nullable=True,
              doc="master: the flux its loop tracks (nil while holding)"),
        Field("skin_temp_c", "float", "degC", required=False, nullable=True,
              doc="master: estimated skin surface temperature, pad minus flux over the "
                  "nominal contact conductance (nil out of contact)"),
        Field("phase", "str", required=False,
              doc="master: idle | contact | render | link lost"),
        Field("safe", "bool", required=False, doc="master: its pad is in its safe state"),
        Field("events", "counters", required=False,
              doc="master: safety and display events of this contact"),
        Field("link", "counters", required=False, doc="master: its transport counters"),
        Field("rtt_s", "float", "s", lo=0, required=False, nullable=True,
              doc="master: link round trip (min-RTT filter)"),
        Field("classes", "list[str]", required=False,
              doc="master: the newest material_estimate it holds"),
        Field("posteriors", "list[float]", lo=0, hi=1, required=False),
        Field("label", "str", required=False),
        Field("decided", "bool", required=False),
        Field("estimate_t_s", "float", "s", lo=0, required=False, nullable=True,
              doc="that estimate's t_since_contact_s"),
        Field("reason", "str", required=False,
              doc="master: that estimate's reason (for 'unknown': why); a later addition, optional"),
    ) + _effusivity_fields("master: that estimate's: "),
       "raw samples of the sender's pad, for display and recording (lossy); the three "
       "channels hold one value per sample (equal lengths); the master publishes its own, "
       "with the optional fields, on its view stream"),
    Kind("status", "control", "both", (
        Field("state", "str", doc="idle | touching | rendering | safe | stopping"),
        Field("counters", "counters", doc="name -> non-negative integer"),
        Field("message", "str", required=False),
    ), "on change of state and every second"),
    Kind("fault", "control", "both", (
        Field("code", "str"),
        Field("message", "str"),
        Field("safe_state", "bool", doc="the sender's pad is in its safe state"),
    ), "something went wrong; the sender says what it did about it"),
)}


class MessageKind(StrEnum):
    """The kinds by name, as the envelope's ``kind`` holds them: what code
    outside the codec compares a message's kind with."""
    HELLO = "hello"
    HEARTBEAT = "heartbeat"
    RESEND = "resend"
    SESSION_CONFIG = "session_config"
    CONTACT_EVENT = "contact_event"
    MATERIAL_ESTIMATE = "material_estimate"
    FLUX_TRAJECTORY = "flux_trajectory"
    FLUX_SETPOINT = "flux_setpoint"
    POSTERIOR_ESTIMATE = "posterior_estimate"
    MEASUREMENT_BATCH = "measurement_batch"
    STATUS = "status"
    FAULT = "fault"


if {k.value for k in MessageKind} != set(KINDS):
    raise RuntimeError("MessageKind and KINDS disagree")     # caught at import, in every test

LOSSLESS = frozenset(k for k, v in KINDS.items() if v.stream == "control" and
                     k not in (MessageKind.HELLO, MessageKind.HEARTBEAT, MessageKind.RESEND))


def field_tables() -> str:
    """The kinds and their fields as Markdown (embedded in PROTOCOL.md)."""
    def rng(f: Field) -> str:
        if f.lo == -math.inf and f.hi == math.inf:
            return ""
        lo = "" if f.lo == -math.inf else f"{f.lo:g}"
        hi = "" if f.hi == math.inf else f"{f.hi:g}"
        return f"[{lo}, {hi}]"

    def row(f: Field) -> str:
        req = "yes" if f.required else "no"
        t = f.type + (" or nil" if f.nullable else "")
        return f"| `{f.name}` | {t} | {f.unit} | {rng(f)} | {req} | {f.doc} |"

    head = "| field | type | unit | range | required | meaning |\n|---|---|---|---|---|---|"
    out = ["### Envelope (every message)", "", head] + [row(f) for f in ENVELOPE]
    for kind in KINDS.values():
        out += ["", f"### `{kind.name}`", "",
                f"Stream: **{kind.stream}** ({'lossless, ordered' if kind.name in LOSSLESS else 'not acknowledged' if kind.stream == 'control' else 'latest value, lossy'}); "
                f"direction: {kind.direction}. {kind.doc}.", "", head]
        out += [row(f) for f in kind.fields]
    return "\n".join(out) + "\n"
