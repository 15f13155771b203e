"""The sensor board's frames and the reader's bad-input handling: garbage
between frames, frames split across reads, CRC errors, another version,
sequence gaps, reboots; the calibration's conversions against the NIST
polynomials."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from telethermal.devices.board import Calibration, DeviceError
from telethermal.devices.frames import (FRAME_VERSION_SLAVE, MAX_FRAME_BYTES, TYPE_BOOT, BoardFrame,
                                       FrameError, FrameReader, crc16, decode, encode)
from telethermal.physics.sensors import type_t_emf_mv

f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
frames = st.builds(BoardFrame, seq=st.integers(0, 0xFFFF), t_us=st.integers(0, 2**32 - 1),
                   flux_uv=f32, tc_uv=f32, cj_c=f32, force_n=f32, status=st.integers(0, 7))


def test_crc_is_ccitt_false():
    assert crc16(b"123456789") == 0x29B1          # the catalogue's check value


@given(frames)
def test_a_frame_round_trips_and_holds_no_zero_byte_before_its_delimiter(frame):
    wire = encode(frame)
    assert wire.endswith(b"\x00") and b"\x00" not in wire[:-1]
    assert decode(wire[:-1]) == frame


@settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(frames, min_size=1, max_size=8), st.lists(st.binary(max_size=40), max_size=8),
       st.data())
def test_garbage_between_frames_and_any_split_lose_no_good_frame(good, junk, data):
    # Frames with garbage between them, cut into reads at arbitrary places:
    # every frame comes out, in order; the garbage is counted, never raised.
    good = [BoardFrame(i, f.t_us, f.flux_uv, f.tc_uv, f.cj_c, f.force_n, f.status)
            for i, f in enumerate(good)]
    stream = b""
    for i, f in enumerate(good):
        # Garbage ends with a delimiter (as a resyncing board sends), or the
        # garbage and the next frame would be one bad packet.
        stream += (junk[i] + b"\x00" if i < len(junk) else b"") + encode(f)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    reader, out, last = FrameReader(), [], 0
    for c in cuts + [len(stream)]:
        out += reader.feed(stream[last:c])
        last = c
    assert out == good
    assert reader.counters["frames"] == len(good)
    assert reader.counters["seq_gaps"] == 0


def test_each_bad_frame_is_counted_by_kind_and_the_next_good_one_read():
    reader = FrameReader()
    good = [BoardFrame(i, 1000 * i, 100.0, 50.0, 25.0, 3.0) for i in range(6)]
    flipped = bytearray(encode(good[1]))
    flipped[5] ^= 0x10
    other_version = BoardFrame(2, 0, 0, 0, 0, 0, 7, version=FRAME_VERSION_SLAVE + 1)
    assert encode(other_version)                   # encodable, but not ours
    stream = encode(good[0]) + bytes(flipped) + encode(other_version) + b"\x13\x37\x00" + \
        encode(good[3]) + encode(good[5])
    out = reader.feed(stream)
    assert [f.seq for f in out] == [0, 3, 5]
    c = reader.counters
    assert c["crc"] == 1 and c["version"] == 1 and c["garbage"] == 1
    assert c["seq_gaps"] == 2 and c["lost_frames"] == 3        # 1, 2 lost; 4 lost
    assert "sequence gap" in reader.last_error
    with pytest.raises(FrameError, match="version 3"):
        decode(encode(other_version)[:-1])


def test_a_reboot_restarts_the_sequence_without_a_gap_and_overlong_junk_is_dropped():
    reader = FrameReader()
    out = reader.feed(encode(BoardFrame(41, 0, 0, 0, 0, 0)) +
                      encode(BoardFrame(0, 0, 0, 0, 25.0, 0, 0, TYPE_BOOT)) +
                      encode(BoardFrame(1, 0, 0, 0, 0, 0)))
    assert [f.seq for f in out] == [41, 0, 1]
    assert reader.counters["boots"] == 1 and reader.counters["seq_gaps"] == 0
    reader.feed(b"\x01" * (MAX_FRAME_BYTES + 1))
    assert reader.counters["overlong"] == 1
    assert reader.feed(encode(BoardFrame(2, 0, 0, 0, 0, 0)))[0].seq == 2


@pytest.mark.parametrize("temp_c", [-20.0, 0.0, 12.5, 33.0, 45.0, 90.0])
@pytest.mark.parametrize("cj_c", [0.0, 22.0, 31.0])
def test_thermocouple_conversion_inverts_the_nist_emf_within_its_stated_error(temp_c, cj_c):
    # NIST's inverse polynomials are stated to +-0.04 C over their range.
    cal = Calibration()
    uv = cal.tc_uv(temp_c, cj_c)
    assert uv == pytest.approx(1000 * (type_t_emf_mv(temp_c) - type_t_emf_mv(cj_c)))
    assert cal.temp_c(uv, cj_c) == pytest.approx(temp_c, abs=0.04)


def test_flux_is_1_26_uv_per_w_m2_unless_a_calibration_file_says_otherwise(tmp_path):
    assert Calibration().flux_w_m2(126.0) == pytest.approx(100.0)
    path = tmp_path / "cal.toml"
    path.write_text("[heat_flux]\nsensitivity_uv_per_w_m2 = 2.0\noffset_uv = 1.0\n")
    assert Calibration.load(path).flux_w_m2(201.0) == pytest.approx(100.0)
    path.write_text("[heat_flux]\nsensitivity_uv_per_w_m2 = -2.0\n")
    with pytest.raises(DeviceError, match="sensitivity must be > 0"):
        Calibration.load(path)
    path.write_text("[heat_flux]\ngain = 2.0\n")
    with pytest.raises(DeviceError, match=r"unknown key heat_flux\.gain"):
        Calibration.load(path)
    path.write_text("[thermocouple]\noffset_uv = 'x'\n")
    with pytest.raises(DeviceError, match=r"thermocouple\.offset_uv must be a number"):
        Calibration.load(path)


def test_shipped_calibration_file_loads():
    from pathlib import Path
    cal = Calibration.load(Path(__file__).parents[2] / "deploy/hardware/calibration.toml")
    assert np.isclose(cal.flux_sensitivity_uv_per_w_m2, 1.26)
