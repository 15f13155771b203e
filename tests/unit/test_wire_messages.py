"""The typed messages (wire/messages.py, issue 26) over the codec: one class
per kind with the schema's fields in its order, the golden vectors' bytes
unchanged through them, and any valid message the same after parse."""

import copy
import dataclasses
from pathlib import Path

import pytest
from hypothesis import given as hypothesis_given, settings

from telethermal.errors import ProtocolError, UnknownKindError
from telethermal.wire import messages, schema
from telethermal.wire.codec import decode, encode, validate
from telethermal.wire.golden import messages as golden_messages

from test_wire_codec import valid_messages

PROTO = Path(__file__).resolve().parents[2] / "proto"
ENVELOPE = [f.name for f in schema.ENVELOPE]


@pytest.mark.parametrize("kind", sorted(schema.KINDS))
def test_each_class_holds_its_kinds_fields_in_the_schemas_order(kind):
    cls = messages.CLASSES[kind]
    assert cls.KIND == kind
    fields = dataclasses.fields(cls)
    assert [f.name for f in fields] == [f.name for f in schema.KINDS[kind].fields]
    for f, spec in zip(fields, schema.KINDS[kind].fields):
        # Required fields have no default; optional ones default to "not sent".
        assert (f.default is dataclasses.MISSING) == spec.required, f.name
        if not spec.required:
            assert f.default is messages.ABSENT


@pytest.mark.parametrize("name", sorted(golden_messages()))
def test_golden_vectors_are_the_same_bytes_through_the_typed_message(name):
    wire = (PROTO / "golden" / f"{name}.msgpack").read_bytes()
    decoded = decode(wire)
    typed = messages.parse(decoded)
    assert typed.kind == decoded["kind"]
    envelope = {k: decoded[k] for k in ENVELOPE}
    assert encode({**envelope, **typed.fields()}) == wire
    assert typed.to_dict() == {k: v for k, v in decoded.items() if k not in ENVELOPE[1:]}


@settings(max_examples=300, deadline=None)
@hypothesis_given(valid_messages())
def test_any_valid_message_is_the_same_after_parse(message):
    canonical, _ = validate(message)
    typed = messages.parse(canonical)
    envelope = {k: canonical[k] for k in ENVELOPE}
    assert {**envelope, **typed.fields()} == canonical
    # Absent optional fields stay absent (a nil is not a missing field).
    for f in dataclasses.fields(typed):
        assert (getattr(typed, f.name) is messages.ABSENT) == (f.name not in canonical)
    assert typed.lossless == (canonical["kind"] in schema.LOSSLESS)


def test_a_nil_and_a_missing_field_stay_apart():
    # The slave's thermometer refused (nil) vs a master's event (not sent).
    refused = messages.ContactEvent(contact_id=1, touching=True, t_s=0.0, force_n=1.0,
                                    object_temp_c=None)
    silent = messages.ContactEvent(contact_id=1, touching=True, t_s=0.0, force_n=1.0)
    assert refused.fields()["object_temp_c"] is None
    assert "object_temp_c" not in silent.fields()
    assert messages.given(silent.object_temp_c, 21.0) == 21.0
    assert messages.given(refused.object_temp_c, 21.0) is None
    assert not silent.names_object
    assert repr(messages.ABSENT) == "ABSENT" and copy.deepcopy(messages.ABSENT) is messages.ABSENT


def test_messages_are_frozen_and_parse_names_what_is_wrong():
    m = messages.FluxSetpoint(contact_id=1, t_since_contact_s=0.1, flux_w_m2=-500.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.flux_w_m2 = 0.0
    with pytest.raises(ProtocolError, match="flux_setpoint.flux_w_m2: missing"):
        messages.parse({"kind": "flux_setpoint", "contact_id": 1, "t_since_contact_s": 0.1})
    with pytest.raises(UnknownKindError, match="unknown message kind 'teleport'"):
        messages.parse({"kind": "teleport"})
    with pytest.raises(UnknownKindError, match="unknown message kind 'None'"):
        messages.parse({})
    # A field of a newer minor revision is left out, as the codec's readers do.
    newer = messages.parse({"kind": "flux_setpoint", "contact_id": 1, "t_since_contact_s": 0.1,
                            "flux_w_m2": 2.0, "colour": "red"})
    assert newer.fields() == {"contact_id": 1, "t_since_contact_s": 0.1, "flux_w_m2": 2.0}
