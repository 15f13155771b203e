"""The sensor board's serial frames (``proto/SERIAL.md``).

One frame per sample: a fixed 27-byte record, COBS-encoded and ended by a
0x00 byte, so a reader that starts mid-stream or meets garbage
resynchronises at the next 0x00. Record (little-endian)::

    0  u8   version       FRAME_VERSION
    1  u8   type          1 sample, 2 boot (the board restarted; seq from 0)
    2  u16  seq           per frame, wraps at 65536
    4  u32  t_us          the board's clock, wraps
    8  f32  flux_uv       heat-flux sensor output, microvolts
    12 f32  tc_uv         thermocouple output, microvolts (type T)
    16 f32  cj_c          the thermocouple's cold-junction temperature, degC
    20 f32  force_n       force on the pad, N
    24 u8   status        bit 0 flux ADC ok, bit 1 thermocouple ok, bit 2 force ok
    25 u16  crc           CRC-16/CCITT-FALSE of bytes 0..24

COBS by the ``cobs`` package; the CRC is the standard library's
``binascii.crc_hqx`` (CCITT polynomial 0x1021) started at 0xFFFF.
"""

from __future__ import annotations

import binascii
import logging
import struct
from dataclasses import dataclass

from cobs import cobs

from telethermal.errors import TelethermalError

log = logging.getLogger(__name__)

FRAME_VERSION = 1
TYPE_SAMPLE, TYPE_BOOT = 1, 2
_RECORD = struct.Struct("<BBHIffffB")
RECORD_BYTES = _RECORD.size + 2            # + CRC
#: A run of this many bytes without a 0x00 is garbage: dropped, counted.
MAX_FRAME_BYTES = 64
STATUS_FLUX, STATUS_TC, STATUS_FORCE = 1, 2, 4
STATUS_ALL = STATUS_FLUX | STATUS_TC | STATUS_FORCE


class FrameError(TelethermalError, ValueError):
    """A frame that cannot be used; ``kind`` names the counter it goes to."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True, slots=True)
class BoardFrame:
    seq: int
    t_us: int
    flux_uv: float
    tc_uv: float
    cj_c: float
    force_n: float
    status: int = STATUS_ALL
    type: int = TYPE_SAMPLE
    version: int = FRAME_VERSION


def crc16(data: bytes) -> int:
    return binascii.crc_hqx(data, 0xFFFF)


def encode(frame: BoardFrame) -> bytes:
    """The bytes on the wire, delimiter included."""
    record = _RECORD.pack(frame.version, frame.type, frame.seq & 0xFFFF,
                          frame.t_us & 0xFFFFFFFF, frame.flux_uv, frame.tc_uv, frame.cj_c,
                          frame.force_n, frame.status)
    return cobs.encode(record + struct.pack("<H", crc16(record))) + b"\x00"


def decode(packet: bytes) -> BoardFrame:
    """One COBS packet (no delimiter) to a frame; :class:`FrameError` says why not."""
    try:
        raw = cobs.decode(packet)
    except cobs.DecodeError as exc:
        raise FrameError("garbage", f"not a COBS packet ({exc}); {len(packet)} bytes") from None
    if len(raw) != RECORD_BYTES:
        raise FrameError("garbage", f"a frame is {RECORD_BYTES} bytes, got {len(raw)}")
    record, (crc,) = raw[:-2], struct.unpack("<H", raw[-2:])
    if crc16(record) != crc:
        raise FrameError("crc", f"CRC mismatch: frame says {crc:#06x}, bytes give "
                                f"{crc16(record):#06x}")
    fields = _RECORD.unpack(record)
    if fields[0] != FRAME_VERSION:
        raise FrameError("version", f"frame version {fields[0]}, this driver speaks "
                                    f"{FRAME_VERSION}")
    if fields[1] not in (TYPE_SAMPLE, TYPE_BOOT):
        raise FrameError("garbage", f"unknown frame type {fields[1]}")
    version, kind, seq, t_us, flux, tc, cj, force, status = fields
    return BoardFrame(seq, t_us, flux, tc, cj, force, status, kind, version)


COUNTERS = ("frames", "garbage", "crc", "version", "seq_gaps", "lost_frames", "boots",
            "overlong")


class FrameReader:
    """Bytes in, frames out, whatever the bytes: split across reads, garbage
    between frames, bad CRCs, other versions, sequence gaps. Each problem is
    counted (``counters``), logged once per kind and skipped; the reader
    resynchronises at the next 0x00 by construction."""

    def __init__(self):
        self._buffer = bytearray()
        self._next_seq: int | None = None
        self.counters = dict.fromkeys(COUNTERS, 0)
        self.last_error: str | None = None
        self._logged: set[str] = set()

    def _error(self, kind: str, message: str) -> None:
        self.counters[kind] += 1
        self.last_error = f"{kind}: {message}"
        if kind not in self._logged:
            self._logged.add(kind)
            log.warning("sensor board: %s (counted in %r; further ones not logged)",
                        message, kind)

    def feed(self, data: bytes) -> list[BoardFrame]:
        self._buffer += data
        out = []
        while True:
            end = self._buffer.find(0)
            if end < 0:
                if len(self._buffer) > MAX_FRAME_BYTES:
                    self._error("overlong", f"{len(self._buffer)} bytes without a delimiter")
                    self._buffer.clear()
                break
            packet = bytes(self._buffer[:end])
            del self._buffer[:end + 1]
            if not packet:
                continue                      # back-to-back delimiters: resync filler
            try:
                frame = decode(packet)
            except FrameError as exc:
                self._error(exc.kind, str(exc))
                continue
            self._sequence(frame)
            self.counters["frames"] += 1
            out.append(frame)
        return out

    def _sequence(self, frame: BoardFrame) -> None:
        if frame.type == TYPE_BOOT:
            self.counters["boots"] += 1
            log.warning("sensor board restarted (boot frame); sequence from %d", frame.seq)
            self._next_seq = (frame.seq + 1) & 0xFFFF
            return
        if self._next_seq is not None and frame.seq != self._next_seq:
            missing = (frame.seq - self._next_seq) & 0xFFFF
            self._error("seq_gaps", f"sequence gap: expected {self._next_seq}, got "
                                    f"{frame.seq} ({missing} frames lost)")
            self.counters["lost_frames"] += missing
        self._next_seq = (frame.seq + 1) & 0xFFFF
