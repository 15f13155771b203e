"""Recording a session to MCAP, and reading it back.

Why MCAP (and not HDF5): a recording is an append-only log written while a
control loop runs, and it must stay readable when the process dies or the
disk fills mid-write. MCAP is exactly that (records appended one after the
other; the index at the end is optional), it is self-describing (a schema
per channel, metadata and attachments in the file) and other tools open it
(the ``mcap`` CLI, Foxglove). An HDF5 file cut mid-write is usually not
readable at all, and HDF5's writer is not built for a streaming log. The
files are written unchunked, so everything written before a cut is
readable (at most the record being written is lost).

Layout of a recording (one file per host and run):

* profile ``telethermal``; metadata ``telethermal`` (recording version,
  protocol version, software, role, date) and ``config`` (the service's
  config or the session's parameters);
* attachments: the identifier and generator model files (npz), so a replay
  with "the same model" needs nothing else;
* one channel per topic, message encoding ``msgpack``, each with a JSON
  schema (``jsonschema``) of its fields. Topics: ``/<role>/period`` (one per
  control period), ``/<role>/news`` (what the master knew of the slave,
  when it changed), ``/<role>/samples`` (the slave pad's samples),
  ``/<role>/wire/<kind>`` (protocol messages sent and received), ``/<role>/touch``
  (a touch's summary).

:class:`Recorder` never blocks the caller: :meth:`Recorder.log` puts the
message on a bounded queue and a writer thread encodes and writes it; a full
queue drops the message and counts it. A write error (the disk is full)
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
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from telethermal.errors import TelethermalError

log = logging.getLogger(__name__)

RECORDING_VERSION = 1
#: Messages written between two flushes by the writer thread.
SLICE = 16
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
                "force_N": "array"},
    "touch": {"summary": "object"},
    "thermometer_calibration": {"calibrated": "boolean", "offset_k": "number", "gain": "number",
                                "residual_k": "number", "offset_sd_k": "number",
                                "points": "array"},
    "sim": {"trace": "object"},
}


class Recorder:
    def __init__(self, path: str | Path, role: str, config: dict | None = None,
                 attachments: dict[str, bytes] | None = None, queue_size: int = 200_000):
        from telethermal import __version__
        from telethermal.wire.schema import PROTOCOL_VERSION

        self.path = Path(path)
        self.role = role
        self.counters = {"queued": 0, "written": 0, "dropped_queue_full": 0,
                         "dropped_after_error": 0}
        self.error: str | None = None
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self._channels: dict[str, int] = {}
        self._closed = False
        self._file = None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = _open(self.path, "wb")
            self._writer = Writer(self._file, use_chunking=False,
                                  compression=CompressionType.NONE)
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
            self._file.flush()
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

    def close(self) -> dict:
        """Write what is queued, the summary, and close; returns the counters
        and the error, if any."""
        if not self._closed:
            self._closed = True
            self._queue.put(None)
            self._thread.join()
            if self.error is None:
                try:
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
        """Drain the queue in slices of ``SLICE`` messages, flushing (a system
        call, which lets the control loop's thread have the GIL) after each,
        so the loop never waits behind a long encoding run."""
        while True:
            item = self._queue.get()
            batch = [item]
            while item is not None and len(batch) < SLICE:
                try:
                    item = self._queue.get_nowait()
                except queue.Empty:
                    break
                batch.append(item)
            if self.error is None:
                try:
                    for entry in batch:
                        if entry is None:
                            break
                        topic, t_s, message = entry
                        t_ns = max(0, int(t_s * 1e9))
                        self._writer.add_message(self._channel(topic), t_ns,
                                                 msgpack.packb(message, use_bin_type=True),
                                                 t_ns)
                        self.counters["written"] += 1
                    self._file.flush()
                except (OSError, ValueError, TypeError) as exc:
                    self._fail(exc)
            else:
                self.counters["dropped_after_error"] += sum(e is not None for e in batch)
            if batch[-1] is None:
                return
            time.sleep(0)                        # and yield the GIL between slices


@dataclass
class Recording:
    path: Path
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    topics: dict[str, list[tuple[float, dict]]] = field(default_factory=dict)
    truncated: str | None = None        # why reading stopped early, if it did
    notes: list[str] = field(default_factory=list)

    @property
    def role(self) -> str:
        return self.metadata.get("telethermal", {}).get("role", "")

    @property
    def config(self) -> dict:
        return json.loads(self.metadata.get("config", {}).get("json", "{}"))

    def messages(self, topic: str) -> list[dict]:
        return [m for _, m in self.topics.get(topic, [])]


def read_recording(path: str | Path) -> Recording:
    """Everything readable in ``path``. A file cut mid-write is read up to
    the cut (``truncated`` says where it stopped); a file of another
    recording version, or not a recording, is a :class:`RecordingError`."""
    from mcap.records import Attachment, Channel, Message, Metadata

    path = Path(path)
    rec = Recording(path)
    channels: dict[int, str] = {}
    try:
        stream = open(path, "rb")
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc}") from exc
    with stream:
        try:
            for record in StreamReader(stream).records:
                if isinstance(record, Metadata):
                    rec.metadata[record.name] = dict(record.metadata)
                    if record.name == "telethermal":
                        rec.notes += _check_version(path, record.metadata)
                elif isinstance(record, Attachment):
                    rec.attachments[record.name] = bytes(record.data)
                elif isinstance(record, Channel):
                    channels[record.id] = record.topic
                elif isinstance(record, Message):
                    topic = channels.get(record.channel_id)
                    if topic is None:
                        continue
                    rec.topics.setdefault(topic, []).append(
                        (record.log_time / 1e9, msgpack.unpackb(record.data, raw=False)))
        except RecordingError:
            raise
        except Exception as exc:                # noqa: BLE001 - any damage: stop at the cut
            if "telethermal" not in rec.metadata:
                raise RecordingError(f"{path} is not a telethermal recording: {exc}") from exc
            rec.truncated = f"{type(exc).__name__}: {exc}"
    if "telethermal" not in rec.metadata:
        raise RecordingError(f"{path} is not a telethermal recording (no telethermal metadata)")
    return rec


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
