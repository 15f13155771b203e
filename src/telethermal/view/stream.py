"""The master's view stream (``proto/PROTOCOL.md`` section 1): a PUB socket
bound on loopback that carries the master's own ``measurement_batch``, with
the optional fields a live view needs (setpoint, skin estimate, phase,
safety, link health, the newest posterior).

It never blocks the display loop: the loop appends one period's readings to
three lists (:meth:`ViewPublisher.period`) and, every ``BATCH_S`` of them,
one message is encoded and sent with ``NOBLOCK`` on a socket whose send
high-water mark is small, so a slow or absent subscriber costs a dropped
message (ZeroMQ's PUB drops past the mark), never a wait.
"""

from __future__ import annotations

import logging
import math

import zmq

from telethermal.control.loop import DEFAULT_RATE_HZ
from telethermal.errors import TransportError
from telethermal.wire.codec import encode
from telethermal.wire.schema import PROTOCOL_VERSION
from telethermal.ports import close_listeners

log = logging.getLogger(__name__)

#: Readings per message: 20 ms of them at any rate (20 periods at 1 kHz, 4
#: at 200 Hz), the view's floor of lag.
BATCH_S = 0.020
#: With no touch going on, a state-only message this often.
IDLE_EVERY_S = 0.1


def skin_estimate_c(pad_temp_c: float, flux_w_m2: float, conductance_w_m2k: float) -> float:
    """The skin surface under the pad: the pad surface less the drop across
    the pad-skin contact conductance (flux positive pad -> finger)."""
    return pad_temp_c - flux_w_m2 / conductance_w_m2k


class ViewPublisher:
    """One PUB socket on ``127.0.0.1:port`` (0: a free port, see ``port``)."""

    def __init__(self, port: int, conductance_w_m2k: float, context: zmq.Context | None = None,
                 hwm: int = 16):
        self.ctx = context or zmq.Context.instance()
        self.sock = self.ctx.socket(zmq.PUB)
        self.sock.linger = 0
        self.sock.sndhwm = hwm
        try:
            if port == 0:
                port = self.sock.bind_to_random_port("tcp://127.0.0.1")
            else:
                self.sock.bind(f"tcp://127.0.0.1:{port}")
        except zmq.ZMQError as exc:
            self.sock.close(linger=0)
            raise TransportError(f"view stream tcp://127.0.0.1:{port}: {exc}") from exc
        self.port = port
        self.h_w_m2k = conductance_w_m2k
        self.counters = {"sent": 0, "dropped": 0, "nonfinite": 0}
        self._seq = 0
        self._cols: tuple[list, list, list] = ([], [], [])
        self._t0 = 0.0
        self._rate_hz = DEFAULT_RATE_HZ          # until the first period says
        self._last_sent = -math.inf

    def period(self, now_s: float, rate_hz: float, flux_w_m2: float, pad_temp_c: float,
               force_n: float, state) -> None:
        """One display period's readings; ``state()`` (called only when a
        message goes out) returns the optional fields, ``contact_id`` and
        ``touching`` (the skin estimate is sent only while touching)."""
        flux, temp, force = self._cols
        if not flux:
            self._t0, self._rate_hz = now_s, rate_hz
        values = (flux_w_m2, pad_temp_c, force_n)
        if not all(math.isfinite(v) for v in values):      # a faulty reading: keep the last
            self.counters["nonfinite"] += 1
            values = tuple(c[-1] if c else 0.0 for c in self._cols)
        flux.append(float(values[0]))
        temp.append(float(values[1]))
        force.append(float(values[2]))
        if len(flux) >= max(1, round(BATCH_S * rate_hz)):
            self._publish(now_s, rate_hz, state())

    def idle(self, now_s: float, state) -> None:
        """No touch going on: the samples the last touch left (at once), or
        the state alone, every ``IDLE_EVERY_S``."""
        if self._cols[0]:
            self._publish(now_s, self._rate_hz, state())
        elif now_s - self._last_sent >= IDLE_EVERY_S:
            self._t0 = now_s
            self._publish(now_s, self._rate_hz, state())

    def _publish(self, now_s: float, rate_hz: float, fields: dict) -> None:
        flux, temp, force = self._cols
        self._cols = ([], [], [])
        self._seq += 1
        message = {"kind": "measurement_batch", "v": PROTOCOL_VERSION, "seq": self._seq,
                   "sent_s": now_s, "contact_id": fields.pop("contact_id", 0),
                   "t0_s": self._t0, "rate_hz": rate_hz, "flux_w_m2": flux, "temp_c": temp,
                   "force_n": force, **fields}
        touching = message.pop("touching", False)
        message["skin_temp_c"] = skin_estimate_c(temp[-1], flux[-1], self.h_w_m2k) \
            if touching and temp else None
        self._last_sent = now_s
        try:
            self.sock.send(encode(message), flags=zmq.NOBLOCK)
            self.counters["sent"] += 1
        except zmq.Again:
            self.counters["dropped"] += 1

    def close(self) -> None:
        close_listeners([self.sock], "127.0.0.1", [self.port])   # closed means free
