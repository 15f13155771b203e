"""The sensor board's serial frames (``proto/SERIAL.md``).

One frame per sample: a fixed record, COBS-encoded and ended by a 0x00
byte, so a reader that starts mid-stream or meets garbage resynchronises
at the next 0x00. Version 1 (the display's board, 27 bytes), little-endian::

    0  u8   version       1
    1  u8   type          1 sample, 2 boot (the board restarted; seq from 0)
    2  u16  seq           per frame, wraps at 65536
    4  u32  t_us          the board's clock, wraps
    8  f32  flux_uv       heat-flux sensor output, microvolts
    12 f32  tc_uv         thermocouple output, microvolts (type T)
    16 f32  cj_c          the thermocouple's cold-junction temperature, degC
    20 f32  force_n       force on the pad, N
    24 u8   status        bit 0 flux ADC ok, bit 1 thermocouple ok, bit 2 force ok
    25 u16  crc           CRC-16/CCITT-FALSE of bytes 0..24

Version 2 (the slave's board, 39 bytes) is version 1's fields up to
``force_n``, then::

    24 f32  ir_object_c   the infrared thermometer's object temperature, degC
    28 f32  ir_ambient_c  its ambient (sensor die) temperature, degC
    32 f32  pad_drive     the active pad's drive: Peltier -1..1, heater duty 0..1
    36 u8   status        bits 0-2 as version 1; bit 3 IR ok, bit 4 heater on,
                          bit 5 pump on
    37 u16  crc           CRC-16/CCITT-FALSE of bytes 0..36

A reader skips and counts a version it does not read (``version``); a
reader written to version 1 alone skips a version-2 frame by its length
(``garbage``). Both resynchronise at the next 0x00.

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
#: The slave's board: version 1's fields and the IR thermometer, the active pad's state.
FRAME_VERSION_SLAVE = 2
#: The versions this reader decodes (a reader may be restricted to fewer).
VERSIONS = (FRAME_VERSION, FRAME_VERSION_SLAVE)
TYPE_SAMPLE, TYPE_BOOT = 1, 2
_RECORD = struct.Struct("<BBHIffffB")
_RECORD_V2 = struct.Struct("<BBHIfffffffB")
RECORD_BYTES = _RECORD.size + 2            # + CRC
RECORD_BYTES_V2 = _RECORD_V2.size + 2
#: Record layout by its length: version 1's, and version 2's (any later version
#: that keeps version 2's length is read as far as its version byte).
_LAYOUTS = {RECORD_BYTES: _RECORD, RECORD_BYTES_V2: _RECORD_V2}
#: A run of this many bytes without a 0x00 is garbage: dropped, counted.
MAX_FRAME_BYTES = 64
STATUS_FLUX, STATUS_TC, STATUS_FORCE = 1, 2, 4
STATUS_ALL = STATUS_FLUX | STATUS_TC | STATUS_FORCE
STATUS_IR, STATUS_HEATER, STATUS_PUMP = 8, 16, 32


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
    # Version 2 only (NaN in a version-1 frame).
    ir_object_c: float = float("nan")
    ir_ambient_c: float = float("nan")
    pad_drive: float = float("nan")


def crc16(data: bytes) -> int:
    return binascii.crc_hqx(data, 0xFFFF)


def encode(frame: BoardFrame) -> bytes:
    """The bytes on the wire, delimiter included: version 1's layout for
    version 1, version 2's for any later version."""
    head = (frame.version, frame.type, frame.seq & 0xFFFF, frame.t_us & 0xFFFFFFFF,
            frame.flux_uv, frame.tc_uv, frame.cj_c, frame.force_n)
    if frame.version == FRAME_VERSION:
        record = _RECORD.pack(*head, frame.status)
    else:
        record = _RECORD_V2.pack(*head, frame.ir_object_c, frame.ir_ambient_c, frame.pad_drive,
                                 frame.status)
    return cobs.encode(record + struct.pack("<H", crc16(record))) + b"\x00"


def decode(packet: bytes, versions=VERSIONS) -> BoardFrame:
    """One COBS packet (no delimiter) to a frame of one of ``versions``;
    :class:`FrameError` says why not."""
    try:
        raw = cobs.decode(packet)
    except cobs.DecodeError as exc:
        raise FrameError("garbage", f"not a COBS packet ({exc}); {len(packet)} bytes") from exc
    layout = _LAYOUTS.get(len(raw))
    if layout is None:
        raise FrameError("garbage", f"a frame is {RECORD_BYTES} (version 1) or "
                                    f"{RECORD_BYTES_V2} (version 2) bytes, got {len(raw)}")
    record, (crc,) = raw[:-2], struct.unpack("<H", raw[-2:])
    if crc16(record) != crc:
        raise FrameError("crc", f"CRC mismatch: frame says {crc:#06x}, bytes give "
                                f"{crc16(record):#06x}")
    version = record[0]
    if version not in versions:
        raise FrameError("version", f"frame version {version}, this reader reads "
                                    f"{', '.join(map(str, versions))}")
    if (layout is _RECORD) != (version == FRAME_VERSION):
        raise FrameError("garbage", f"a version-{version} frame of {len(raw)} bytes")
    fields = layout.unpack(record)
    if fields[1] not in (TYPE_SAMPLE, TYPE_BOOT):
        raise FrameError("garbage", f"unknown frame type {fields[1]}")
    if layout is _RECORD:
        version, kind, seq, t_us, flux, tc, cj, force, status = fields
        return BoardFrame(seq, t_us, flux, tc, cj, force, status, kind, version)
    version, kind, seq, t_us, flux, tc, cj, force, ir_obj, ir_amb, drive, status = fields
    return BoardFrame(seq, t_us, flux, tc, cj, force, status, kind, version, ir_obj, ir_amb,
                      drive)


COUNTERS = ("frames", "frames_v1", "frames_v2", "garbage", "crc", "version", "seq_gaps",
            "lost_frames", "boots", "overlong")


class FrameReader:
    """Bytes in, frames out, whatever the bytes: split across reads, garbage
    between frames, bad CRCs, other versions, sequence gaps. Each problem is
    counted (``counters``), logged once per kind and skipped; the reader
    resynchronises at the next 0x00 by construction. ``versions``: the
    frame versions read (others are skipped and counted in ``version``)."""

    def __init__(self, versions=VERSIONS):
        self.versions = tuple(versions)
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
                frame = decode(packet, self.versions)
            except FrameError as exc:
                self._error(exc.kind, str(exc))
                continue
            self._sequence(frame)
            self.counters["frames"] += 1
            self.counters[f"frames_v{frame.version}"] += 1
            out.append(frame)
        return out

    def restart_sequence(self) -> None:
        """The line was reopened: what the board sent meanwhile (its boot
        frame among it) is gone, so the next frame starts the sequence."""
        self._next_seq = None
        self._buffer.clear()

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
