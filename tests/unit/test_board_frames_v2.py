"""Frame version 2 (the slave's board: IR thermometer, active pad state):
round trip, mixed with version 1 and garbage, met by a reader of version 1
(skipped and counted), and the driver's IR checks (flagged, out of range)."""

import math

import pytest
from cobs import cobs
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.devices.board import IR_OBJECT_RANGE_C, SensorBoard
from telethermal.devices.frames import (FRAME_VERSION_SLAVE, RECORD_BYTES, RECORD_BYTES_V2,
                                        STATUS_ALL, STATUS_HEATER, STATUS_IR, STATUS_PUMP,
                                        BoardFrame, FrameReader, decode, encode)

f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)


def v2(seq, ir_object_c=30.0, ir_ambient_c=25.0, status=STATUS_ALL | STATUS_IR, **kw):
    return BoardFrame(seq, 1000 * seq, kw.get("flux_uv", 12.0), kw.get("tc_uv", 250.0), 24.0,
                      kw.get("force_n", 0.0), status, version=FRAME_VERSION_SLAVE,
                      ir_object_c=ir_object_c, ir_ambient_c=ir_ambient_c,
                      pad_drive=kw.get("pad_drive", 0.25))


frames_v2 = st.builds(BoardFrame, seq=st.integers(0, 0xFFFF), t_us=st.integers(0, 2**32 - 1),
                      flux_uv=f32, tc_uv=f32, cj_c=f32, force_n=f32,
                      status=st.integers(0, 63), version=st.just(FRAME_VERSION_SLAVE),
                      ir_object_c=f32, ir_ambient_c=f32, pad_drive=f32)


@given(frames_v2)
def test_a_version_2_frame_round_trips_without_a_zero_byte_before_its_delimiter(frame):
    wire = encode(frame)
    assert wire.endswith(b"\x00") and b"\x00" not in wire[:-1]
    assert len(cobs.decode(wire[:-1])) == RECORD_BYTES_V2
    assert decode(wire[:-1]) == frame


@settings(max_examples=200)
@given(st.lists(st.tuples(st.booleans(), frames_v2), min_size=1, max_size=10),
       st.lists(st.binary(max_size=50), max_size=10), st.data())
def test_versions_mixed_with_garbage_and_any_split_come_out_in_order(picks, junk, data):
    good = []
    for i, (is_v1, f) in enumerate(picks):
        good.append(BoardFrame(i, f.t_us, f.flux_uv, f.tc_uv, f.cj_c, f.force_n, f.status & 7)
                    if is_v1 else BoardFrame(i, f.t_us, f.flux_uv, f.tc_uv, f.cj_c, f.force_n,
                                             f.status, version=2, ir_object_c=f.ir_object_c,
                                             ir_ambient_c=f.ir_ambient_c, pad_drive=f.pad_drive))
    stream = b"".join((junk[i] + b"\x00" if i < len(junk) else b"") + encode(f)
                      for i, f in enumerate(good))
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    reader, out, last = FrameReader(), [], 0
    for c in cuts + [len(stream)]:
        out += reader.feed(stream[last:c])
        last = c
    assert out == good
    c = reader.counters
    assert c["frames_v1"] == sum(f.version == 1 for f in good)
    assert c["frames_v2"] == sum(f.version == 2 for f in good)
    assert c["seq_gaps"] == 0


@given(st.lists(st.booleans(), min_size=1, max_size=20))
def test_a_version_1_reader_skips_and_counts_every_version_2_frame(is_v2):
    # The driver restricted to version 1 (as a display's board reader is):
    # version-2 frames are skipped, counted in 'version' (their sequence
    # numbers then show as lost), and the version-1 frames around them read.
    frames = [v2(i) if new else BoardFrame(i, 1000 * i, 1.0, 2.0, 24.0, 0.0)
              for i, new in enumerate(is_v2)]
    reader = FrameReader(versions=(1,))
    out = reader.feed(b"".join(encode(f) for f in frames))
    assert [f.seq for f in out] == [f.seq for f in frames if f.version == 1]
    assert reader.counters["version"] == sum(is_v2)
    assert reader.counters["frames_v2"] == 0
    v1_at = [i for i, new in enumerate(is_v2) if not new]
    between = sum(is_v2[v1_at[0]:v1_at[-1]]) if v1_at else 0
    assert reader.counters["lost_frames"] == between
    # A reader written to version 1 of SERIAL.md alone (27-byte records:
    # anything else is 'garbage') skips it by its length, too.
    assert RECORD_BYTES_V2 != RECORD_BYTES


def _board_with(frames) -> SensorBoard:
    board = SensorBoard("loop://", clock=lambda: 0.0, keep=True)
    board._ser.write(b"".join(encode(f) for f in frames))
    board.poll()
    return board


def test_the_driver_reads_ir_and_pad_state_and_counts_what_it_cannot_use():
    lo, hi = IR_OBJECT_RANGE_C
    board = _board_with([
        v2(0, status=STATUS_ALL | STATUS_IR | STATUS_HEATER | STATUS_PUMP),
        v2(1, status=STATUS_ALL),                        # IR flagged by the board
        v2(2, ir_object_c=hi + 50.0),                    # beyond what the sensor reports
        v2(3, ir_object_c=lo - 1.0),
        v2(4, ir_ambient_c=float("nan")),
        v2(5, ir_object_c=31.5)])
    r = board.take_readings()
    assert len(r) == 6
    assert (r[0].ir_object_c, r[0].ir_ambient_c) == (30.0, 25.0)
    assert r[0].heater_on and r[0].pump_on and r[0].pad_drive == pytest.approx(0.25)
    assert all(math.isnan(x.ir_object_c) for x in r[1:5])
    assert not r[1].heater_on
    assert r[5].ir_object_c == 31.5
    assert board.all_counters["ir_flagged"] == 1
    assert board.all_counters["ir_out_of_range"] == 3
    assert board.all_counters["frames_v2"] == 6
    assert board.take_readings() == []
    board.close()


def test_a_version_1_frame_has_no_ir():
    board = _board_with([BoardFrame(0, 0, 1.26, 0.0, 24.0, 1.0)])
    r = board.take_readings()[0]
    assert r.version == 1 and math.isnan(r.ir_object_c) and r.flux_w_m2 == pytest.approx(1.0)
    board.close()
