"""Reading an MCAP file record by record, past damage (issue 47).

``mcap``'s own readers stop at the first record that does not parse and
check no chunk's CRC unless asked. A recording is read here instead as a
sequence of top-level records, each parsed alone by ``mcap``'s
:class:`~mcap.stream_reader.StreamReader`:

* a chunk whose CRC (of its records, written by the recorder) does not
  match is reported (:attr:`Damage.corrupt_chunks`) and its records are not
  used: a damaged recording is never replayed as if it were whole;
* a record that does not parse (a flipped length or opcode byte) is
  skipped: the reader looks for the next chunk whose CRC matches and goes
  on from there (:attr:`Damage.skipped_bytes`);
* the end of a file cut mid-write is where reading stops (:attr:`Damage.cut`).
"""

from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass, field

from mcap.records import Chunk
from mcap.stream_reader import StreamReader, breakup_chunk

MAGIC = b"\x89MCAP0\r\n"
CHUNK_OPCODE = 0x06
FOOTER_OPCODE = 0x02
#: The largest recording read (a service's day: tens of MB).
MAX_RECORDING_BYTES = 1024 ** 3


@dataclass
class Damage:
    corrupt_chunks: list = field(default_factory=list)    # "offset N: why"
    skipped_bytes: int = 0                                 # unparseable, passed over
    skipped_records: int = 0
    cut: str | None = None                                 # where a cut file ends

    @property
    def any(self) -> bool:
        return bool(self.corrupt_chunks or self.skipped_bytes or self.skipped_records)


def _record_at(data: bytes, offset: int):
    """(record, end) of the top-level record at ``offset``; raises on damage."""
    if offset + 9 > len(data):
        raise EOFError(f"cut at byte {offset}: {len(data) - offset} bytes of a record header")
    opcode = data[offset]
    (length,) = struct.unpack_from("<Q", data, offset + 1)
    end = offset + 9 + length
    if end > len(data):
        raise EOFError(f"cut at byte {len(data)}: the record at {offset} (opcode {opcode:#x}) "
                       f"needs {length} bytes")
    reader = StreamReader(io.BytesIO(data[offset:end]), skip_magic=True, emit_chunks=True,
                          validate_crcs=True, record_size_limit=None)
    return next(iter(reader.records)), end


def _chunk_records(chunk: Chunk, offset: int) -> list:
    """The records inside a chunk, after its CRC is checked; ValueError if it fails."""
    if chunk.compression not in ("", "none"):
        raise ValueError(f"compression {chunk.compression!r} (the recorder writes none)")
    if chunk.uncompressed_crc and zlib.crc32(chunk.data) != chunk.uncompressed_crc:
        raise ValueError(f"CRC mismatch (recorded {chunk.uncompressed_crc:#010x}, "
                         f"read {zlib.crc32(chunk.data):#010x})")
    return breakup_chunk(chunk, validate_crc=False)


def _next_chunk(data: bytes, start: int) -> int | None:
    """The offset of the next chunk at or after ``start`` whose CRC matches."""
    at = data.find(bytes([CHUNK_OPCODE]), start)
    while at != -1:
        try:
            record, _ = _record_at(data, at)
            if isinstance(record, Chunk) and record.uncompressed_crc and \
                    zlib.crc32(record.data) == record.uncompressed_crc:
                return at
        except Exception:                   # noqa: BLE001 - not a chunk here: look on
            pass
        at = data.find(bytes([CHUNK_OPCODE]), at + 1)
    return None


def iter_records(data: bytes, damage: Damage):
    """Every readable record of an MCAP file's bytes, chunks opened, in
    file order; what could not be read is counted in ``damage``."""
    if not data.startswith(MAGIC):
        raise ValueError("no MCAP magic at the start")
    offset = len(MAGIC)
    while offset < len(data):
        if data[offset:] == MAGIC or data[offset] == FOOTER_OPCODE:     # the end
            return
        try:
            record, end = _record_at(data, offset)
        except Exception as exc:                # noqa: BLE001 - a cut, or damage: resync
            resume = _next_chunk(data, offset + 1)
            if resume is None:                  # nothing whole after it: the file's end
                damage.cut = str(exc) if isinstance(exc, EOFError) else \
                    f"unreadable from byte {offset} to the end ({exc or type(exc).__name__})"
                return
            damage.skipped_records += 1
            damage.skipped_bytes += resume - offset
            offset = resume
            continue
        if isinstance(record, Chunk):
            try:
                yield from _chunk_records(record, offset)
            except Exception as exc:            # noqa: BLE001
                damage.corrupt_chunks.append(f"chunk at byte {offset}: "
                                             f"{exc or type(exc).__name__}")
        else:
            yield record
        offset = end
