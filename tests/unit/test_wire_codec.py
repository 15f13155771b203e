"""The wire codec: golden vectors both ways, the spec's tables, fuzzing."""

import json
import math
from pathlib import Path

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.errors import ProtocolError
from telethermal.wire import schema
from telethermal.wire.codec import decode, decode_verbose, encode
from telethermal.wire.golden import messages

PROTO = Path(__file__).resolve().parents[2] / "proto"


@pytest.mark.parametrize("name", sorted(messages()))
def test_golden_vectors_both_ways(name):
    wire = (PROTO / "golden" / f"{name}.msgpack").read_bytes()
    value = json.loads((PROTO / "golden" / f"{name}.json").read_text())
    assert decode(wire) == value
    assert encode(value) == wire


def test_every_kind_has_a_golden_vector_and_the_examples_are_the_files():
    assert {m["kind"] for m in messages().values()} == set(schema.KINDS)
    assert {p.name[:-len(".msgpack")] for p in (PROTO / "golden").glob("*.msgpack")} == \
        set(messages())
    for name, message in messages().items():
        assert json.loads((PROTO / "golden" / f"{name}.json").read_text()) == message


def test_the_object_announcement_vector_carries_the_object_memory():
    announcement = messages()["contact_event.object"]
    assert announcement["contact_id"] == 0 and not announcement["touching"]
    assert {"object_id", "object_material", "object_confidence"} <= set(announcement)
    estimate, decision = messages()["posterior_estimate"], messages()["material_estimate"]
    assert set(estimate) == set(decision)            # the same fields, another stream
    assert schema.KINDS["posterior_estimate"].stream == "stream"
    assert "posterior_estimate" not in schema.LOSSLESS


def test_the_protocol_document_holds_the_codecs_tables():
    text = (PROTO / "PROTOCOL.md").read_text()
    begin, end = "<!-- generated tables: begin -->\n", "<!-- generated tables: end -->"
    assert text[text.index(begin) + len(begin):text.index(end)] == schema.field_tables()


# ------------------------------------------------------------------ errors
def example(of="material_estimate", **changes):
    message = dict(messages()[of])
    message.update(changes)
    return message


@pytest.mark.parametrize("changes, match", [
    ({"confidence": math.nan}, "material_estimate.confidence: nan"),
    ({"confidence": 1.5}, r"material_estimate.confidence: 1.5 outside"),
    ({"decided": 1}, "material_estimate.decided: expected true or false"),
    ({"contact_id": -1}, "material_estimate.contact_id: expected an unsigned"),
    ({"classes": "steel"}, "material_estimate.classes: expected an array"),
    ({"posteriors": [0.5]}, "classes and posteriors differ"),
    ({"v": 2}, "protocol version 2"),
    ({"kind": "teleport"}, "unknown message kind 'teleport'"),
])
def test_bad_messages_name_the_kind_and_field(changes, match):
    with pytest.raises(ProtocolError, match=match):
        encode(example(**changes))
    raw = msgpack.packb(example(**changes), use_bin_type=True)
    with pytest.raises(ProtocolError, match=match):
        decode(raw)


def test_missing_field_unknown_field_and_size_limit():
    message = example()
    del message["label"]
    with pytest.raises(ProtocolError, match="material_estimate.label: missing"):
        encode(message)
    newer = example(extra_field_from_v1_1=3)
    with pytest.raises(ProtocolError, match="not in protocol version 1"):
        encode(newer)                                          # we never send them
    value, ignored = decode_verbose(msgpack.packb(newer, use_bin_type=True))
    assert ignored == ["extra_field_from_v1_1"] and value == example()   # but read past them
    curve = {"t_s": [float(i) for i in range(8000)], "g_w_m2k": [0.5] * 8000}
    big = example("session_config", curves={m: curve for m in ("a", "b", "c")})
    with pytest.raises(ProtocolError, match="bytes >"):
        encode(big)
    with pytest.raises(ProtocolError, match="not a msgpack message|a message is a map"):
        decode(b"\xc1\x00")


def test_trajectories_must_ascend():
    with pytest.raises(ProtocolError, match="ascending"):
        encode(example("flux_trajectory", t_s=[0.0, 0.5, 0.5]))


# ------------------------------------------------------------------ fuzzing
_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


def _strategy(f: schema.Field):
    lo = None if f.lo == -math.inf else f.lo
    hi = None if f.hi == math.inf else f.hi
    text = st.text(max_size=20)
    base = {
        "str": text, "bool": st.booleans(),
        "uint": st.integers(int(lo or 0), int(hi) if hi is not None else 2 ** 64 - 1),
        "float": st.floats(lo, hi, allow_nan=False, allow_infinity=False),
        "list[str]": st.lists(text, max_size=5),
        "list[uint]": st.lists(st.integers(0, 2 ** 64 - 1), max_size=5),
        "list[float]": st.lists(st.floats(lo, hi, allow_nan=False, allow_infinity=False),
                                max_size=5),
        "counters": st.dictionaries(text, st.integers(0, 2 ** 40), max_size=4),
        "curves": st.dictionaries(text, st.integers(2, 6).flatmap(lambda n: st.tuples(
            st.lists(st.floats(0, 1e3, allow_nan=False), min_size=n, max_size=n, unique=True),
            st.lists(_finite, min_size=n, max_size=n))).map(
            lambda p: {"t_s": sorted(p[0]), "g_w_m2k": p[1]}), max_size=3),
    }[f.type]
    return st.one_of(st.none(), base) if f.nullable else base


@st.composite
def valid_messages(draw, kind=None, every_field=False):
    """A schema-valid message (of ``kind``; with ``every_field``, its
    optional fields too)."""
    kind = kind or draw(st.sampled_from(sorted(schema.KINDS)))
    message = {"kind": kind, "v": 1, "seq": draw(st.integers(0, 2 ** 64 - 1)),
               "sent_s": draw(_finite)}
    for f in schema.KINDS[kind].fields:
        if f.required or every_field or draw(st.booleans()):
            message[f.name] = draw(_strategy(f))
    if kind in ("material_estimate", "posterior_estimate"):
        message["posteriors"] = message["posteriors"][:len(message["classes"])]
        message["classes"] = message["classes"][:len(message["posteriors"])]
    if kind == "flux_trajectory":
        n = min(len(message["t_s"]), len(message["g_w_m2k"]))
        message["t_s"] = [float(i) for i in range(max(n, 2))]
        message["g_w_m2k"] = (message["g_w_m2k"] + [0.0, 0.0])[:max(n, 2)]
    if kind == "measurement_batch":
        n = min(len(message[c]) for c in ("flux_w_m2", "temp_c", "force_n"))
        for c in ("flux_w_m2", "temp_c", "force_n"):
            message[c] = message[c][:n]
    return message


@settings(max_examples=300, deadline=None)
@given(valid_messages())
def test_any_valid_message_round_trips(message):
    try:
        wire = encode(message)
    except ProtocolError as exc:
        # Only the size limit may refuse a schema-valid message.
        assert "bytes >" in str(exc)
        return
    back = decode(wire)
    assert encode(back) == wire
    for key, value in message.items():
        assert back[key] == value


@settings(max_examples=200, deadline=None)
@given(st.one_of(valid_messages("posterior_estimate"),
                 valid_messages("contact_event", every_field=True)))
def test_estimates_and_object_memory_fields_round_trip(message):
    wire = encode(message)
    back = decode(wire)
    assert back == message and encode(back) == wire
    if message["kind"] == "posterior_estimate":
        with pytest.raises(ProtocolError, match="posterior_estimate: classes and posteriors"):
            encode({**message, "posteriors": message["posteriors"] + [0.5]})


def test_an_old_reader_skips_the_object_memory_fields():
    # A reader of the revision before object memory: contact_event without
    # the three fields. It ignores them (section 3) and reads the rest.
    import dataclasses
    from unittest import mock

    from telethermal.wire import codec
    event = schema.KINDS["contact_event"]
    old = dataclasses.replace(event, fields=tuple(
        f for f in event.fields if f.name not in ("object_id", "object_material",
                                                  "object_confidence")))
    wire = encode(messages()["contact_event.object"])
    with mock.patch.dict(schema.KINDS, {"contact_event": old}), \
            mock.patch.dict(codec._NAMES, {"contact_event": {
                f.name for f in schema.ENVELOPE + old.fields}}):
        value, ignored = decode_verbose(wire)
    assert sorted(ignored) == ["object_confidence", "object_id", "object_material"]
    assert value["object_temp_c"] == 23.75 and "object_id" not in value


@settings(max_examples=500, deadline=None)
@given(st.binary(max_size=300))
def test_garbage_is_a_protocol_error_never_a_crash(data):
    try:
        decode(data)
    except ProtocolError:
        pass


@settings(max_examples=300, deadline=None)
@given(valid_messages(), st.data())
def test_flipping_a_byte_never_crashes_the_decoder(message, data):
    try:
        wire = bytearray(encode(message))
    except ProtocolError:
        return
    i = data.draw(st.integers(0, len(wire) - 1))
    wire[i] ^= data.draw(st.integers(1, 255))
    try:
        decode(bytes(wire))
    except ProtocolError:
        pass
