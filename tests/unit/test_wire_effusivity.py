"""The estimates' effusivity fields on the wire (PROTOCOL.md section 6c, a
minor revision of version 1): what the slave sends is what the master
reads, and a peer of the revision before interoperates both ways."""

import dataclasses
import json
from pathlib import Path
from unittest import mock

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.ident.anytime import NEW_MATERIAL, Estimate, Reason
from telethermal.ident.openset import EFFUSIVITY_KEYS, effusivity_of
from telethermal.teleop.link import SlaveLink
from telethermal.wire import codec, messages, schema
from telethermal.wire.codec import decode_verbose, encode
from telethermal.wire.golden import messages as golden_messages

PROTO = Path(__file__).resolve().parents[2] / "proto"
ENV = {"v": 1, "seq": 1, "sent_s": 10.0}
CLASSES = ["plexiglass", "steel"]

positive = st.floats(min_value=1e-3, max_value=1e6, allow_nan=False, allow_infinity=False)


@st.composite
def effusivity_estimates(draw):
    """A new material's decided estimate, or an undecided one of a class,
    with an effusivity and an interval around it."""
    e = draw(positive)
    lo = e / draw(st.floats(min_value=1.0, max_value=10.0))
    hi = e * draw(st.floats(min_value=1.0, max_value=10.0))
    p = draw(st.floats(min_value=0.0, max_value=1.0))
    if draw(st.booleans()):
        nearest = draw(st.sampled_from(CLASSES))
        return Estimate(1.0, (p, 1.0 - p), NEW_MATERIAL, 0.99999, True, Reason.NEW_MATERIAL,
                        e, lo, hi, nearest)
    return Estimate(draw(st.floats(min_value=0.0, max_value=2.0)), (p, 1.0 - p), "steel",
                    1.0 - p, False, Reason.UNDECIDED, e, lo, hi)


def _wire(est: Estimate, kind=messages.PosteriorEstimate):
    """The slave's message of ``est`` (teleop/session.py's fields), encoded."""
    m = kind(contact_id=4, t_since_contact_s=float(est.t_s), classes=CLASSES,
             posteriors=list(est.posteriors), label=str(est.label),
             confidence=float(est.confidence), decided=bool(est.decided),
             reason=str(est.reason), object_temp_c=24.0, **effusivity_of(est))
    return encode({"kind": str(m.kind), **ENV, **m.fields()})


def _master_reads(data: bytes) -> Estimate:
    link = SlaveLink(classes=tuple(CLASSES))
    link.begin(4)
    link.on_message(messages.parse(codec.decode(data)), now_s=11.0)
    return link.latest


@settings(max_examples=200, deadline=None)
@given(effusivity_estimates())
def test_what_the_slave_sends_the_master_reads(est):
    got = _master_reads(_wire(est))
    assert got == est                       # every field, the effusivity's bit for bit


@settings(max_examples=100, deadline=None)
@given(effusivity_estimates())
def test_a_master_of_the_revision_before_reads_a_new_material(est):
    """An older master's codec (the estimate kinds without the four fields)
    ignores them (section 3) and reads the rest unchanged."""
    data = _wire(est, messages.MaterialEstimate)
    new, _ = decode_verbose(data)
    older = {name: dataclasses.replace(kind, fields=tuple(
        f for f in kind.fields if f.name not in EFFUSIVITY_KEYS))
        for name, kind in schema.KINDS.items()}
    names = {k: {f.name for f in schema.ENVELOPE + v.fields} for k, v in older.items()}
    with mock.patch.object(codec, "KINDS", older), mock.patch.object(codec, "_NAMES", names):
        old, ignored = decode_verbose(data)
    present = [k for k in EFFUSIVITY_KEYS if k in new]
    assert sorted(ignored) == sorted(present)
    assert old == {k: v for k, v in new.items() if k not in EFFUSIVITY_KEYS}


def test_a_slave_of_the_revision_before_gives_estimates_without_effusivity():
    """The golden vector of the revision before (no effusivity fields): the
    master reads the estimate with its effusivity fields None."""
    data = (PROTO / "golden" / "posterior_estimate.msgpack").read_bytes()
    est = _master_reads(_renumbered(data))
    assert est is not None and all(getattr(est, k) is None for k in EFFUSIVITY_KEYS)
    assert effusivity_of(est) == {}


def _renumbered(data: bytes) -> bytes:
    m = codec.decode(data)
    return encode({**m, "contact_id": 4})


def test_the_new_material_vector_is_a_decided_new_material_with_its_estimate():
    v = golden_messages()["material_estimate.new"]
    assert v["label"] == v["reason"] == "new material" and v["decided"]
    assert v["effusivity_lo_w_s05_m2k"] < v["effusivity_w_s05_m2k"] < v["effusivity_hi_w_s05_m2k"]
    assert v["nearest"] in v["classes"]
    assert json.loads((PROTO / "golden" / "material_estimate.new.json").read_text()) == v


@pytest.mark.parametrize("field, value, match", [
    ("effusivity_w_s05_m2k", -1.0, "effusivity_w_s05_m2k: -1.0 outside"),
    ("effusivity_lo_w_s05_m2k", float("nan"), "effusivity_lo_w_s05_m2k: nan"),
    ("nearest", 3, "nearest: expected a string"),
])
def test_bad_effusivity_fields_are_refused_naming_the_field(field, value, match):
    bad = {**golden_messages()["material_estimate.new"], field: value}
    with pytest.raises(Exception, match=match):
        encode(bad)
