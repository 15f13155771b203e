"""Hypothesis against the decoders and a live socket.

* Differential: messages built from the document's tables and then broken
  at random; telethermal's codec must accept exactly what the document
  (as read by protocol_doc) accepts, and refuse the rest with its one error
  class, never with another exception.
* Live: the same broken messages sent to the running slave by a document
  master; after each batch the slave is alive and has counted every message
  the document calls bad exactly once, and nothing else.
"""

from __future__ import annotations

import math
import os

import msgpack
import pytest
import zmq
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import protocol_doc as doc
from conftest import HEARTBEAT_S
from doc_peer import DocMaster, pack

#: Bounded for the suite's time budget; raise them for a deeper run
#: (measured: 10,000 codec and 1,000 live examples found nothing more).
CODEC_EXAMPLES = int(os.environ.get("TELETHERMAL_FUZZ_CODEC", 300))
LIVE_EXAMPLES = int(os.environ.get("TELETHERMAL_FUZZ_LIVE", 40))
TEXT = st.text(st.characters(blacklist_categories=("Cs",)), max_size=12)
ANY = st.recursive(
    st.none() | st.booleans() | st.integers(-2 ** 63, 2 ** 64 - 1) | st.floats() | TEXT |
    st.binary(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(TEXT, inner, max_size=3),
    max_leaves=6)


def value_of(data, f: doc.DocField, n: int, name: str):
    t = f.type
    if f.nullable and data.draw(st.booleans()):
        return None
    if t == "str":
        return data.draw(TEXT)
    if t == "bool":
        return data.draw(st.booleans())
    if t == "uint":
        return data.draw(st.integers(int(max(f.lo, 0)), int(min(f.hi, 2 ** 64 - 1))))
    if t == "float":
        return data.draw(st.floats(None if math.isinf(f.lo) else f.lo,
                                   None if math.isinf(f.hi) else f.hi,
                                   allow_nan=False, allow_infinity=False))
    if t == "list[str]":
        return [data.draw(TEXT) for _ in range(n)]
    if t == "list[uint]":
        return data.draw(st.lists(st.integers(0, 3), max_size=3))
    if t == "list[float]":
        lo = 0.0 if math.isinf(f.lo) else f.lo
        hi = lo + 1.0 if math.isinf(f.hi) else f.hi
        values = [lo + (hi - lo) * i / n for i in range(n)]       # ascending, in range
        return values if name == "t_s" else data.draw(st.permutations(values))
    if t == "counters":
        return data.draw(st.dictionaries(TEXT, st.integers(0, 2 ** 64 - 1), max_size=3))
    if t == "curves":
        return {data.draw(TEXT): {"t_s": [0.1, 0.2], "g_w_m2k": [1.0, 2.0]}}
    raise AssertionError(t)


def message_of(data, kind: str, seq: int | None = None) -> dict:
    k = doc.KINDS[kind]
    n = data.draw(st.integers(2, 3))
    m = {"kind": kind, "v": 1, "seq": data.draw(st.integers(1, 1000)) if seq is None else seq,
         "sent_s": data.draw(st.floats(0, 1e6))}
    for f in k.fields.values():
        if f.required or data.draw(st.booleans()):
            m[f.name] = value_of(data, f, n, f.name)
    return m


def broken(data, m: dict, keep_envelope: bool = False) -> dict:
    """Up to two random changes: a field dropped, replaced by anything, added."""
    m = dict(m)
    fields = [k for k in m if not (keep_envelope and k in ("kind", "seq"))]
    for _ in range(data.draw(st.integers(0, 2))):
        what = data.draw(st.sampled_from(("drop", "replace", "add")))
        name = data.draw(st.sampled_from(fields))
        if what == "drop" and name in m:
            del m[name]
        elif what == "replace":
            m[name] = data.draw(ANY)
        else:
            m[data.draw(TEXT)] = data.draw(ANY)
    return m


def doc_accepts(m) -> bool:
    return not [e for e in doc.deviations(m) if "fields not in the document" not in e]


@settings(max_examples=CODEC_EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_the_codec_accepts_exactly_what_the_document_accepts(data):
    from telethermal.errors import ProtocolError
    from telethermal.wire.codec import decode

    m = broken(data, message_of(data, data.draw(st.sampled_from(sorted(doc.KINDS)))))
    try:
        raw = pack(m)
    except (ValueError, TypeError, OverflowError):
        return                                  # not even msgpack: nothing to send
    try:
        decoded = decode(raw)
    except ProtocolError as exc:
        assert not doc_accepts(m), f"the codec refused what the document allows: {exc}"
        return
    assert doc_accepts(m), f"the codec accepted what the document refuses: " \
                           f"{doc.deviations(m)}"
    assert decoded["kind"] == m["kind"]


@settings(max_examples=300, deadline=None)
@given(ANY)
def test_the_document_reader_itself_never_crashes(value):
    assert isinstance(doc.deviations(value), list)


# ---------------------------------------------------------------- live
ERRORS = ("invalid", "unknown_kind", "oversized", "before_hello", "version_mismatch",
          "not_peer", "wrong_direction", "out_of_window", "skipped", "resend_throttled",
          "duplicates", "contact_ignored")
# What a master may send that leaves the pad alone: heartbeats, status and
# faults (the lossless ones take the master's next seq, so a good one is
# delivered and a bad one uses its seq up), and kinds nobody knows.
LIVE_KINDS = ("heartbeat", "status", "fault")


@pytest.fixture(scope="module")
def live(slave, curve_keys):
    ctx = zmq.Context()
    m = DocMaster(ctx, slave.control, slave.stream, curve_keys["a"], heartbeat_s=HEARTBEAT_S)
    m.connect()
    m.answer_resend = False
    yield m
    m.close()
    ctx.destroy(linger=0)


@settings(max_examples=LIVE_EXAMPLES, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.data())
def test_a_live_slave_counts_every_bad_message_once(slave, live, data):
    m = live
    batch = [_draw_one(data) for _ in range(data.draw(st.integers(1, 5)))]
    # Everything drawn first: hypothesis may stop an example at any draw, and
    # a lossless seq taken but never sent would open a gap in the session.
    before = slave.counters()
    bad = 0
    for kind, message, raw in batch:
        if message is not None and kind in doc.KINDS and doc.KINDS[kind].lossless:
            message["seq"] = m.envelope(kind, True)["seq"]
            raw = pack(message)
        bad += not doc_accepts(message) if message is not None else 1
        m.send_raw(raw)
    m.sync()
    assert slave.alive
    after = slave.counters()
    moved = {k: after[k] - before[k] for k in ERRORS if after[k] != before[k]}
    assert sum(moved.values()) == bad, moved


def _draw_one(data) -> tuple[str, dict | None, bytes]:
    """(kind, message or None for junk, its bytes)."""
    kind = data.draw(st.sampled_from(LIVE_KINDS + ("no-such-kind",)))
    if kind == "no-such-kind":
        name = data.draw(TEXT.filter(lambda k: k not in doc.KINDS))
        message = {"kind": name, "v": 1, "seq": data.draw(st.integers(1, 1000)),
                   "sent_s": 1.0, "x": data.draw(ANY)}
    else:
        lossless = doc.KINDS[kind].lossless
        message = broken(data, message_of(data, kind, 1), keep_envelope=lossless)
    try:
        return kind, message, pack(message)
    except (ValueError, TypeError, OverflowError):       # not even msgpack
        if doc.KINDS.get(kind) is not None and doc.KINDS[kind].lossless:
            # Its seq will be taken: a bad message that uses it up instead.
            message = {"kind": kind, "v": 1, "seq": 1, "sent_s": "?"}
            return kind, message, pack(message)
        raw = data.draw(st.binary(max_size=64).filter(lambda b: not _readable(b)))
        return kind, None, raw


def _readable(raw: bytes) -> bool:
    try:
        value = msgpack.unpackb(raw, raw=False)
    except Exception:                                   # noqa: BLE001 - junk
        return False
    return isinstance(value, dict) and value.get("kind") in doc.KINDS
