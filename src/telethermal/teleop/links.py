"""The wire between the master's and the slave's session rules, as each
side sees it: a :class:`Link` takes the session's typed messages
(:class:`~telethermal.teleop.session.Send`) and hands back the messages
that have arrived by ``now``.

Three links carry a touch: the networked services' ZeroMQ transport
(:class:`EndpointLink`), and on the simulated clock the in-process wire
with no delay (:mod:`telethermal.sim.links`) and the simulated network
(the services' own lossless stream over a faulty channel:
:meth:`telethermal.sim.network.SimNetwork.end`)."""

from __future__ import annotations

import logging
from typing import Protocol

from telethermal.errors import ProtocolError, WindowFull
from telethermal.teleop.session import Send
from telethermal.wire.messages import Message, parse


class Link(Protocol):
    """One side's end of the wire."""

    def send(self, s: Send) -> bool:
        """``s.message`` on its way (lossless or not, as ``s.lossless``
        says); False: refused and left out. A link that models when a
        message leaves (the simulated network) sends it at ``s.t_s``."""

    def due(self, now_s: float) -> list[Message]:
        """The messages that have reached this side by ``now_s``, in the
        order its application gets them."""


class EndpointLink:
    """The ZeroMQ link: one side's transport
    :class:`~telethermal.wire.transport.Endpoint`. A send the lossless
    window refuses (the peer has acknowledged nothing for a whole window)
    or that fails (unencodable, a socket's error) is logged, counted
    (``send_errors``) and left out: the caller's loop goes on, and nothing
    sent before is lost. ``on_arrival(raw)``: each message as it came off
    the wire, before it is typed (the services' recording)."""

    def __init__(self, endpoint, log: logging.Logger, on_arrival=None):
        self.endpoint, self.log, self.on_arrival = endpoint, log, on_arrival

    def send(self, s: Send) -> bool:
        try:
            self.endpoint.send(s.kind, **s.message.fields())
        except WindowFull as exc:
            self.log.error("%s", exc)
            return False
        except Exception as exc:        # one message's (unencodable, a socket's error)
            counters = self.endpoint.extra_counters
            counters["send_errors"] = counters.get("send_errors", 0) + 1
            self.log.error("%s not sent: %s: %s", s.kind, type(exc).__name__, str(exc)[:200],
                           exc_info=counters["send_errors"] <= 3)
            return False
        return True

    def send_all(self, sends: list[Send]) -> list[Send]:
        """Each of ``sends``; returns those sent."""
        return [s for s in sends if self.send(s)]

    def due(self, now_s: float, wait_s: float = 0.0) -> list[Message]:
        """What the endpoint has received, waiting up to ``wait_s`` for a
        first message (the endpoint has checked each against the protocol's
        schema); one the typed messages refuse all the same is counted as
        the endpoint counts one it refuses (``unknown_kind``, ``invalid``)
        and left out, never the rest. A recording hook that fails is logged
        and counted (``record_errors``), the message still handled."""
        out = []
        for raw in self.endpoint.poll(wait_s):
            if self.on_arrival is not None:
                try:
                    self.on_arrival(raw)
                except Exception as exc:        # the recording's, not the link's
                    counters = self.endpoint.extra_counters
                    counters["record_errors"] = counters.get("record_errors", 0) + 1
                    self.log.error("a message not recorded: %s: %s", type(exc).__name__,
                                   str(exc)[:200], exc_info=counters["record_errors"] <= 3)
            try:
                out.append(parse(raw))
            except ProtocolError as exc:
                self.endpoint.refuse(exc)
        return out
