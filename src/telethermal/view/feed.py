"""The live feed: the services' streams read as a subscriber, decimated, and
handed to the page's connections as small JSON frames.

Two SUB sockets, read by one thread: the master's view stream (its pad, its
state, the newest posterior; ``proto/PROTOCOL.md`` section 1) and the
slave's stream (its pad's ``measurement_batch`` and the naive
``flux_setpoint``). Both are the services' own PUB sockets: a subscriber
that falls behind loses messages at the publisher's high-water mark and
never slows a service down. Every ``FRAME_S`` the thread makes one frame of
what arrived, every series decimated to at most ``MAX_RATE_HZ``, and puts it
on each connection's bounded queue (a full queue drops its oldest frame and
counts it: a stalled tab costs the feed nothing either).
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time

import zmq

from telethermal.errors import ProtocolError
from telethermal.ident.openset import EFFUSIVITY_KEYS
from telethermal.wire.codec import decode
from telethermal.wire.schema import MessageKind

log = logging.getLogger(__name__)

FRAME_S = 0.05
MAX_RATE_HZ = 100.0
CLIENT_QUEUE = 64
#: Link counters the page shows (the master's transport counters).
LINK_COUNTERS = ("stream_lost", "resent", "gaps", "heartbeats_missed", "reconnects",
                 "duplicates", "invalid")


class Frames:
    """Fan-out of frames to the page's connections, never blocking the feed."""

    def __init__(self):
        self._lock = threading.Lock()
        self._clients: list[queue.Queue] = []
        self.dropped = 0

    def subscribe(self) -> queue.Queue:
        q: queue.Queue = queue.Queue(maxsize=CLIENT_QUEUE)
        with self._lock:
            self._clients.append(q)
        return q

    def unsubscribe(self, q: queue.Queue) -> None:
        with self._lock:
            if q in self._clients:
                self._clients.remove(q)

    @property
    def clients(self) -> int:
        with self._lock:
            return len(self._clients)

    def publish(self, frame: dict) -> None:
        with self._lock:
            clients = list(self._clients)
        for q in clients:
            while True:
                try:
                    q.put_nowait(frame)
                    break
                except queue.Full:
                    try:
                        q.get_nowait()
                        self.dropped += 1
                    except queue.Empty:
                        pass


def _decimated(t0_s: float, rate_hz: float, values: list, t_ref_s: float) -> list:
    """``[[t, v], ...]`` every k-th sample, at most ``MAX_RATE_HZ``; times in
    seconds since ``t_ref_s``."""
    k = max(1, math.ceil(rate_hz / MAX_RATE_HZ))
    return [[round(t0_s + i / rate_hz - t_ref_s, 4), v] for i, v in enumerate(values)
            if i % k == 0]


class Pending:
    """What arrived since the last frame."""

    def __init__(self):
        self.series: dict[str, list] = {}
        self.counts = {"master": 0, "slave": 0, "slave_setpoint": 0}
        self.state: dict | None = None
        self.newest_s: float | None = None

    def add(self, name: str, points: list) -> None:
        self.series.setdefault(name, []).extend(points)

    def seen(self, t_s: float) -> None:
        self.newest_s = t_s if self.newest_s is None else max(self.newest_s, t_s)


def master_state(m: dict) -> dict:
    """The page's status panel and posterior from one view-stream batch."""
    link = m.get("link", {})
    state = {"contact_id": m["contact_id"], "phase": m.get("phase", ""),
             "safe": m.get("safe", False), "events": m.get("events", {}),
             "rtt_s": m.get("rtt_s"), "link": {k: link.get(k, 0) for k in LINK_COUNTERS}}
    if m.get("posteriors") is not None:
        state["estimate"] = {"classes": m.get("classes", []), "posteriors": m["posteriors"],
                             "label": m.get("label", ""), "decided": m.get("decided", False),
                             "t_s": m.get("estimate_t_s"), "reason": m.get("reason", ""),
                             **{k: m[k] for k in EFFUSIVITY_KEYS if k in m}}
    return state


class LiveFeed:
    """Subscribes to ``master_url`` (the view stream) and ``slave_url`` (the
    slave's stream, with ``curve`` = (client public, client secret, server
    public) keys when it uses CURVE)."""

    def __init__(self, master_url: str | None, slave_url: str | None, curve=None,
                 context: zmq.Context | None = None, clock=time.monotonic):
        self.ctx = context or zmq.Context.instance()
        self.clock = clock
        self.frames = Frames()
        self.t_ref_s = clock()
        self.counters = {"master_batches": 0, "slave_batches": 0, "setpoints": 0,
                         "invalid": 0, "frames": 0}
        self.socks: dict[zmq.Socket, str] = {}
        for role, url in (("master", master_url), ("slave", slave_url)):
            if url:
                self.socks[self._sub(url, curve if role == "slave" else None)] = role
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="view-feed", daemon=True)

    def _sub(self, url: str, curve) -> zmq.Socket:
        sock = self.ctx.socket(zmq.SUB)
        sock.linger = 0
        sock.rcvhwm = 256
        if curve is not None:
            sock.curve_publickey, sock.curve_secretkey, sock.curve_serverkey = curve
        sock.setsockopt(zmq.SUBSCRIBE, b"")
        sock.connect(url)
        return sock

    def start(self) -> "LiveFeed":
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        for sock in self.socks:
            sock.close(linger=0)

    def _run(self) -> None:
        poller = zmq.Poller()
        for sock in self.socks:
            poller.register(sock, zmq.POLLIN)
        pending = Pending()
        next_frame = self.clock() + FRAME_S
        while not self._stop.is_set():
            timeout_ms = max(0.0, next_frame - self.clock()) * 1000
            for sock, _ in poller.poll(timeout_ms):
                self._drain(sock, pending)
            now = self.clock()
            if now >= next_frame:
                next_frame = max(next_frame + FRAME_S, now)
                if pending.newest_s is not None or pending.state is not None:
                    self.frames.publish(self._frame(pending, now))
                    pending = Pending()

    def _drain(self, sock, pending: Pending) -> None:
        role = self.socks[sock]
        while True:
            try:
                data = sock.recv(flags=zmq.NOBLOCK)
            except zmq.Again:
                return
            try:
                m = decode(data)
            except ProtocolError as exc:
                self.counters["invalid"] += 1
                log.warning("view: dropped a %s message: %s", role, exc)
                continue
            self._take(role, m, pending)

    def _take(self, role: str, m: dict, pending: Pending) -> None:
        ref = self.t_ref_s
        if m["kind"] == MessageKind.FLUX_SETPOINT:
            self.counters["setpoints"] += 1
            pending.counts["slave_setpoint"] += 1
            pending.add("slave_setpoint", [[round(m["sent_s"] - ref, 4), m["flux_w_m2"]]])
            pending.seen(m["sent_s"])
            return
        if m["kind"] != MessageKind.MEASUREMENT_BATCH:
            return
        n, rate, t0 = len(m["temp_c"]), m["rate_hz"], m["t0_s"]
        self.counters[f"{role}_batches"] += 1
        pending.counts[role] += n
        if n:
            pending.add(f"{role}_temp", _decimated(t0, rate, m["temp_c"], ref))
            pending.add(f"{role}_flux", _decimated(t0, rate, m["flux_w_m2"], ref))
            pending.seen(t0 + (n - 1) / rate)
        if role == "master":
            t_end = round(t0 + max(n - 1, 0) / rate - ref, 4)
            if m.get("setpoint_w_m2") is not None:
                pending.add("master_setpoint", [[t_end, m["setpoint_w_m2"]]])
            if m.get("skin_temp_c") is not None:
                pending.add("skin", [[t_end, m["skin_temp_c"]]])
            pending.state = master_state(m)

    def _frame(self, pending: Pending, now: float) -> dict:
        self.counters["frames"] += 1
        return {"mono_s": now, "wall_s": time.time(), "t_s": round(now - self.t_ref_s, 4),
                "data_s": pending.newest_s, "series": pending.series, "counts": pending.counts,
                "state": pending.state, "feed": dict(self.counters),
                "frames_dropped": self.frames.dropped}
