"""Recordings that survive a crash (issue 47): chunks with CRCs flushed
while the process runs, so a ``kill -9`` loses only what came after the
last flush; a damaged chunk or record is skipped, counted and named, the
rest read; the ``mcap`` library's own readers open the files, cut or whole."""

from __future__ import annotations

import io
import signal
import subprocess
import sys
import textwrap
from types import SimpleNamespace

import msgpack
import numpy as np
import pytest
from mcap.reader import NonSeekingReader, make_reader

from telethermal.record.recorder import SessionRecorder
from telethermal.record.recording import Recorder, read_recording

N_CHUNKS, PER_CHUNK = 6, 10


def _write(path, bad_at: int | None = None):
    """N_CHUNKS chunks of PER_CHUNK messages ``{"i": i}`` on /t (each chunk
    closed by ``sync``); message ``bad_at`` is bytes that do not unpack."""
    rec = Recorder(path, "session", {"x": 1})
    for c in range(N_CHUNKS):
        for j in range(PER_CHUNK):
            i = c * PER_CHUNK + j
            if i == bad_at:
                assert rec.sync()
                rec._writer.add_message(rec._channel("/t"), i, b"\xc1\xc1", i)
            else:
                rec.log("/t", i * 1e-9, {"i": i})
        assert rec.sync()
    rec.close()
    return path


def _ids(path) -> list[int]:
    return [m["i"] for m in read_recording(path).messages("/t")]


def _chunk_offsets(data: bytes) -> list[int]:
    out, at = [], 8
    while at < len(data) - 8 and data[at] != 0x02:
        length = int.from_bytes(data[at + 1:at + 9], "little")
        if data[at] == 0x06:
            out.append(at)
        at += 9 + length
    return out


def _library_messages(data: bytes, seeking: bool) -> list[int]:
    """What the mcap library reads: ``make_reader`` (whole files), or its
    non-seeking reader in file order up to a cut."""
    out = []
    reader = make_reader(io.BytesIO(data)) if seeking else NonSeekingReader(io.BytesIO(data))
    try:
        for _, channel, message in reader.iter_messages(log_time_order=False):
            if channel.topic == "/t":
                out.append(msgpack.unpackb(message.data)["i"])
    except Exception:                          # noqa: BLE001 - the cut
        if seeking:
            raise
    return out


def test_a_whole_recording_is_read_by_ours_and_by_both_mcap_readers(tmp_path):
    path = _write(tmp_path / "whole.mcap")
    data = path.read_bytes()
    assert len(_chunk_offsets(data)) >= N_CHUNKS
    everything = list(range(N_CHUNKS * PER_CHUNK))
    assert _ids(path) == everything
    assert _library_messages(data, seeking=True) == everything
    assert _library_messages(data, seeking=False) == everything
    assert read_recording(path).damaged is None


@pytest.mark.parametrize("into", [0.0, 0.5, 0.99])
def test_a_truncated_chunk_is_read_up_to_the_last_whole_chunk(tmp_path, into):
    data = _write(tmp_path / "w.mcap").read_bytes()
    chunks = _chunk_offsets(data)
    k = 3
    start = chunks[k]
    end = start + 9 + int.from_bytes(data[start + 1:start + 9], "little")   # the chunk's own
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:start + 1 + int((end - start - 1) * into)])
    before = list(range(k * PER_CHUNK))
    rec = read_recording(cut)
    assert [m["i"] for m in rec.messages("/t")] == before and rec.truncated
    assert _library_messages(cut.read_bytes(), seeking=False) == before


def test_a_flipped_byte_in_a_chunk_fails_its_crc_and_is_reported_the_rest_read(tmp_path):
    data = bytearray(_write(tmp_path / "w.mcap").read_bytes())
    chunks = _chunk_offsets(bytes(data))
    k = 2
    data[chunks[k] + 9 + (chunks[k + 1] - chunks[k]) // 4] ^= 0x10   # inside its records
    bad = tmp_path / "flip.mcap"
    bad.write_bytes(bytes(data))
    rec = read_recording(bad)
    expected = [i for i in range(N_CHUNKS * PER_CHUNK) if i // PER_CHUNK != k]
    assert [m["i"] for m in rec.messages("/t")] == expected
    assert len(rec.damage.corrupt_chunks) == 1 and "CRC mismatch" in rec.damaged


def test_a_broken_record_header_is_skipped_to_the_next_good_chunk(tmp_path):
    data = bytearray(_write(tmp_path / "w.mcap").read_bytes())
    chunks = _chunk_offsets(bytes(data))
    k = 1
    data[chunks[k] + 6] ^= 0x7F                           # its length: now petabytes
    bad = tmp_path / "len.mcap"
    bad.write_bytes(bytes(data))
    rec = read_recording(bad)
    ids = [m["i"] for m in rec.messages("/t")]
    assert ids[:PER_CHUNK] == list(range(PER_CHUNK))
    assert ids[PER_CHUNK:] == list(range((k + 1) * PER_CHUNK, N_CHUNKS * PER_CHUNK))
    assert rec.damage.skipped_bytes > 0 and "unreadable bytes" in rec.damaged


def test_one_message_that_does_not_unpack_is_counted_the_rest_read(tmp_path):
    path = _write(tmp_path / "bad.mcap", bad_at=25)
    rec = read_recording(path)
    assert [m["i"] for m in rec.messages("/t")] == [i for i in range(60) if i != 25]
    assert rec.bad_messages == 1 and "did not unpack" in rec.damaged


CHILD = textwrap.dedent("""
    import sys, time
    from telethermal.record.recording import Recorder
    rec = Recorder(sys.argv[1], "slave", {})
    for i in range(200):
        rec.log("/t", i * 1e-3, {"i": i})
    assert rec.sync()
    print("synced", flush=True)
    for i in range(200, 260):
        rec.log("/t", i * 1e-3, {"i": i})
    time.sleep(600)
""")


def test_kill_9_loses_nothing_flushed(tmp_path):
    # Killed after a sync (what the writer does every FLUSH_S by itself):
    # every message queued before it is in the file, for us and for mcap.
    path = tmp_path / "killed.mcap"
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE,
                             text=True)
    try:
        assert child.stdout.readline().strip() == "synced"
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
        child.stdout.close()
    ids = _ids(path)
    assert ids[:200] == list(range(200)) and len(ids) <= 260
    assert _library_messages(path.read_bytes(), seeking=False)[:200] == list(range(200))


def _pad(n: int, rate_hz: float = 1000.0):
    t = np.arange(400) / rate_hz
    return SimpleNamespace(channels={"t_s": t, "heat_flux_W_m2": -t}, samples_read=n,
                           events=[], object_ir_c=22.0, object_true_c=22.1,
                           pad_before_c=34.0, gap_k=12.0)


def test_the_slave_streams_its_samples_and_a_cut_contact_keeps_them(tmp_path):
    path = tmp_path / "slave.mcap"
    rec = SessionRecorder(Recorder(path, "slave", {}))
    pad = _pad(0)
    for n in range(0, 301, 7):                        # samples read as the touch goes on
        pad.samples_read = n
        rec.slave_stream(pad, contact_id=4)
    assert rec.rec.sync()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes())                # the file as a kill -9 leaves it
    pad.samples_read = 350
    rec.slave(pad, contact_id=4)                      # the lift: the rest and the end
    rec.close()
    whole = read_recording(path).messages("/slave/samples")
    assert len(whole) == 1 and whole[0]["t_s"] == list(pad.channels["t_s"][:350])
    assert whole[0]["gap_k"] == 12.0 and whole[0]["contact_id"] == 4
    part = read_recording(cut)
    got = part.messages("/slave/samples")[0]["t_s"]
    # Batches of 20 ms at 1 kHz: all but the last (unfinished) batch's.
    assert got == list(pad.channels["t_s"][:len(got)]) and 280 <= len(got) <= 301
    assert any("cut mid-touch" in n for n in part.notes)
