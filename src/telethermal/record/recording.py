"""Recording a session to MCAP, and reading it back.

Why MCAP (and not HDF5): a recording is an append-only log written while a
control loop runs, and it must stay readable when the process dies or the
disk fills mid-write. MCAP is exactly that (records appended one after the
other; the index at the end is optional), it is self-describing (a schema
per channel, metadata and attachments in the file) and other tools open it
(the ``mcap`` CLI, Foxglove). An HDF5 file cut mid-write is usually not
readable at all, and HDF5's writer is not built for a streaming log. The
messages are written in uncompressed chunks, each with the CRC of its
records, closed and flushed to the file every ``FLUSH_S`` (0.1 s) while
messages come: a process killed mid-write loses at most the last 0.1 s of
what it had queued. Reading (:mod:`telethermal.record.mcapread`) checks each
chunk's CRC, skips and counts what is damaged and goes on; the ``mcap``
library's non-seeking reader reads a cut file up to the cut, and its
seeking reader (``make_reader``) reads every file that was closed.

Layout of a recording (one file per host and run):

* profile ``telethermal``; metadata ``telethermal`` (recording version,
  protocol version, software, role, date) and ``config`` (the service's
  config or the session's parameters);
* attachments: the identifier and generator model files (npz), so a replay
  with "the same model" needs nothing else;
* one channel per topic, message encoding ``msgpack``, each with a JSON
  schema (``jsonschema``) of its fields. Topics: ``/<role>/period`` (one per
  control period), ``/<role>/news`` (what the master knew of the slave,
  when it changed), ``/slave/sample_batch`` (the slave pad's samples as
  they come, 20 ms a batch, with ``measured`` (1/0) on devices; read back
  as one ``/slave/samples`` message per contact), ``/slave/contact_end`` (a contact's end),
  ``/<role>/wire/<kind>`` (protocol messages sent and received), ``/<role>/touch``
  (a touch's summary).

:class:`Recorder` never blocks the caller: :meth:`Recorder.log` puts the
message on a bounded queue and a writer thread encodes and writes it; a full
queue drops the message and counts it, and so does a message msgpack cannot
encode (that message alone; the file says how many when it closes). A
write error (the disk is full)
stops the recording with a clear error (:attr:`Recorder.error`) and every
later message is dropped and counted; the session goes on.
"""

from __future__ import annotations

import datetime
import json
import logging
import queue
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import msgpack
from mcap.writer import CompressionType, Writer

from telethermal.errors import TelethermalError
from telethermal.filelimits import read_bytes
from telethermal.record.mcapread import MAX_RECORDING_BYTES, Damage, iter_records

log = logging.getLogger(__name__)

RECORDING_VERSION = 1
#: Messages written at a time by the writer thread (it yields between).
SLICE = 16
#: The writer closes its chunk (CRC'd) and flushes it to the file at least
#: this often while messages come: a process killed with -9 loses at most
#: the messages queued in the last FLUSH_S (plus what its caller had not
#: yet handed over: a master's or a slave's batch, 20 ms).
FLUSH_S = 0.1
#: A chunk is also closed when it reaches this size: a file cut anywhere
#: loses at most this much of what was written before the cut (a writer
#: faster than real time, an in-process session, fills it before FLUSH_S).
CHUNK_BYTES = 16 * 1024
PROFILE = "telethermal"


#: How recordings are opened (a test replaces it to fill the disk).
_open = open


class RecordingError(TelethermalError, ValueError):
    """A recording that cannot be written or read; names the file and why."""


def _schema(fields: dict[str, str]) -> bytes:
    return json.dumps({"type": "object", "properties": {
        k: {"type": v} for k, v in fields.items()}}).encode()


#: Field types of the fixed topics (JSON-schema type names); wire messages
#: take their schema from the protocol's.
TOPIC_FIELDS = {
    "period": {"t_s": "number", "dt_s": "number", "flux_w_m2": "number",
               "pad_temp_c": "number", "force_n": "number", "phase": "string",
               "desired_flux_w_m2": "number", "junction_cmd_c": "number",
               "junction_applied_c": "number", "safe": "boolean"},
    "news": {"t_s": "number", "object_temp_c": "number", "estimate": "array",
             "classes": "array", "setpoint_w_m2": "number", "link_ok": "boolean"},
    "samples": {"t_s": "array", "heat_flux_W_m2": "array", "temperature_C": "array",
                "force_N": "array", "measured": "array"},
    "sample_batch": {"contact_id": "integer", "k0": "integer", "t_s": "array",
                     "heat_flux_W_m2": "array", "temperature_C": "array", "force_N": "array",
                     "measured": "array"},
    "contact_end": {"contact_id": "integer", "samples": "integer", "object_ir_c": "number",
                    "pad_before_c": "number", "gap_k": "number"},
    "touch": {"summary": "object"},
    "thermometer_calibration": {"calibrated": "boolean", "offset_k": "number", "gain": "number",
                                "residual_k": "number", "offset_sd_k": "number",
                                "points": "array"},
    "sim": {"trace": "object"},
    "unpackable": {"topic": "string", "count": "integer", "error": "string"},
}
#: Where the writer notes, in the stream itself, each message it could not
#: encode (so a file cut by a kill -9 still says what is missing).
UNPACKABLE_TOPIC = "/recording/unpackable"


class Recorder:
    def __init__(self, path: str | Path, role: str, config: dict | None = None,
                 attachments: dict[str, bytes] | None = None, queue_size: int = 200_000):
        from telethermal import __version__
        from telethermal.wire.schema import PROTOCOL_VERSION

        self.path = Path(path)
        self.role = role
        self.counters = {"queued": 0, "written": 0, "dropped_queue_full": 0,
                         "dropped_after_error": 0, "dropped_unpackable": 0}
        self.error: str | None = None
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self._channels: dict[str, int] = {}
        self._closed = False
        self._file = None
        self._last_t_ns = 0                  # the last written message's time
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = _open(self.path, "wb")
            self._writer = Writer(self._file, chunk_size=CHUNK_BYTES,
                                  compression=CompressionType.NONE, enable_crcs=True)
            self._writer.start(profile=PROFILE, library=f"telethermal {__version__}")
            self._writer.add_metadata("telethermal", {
                "recording_version": str(RECORDING_VERSION),
                "protocol_version": str(PROTOCOL_VERSION), "software": f"telethermal "
                f"{__version__}", "role": role,
                "date": datetime.datetime.now(datetime.timezone.utc).isoformat()})
            self._writer.add_metadata("config", {"json": json.dumps(config or {},
                                                                    default=str)})
            for name, data in (attachments or {}).items():
                self._writer.add_attachment(0, 0, name, "application/octet-stream", data)
            self._writer.flush()
        except OSError as exc:
            if self._file is not None:   # opened, then its start could not be written:
                try:                     # nothing half-written is left behind
                    self._file.close()
                except OSError:
                    pass
                self.path.unlink(missing_ok=True)
            raise RecordingError(f"cannot record to {self.path}: {exc}") from exc
        self._thread = threading.Thread(target=self._run, name=f"recorder-{role}",
                                        daemon=True)
        self._thread.start()

    # ------------------------------------------------------------ caller side
    def log(self, topic: str, t_s: float, message: dict) -> bool:
        """Queue one message (never blocks); False if it was dropped."""
        if self.error is not None or self._closed:
            self.counters["dropped_after_error"] += 1
            return False
        try:
            self._queue.put_nowait((topic, t_s, message))
        except queue.Full:
            self.counters["dropped_queue_full"] += 1
            return False
        self.counters["queued"] += 1
        return True

    def sync(self, timeout_s: float = 10.0) -> bool:
        """Wait until everything queued so far is written and flushed (its
        chunk closed): what a ``kill -9`` after this returns cannot lose."""
        done = threading.Event()
        if self._closed or self.error is not None:
            return False
        self._queue.put(done)
        return done.wait(timeout_s)

    def close(self) -> dict:
        """Write what is queued, the summary, and close; returns the counters
        and the error, if any."""
        if not self._closed:
            self._closed = True
            self._queue.put(None)
            self._thread.join()
            if self.error is None:
                try:
                    if self.counters["dropped_unpackable"]:
                        self._writer.add_metadata("dropped", {
                            "unpackable": str(self.counters["dropped_unpackable"])})
                    self._writer.finish()
                except OSError as exc:
                    self._fail(exc)
            try:
                self._file.close()
            except OSError as exc:
                if self.error is None:
                    self._fail(exc)
        return {**self.counters, "error": self.error, "path": str(self.path)}

    def discard(self) -> None:
        """Close and remove the file: nothing of it is kept."""
        self.close()
        self.path.unlink(missing_ok=True)

    # ------------------------------------------------------------ writer thread
    def _channel(self, topic: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            leaf = topic.rsplit("/", 1)[-1]
            fields = TOPIC_FIELDS.get(leaf)
            if fields is None:
                from telethermal.wire.schema import KINDS
                kind = KINDS.get(leaf)
                fields = {f.name: "any" for f in kind.fields} if kind else {}
            sid = self._writer.register_schema(topic.strip("/").replace("/", "."),
                                               "jsonschema", _schema(fields))
            cid = self._channels[topic] = self._writer.register_channel(topic, "msgpack", sid)
        return cid

    def _fail(self, exc: Exception) -> None:
        self.error = f"recording to {self.path} stopped: {exc}"
        log.error("%s; the session goes on without it", self.error)

    def _run(self) -> None:
        """Drain the queue in slices of ``SLICE`` messages (yielding the GIL
        between them, so the loop never waits behind a long encoding run);
        close the chunk and flush it to the file every ``FLUSH_S`` while
        messages come, at once when the queue runs dry, and on ``sync``."""
        last_flush, pending = time.monotonic(), False
        while True:
            try:
                item = self._queue.get(timeout=FLUSH_S)
            except queue.Empty:
                item = []                         # nothing new: flush what is pending
            batch = [item] if item != [] else []
            while item is not None and not isinstance(item, threading.Event) and \
                    len(batch) < SLICE:
                try:
                    item = self._queue.get_nowait()
                except queue.Empty:
                    break
                batch.append(item)
            pending = self._write(batch) or pending
            now = time.monotonic()
            if pending and (not batch or now - last_flush >= FLUSH_S or
                            isinstance(batch[-1], threading.Event)):
                self._flush()
                last_flush, pending = now, False
            if batch and isinstance(batch[-1], threading.Event):
                batch[-1].set()
            if batch and batch[-1] is None:
                return
            time.sleep(0)                        # and yield the GIL between slices

    def _write(self, batch: list) -> bool:
        """The messages of ``batch`` (up to a None or a sync marker) into the
        open chunk; whether any was written."""
        entries = [e for e in batch if isinstance(e, tuple)]
        if self.error is not None:
            self.counters["dropped_after_error"] += len(entries)
            return False
        try:
            for topic, t_s, message in entries:
                try:
                    data = msgpack.packb(message, use_bin_type=True)
                    t_ns = max(0, int(t_s * 1e9))
                except (ValueError, TypeError, OverflowError) as exc:
                    self._unpackable(topic, exc)  # this message only: the rest goes on
                    continue
                self._writer.add_message(self._channel(topic), t_ns, data, t_ns)
                self.counters["written"] += 1
                self._last_t_ns = t_ns
        except (OSError, ValueError, TypeError, OverflowError) as exc:
            self._fail(exc)
        return bool(entries)

    def _unpackable(self, topic: str, exc: Exception) -> None:
        """One message msgpack cannot encode (an object it does not know, an
        integer past 64 bits) or whose time is not a number: dropped and
        counted, logged at the first and every 1000th; the file records the
        count in its stream at once (:data:`UNPACKABLE_TOPIC`, flushed with the
        chunk, so a file cut by a kill -9 keeps it) and when it closes
        (metadata ``dropped``), so a reader says it."""
        self.counters["dropped_unpackable"] += 1
        n = self.counters["dropped_unpackable"]
        note = {"topic": str(topic)[:200], "count": n,
                "error": f"{type(exc).__name__}: {exc}"[:200]}
        try:
            self._writer.add_message(self._channel(UNPACKABLE_TOPIC), self._last_t_ns,
                                     msgpack.packb(note, use_bin_type=True), self._last_t_ns)
        except (ValueError, TypeError, OverflowError) as note_exc:
            # The note itself did not encode: the count at close still says it.
            log.warning("recording to %s: the note of message %d not written (%s)",
                        self.path, n, note_exc)
        if n == 1 or n % 1000 == 0:
            log.warning("recording to %s: message %d on %s not recorded (%s: %s); the "
                        "recording goes on", self.path, n, topic, type(exc).__name__, exc)

    def _flush(self) -> None:
        if self.error is None:
            try:
                self._writer.flush()              # the chunk closed with its CRC, written
            except OSError as exc:
                self._fail(exc)


@dataclass
class Recording:
    path: Path
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    topics: dict[str, list[tuple[float, dict]]] = field(default_factory=dict)
    truncated: str | None = None        # why reading stopped early, if it did
    notes: list[str] = field(default_factory=list)
    damage: Damage = field(default_factory=Damage)     # chunks and bytes skipped
    bad_messages: int = 0               # messages that did not unpack, skipped

    @property
    def damaged(self) -> str | None:
        """What was skipped, in words (None: nothing): such a recording is
        never replayed as identical."""
        d, parts = self.damage, []
        if d.corrupt_chunks:
            parts.append(f"{len(d.corrupt_chunks)} chunk(s) failed their CRC "
                         f"({'; '.join(d.corrupt_chunks[:3])})")
        if d.skipped_bytes:
            parts.append(f"{d.skipped_bytes} unreadable bytes skipped")
        if self.bad_messages:
            parts.append(f"{self.bad_messages} message(s) did not unpack")
        closed = str(self.metadata.get("dropped", {}).get("unpackable", "0"))
        noted = [m.get("count") for m in self.messages(UNPACKABLE_TOPIC)]
        unpackable = max([int(closed) if closed.isdigit() else 0]
                         + [n for n in noted if isinstance(n, int) and n > 0])
        if unpackable:
            parts.append(f"{unpackable} message(s) the writer could not encode are missing")
        return "; ".join(parts) or None

    @property
    def role(self) -> str:
        return self.metadata.get("telethermal", {}).get("role", "")

    @property
    def config(self) -> dict:
        try:
            config = json.loads(self.metadata.get("config", {}).get("json", "{}"))
        except (ValueError, RecursionError) as exc:
            raise RecordingError(f"{self.path}: its config metadata is not JSON: {exc}") from exc
        if not isinstance(config, dict):
            raise RecordingError(f"{self.path}: its config metadata is not a JSON object")
        return config

    def messages(self, topic: str) -> list[dict]:
        return [m for _, m in self.topics.get(topic, [])]


def read_recording(path: str | Path) -> Recording:
    """Everything readable in ``path``. A file cut mid-write is read up to
    the cut (``truncated`` says where it stopped); a chunk whose CRC fails
    or a record that does not parse is skipped, counted and named in
    ``damage`` (the records after it are read); a message that does not
    unpack is skipped and counted (``bad_messages``). A file of another
    recording version, or not a recording, is a :class:`RecordingError`."""
    from mcap.records import Attachment, Channel, Message, Metadata

    path = Path(path)
    rec = Recording(path)
    channels: dict[int, str] = {}
    data = read_bytes(path, MAX_RECORDING_BYTES, "recording", RecordingError)
    try:
        for record in iter_records(data, rec.damage):
            if isinstance(record, Metadata):
                rec.metadata[record.name] = dict(record.metadata)
                if record.name == "telethermal":
                    rec.notes += _check_version(path, record.metadata)
            elif isinstance(record, Attachment):
                rec.attachments[record.name] = bytes(record.data)
            elif isinstance(record, Channel):
                channels[record.id] = record.topic
            elif isinstance(record, Message):
                _add_message(rec, channels.get(record.channel_id), record)
    except ValueError as exc:                   # no MCAP magic
        raise RecordingError(f"{path} is not a telethermal recording: {exc}") from exc
    if "telethermal" not in rec.metadata:
        raise RecordingError(f"{path} is not a telethermal recording (no telethermal metadata)")
    rec.truncated = rec.damage.cut
    for what in rec.damage.corrupt_chunks:
        log.warning("%s: %s: its records skipped", path, what)
    if rec.damage.skipped_bytes:
        log.warning("%s: %d unreadable bytes skipped", path, rec.damage.skipped_bytes)
    merge_sample_batches(rec)
    return rec


def _add_message(rec: Recording, topic: str | None, record) -> None:
    """One message into ``rec.topics``; a message on no known channel or
    that does not unpack to a map is skipped and counted."""
    try:
        if topic is None:
            raise ValueError(f"channel {record.channel_id} was never announced")
        message = msgpack.unpackb(record.data, raw=False)
        if not isinstance(message, dict):
            raise ValueError(f"a {type(message).__name__}, not a map")
    except (ValueError, msgpack.exceptions.ExtraData, msgpack.exceptions.FormatError,
            msgpack.exceptions.StackError, TypeError) as exc:
        rec.bad_messages += 1
        if rec.bad_messages <= 3:
            log.warning("%s: message on %s at %d ns skipped: %s", rec.path, topic,
                        record.log_time, exc)
        return
    rec.topics.setdefault(topic, []).append((record.log_time / 1e9, message))


def merge_sample_batches(rec: Recording) -> None:
    """The slave's streamed batches (``/slave/sample_batch``) as one
    ``/slave/samples`` message per contact, as older recordings hold it: its
    channels concatenated in order, its scalars from ``/slave/contact_end``
    (or, for a contact cut mid-touch, from its last batch: noted)."""
    batches = rec.topics.pop("/slave/sample_batch", [])
    ends = {m.get("contact_id"): m for m in rec.messages("/slave/contact_end")}
    by_contact: dict = {}
    for t_s, m in batches:
        by_contact.setdefault(m.get("contact_id", 0), []).append((t_s, m))
    for cid, items in by_contact.items():
        items.sort(key=lambda x: x[1].get("k0", 0))
        merged: dict = {}
        k = 0
        for _, m in items:
            if m.get("k0") != k:
                rec.notes.append(f"contact {cid}: samples {k}-{m.get('k0')} missing "
                                 "(a damaged part of the file)")
            for key, value in m.items():
                if isinstance(value, list):
                    merged.setdefault(key, []).extend(value)
                    k = m.get("k0", 0) + len(value)
        last = ends.get(cid)
        if last is None:
            last = items[-1][1]
            rec.notes.append(f"contact {cid}: cut mid-touch; {k} samples up to the cut")
        merged.update({key: v for key, v in last.items() if not isinstance(v, list)})
        merged["contact_id"] = cid
        rec.topics.setdefault("/slave/samples", []).append((items[0][0], merged))


def _check_version(path: Path, meta: dict) -> list[str]:
    """Refuse what cannot be read; note what is read differently."""
    from telethermal.wire.schema import PROTOCOL_VERSION
    try:
        version = int(meta.get("recording_version", ""))
        protocol = int(meta.get("protocol_version", ""))
    except ValueError as exc:
        raise RecordingError(f"{path}: unreadable version metadata {dict(meta)}") from exc
    if version != RECORDING_VERSION:
        raise RecordingError(f"{path}: recording version {version}; this telethermal reads "
                             f"version {RECORDING_VERSION}")
    if protocol > PROTOCOL_VERSION:
        raise RecordingError(f"{path}: recorded with protocol version {protocol}, newer than "
                             f"this telethermal's ({PROTOCOL_VERSION}); upgrade to read it")
    if protocol < PROTOCOL_VERSION:
        note = (f"recorded with protocol version {protocol}, older than {PROTOCOL_VERSION}: "
                "wire messages are returned as recorded; fields added since are absent")
        log.warning("%s: %s", path, note)
        return [note]
    return []
