"""The in-process wire (:func:`instant_pair`): the two sides' ends of a
:class:`~telethermal.teleop.links.Link` with no delay and no loss. What
one side sends, the other has at its next :meth:`InstantEnd.due`; the
order kept. The simulated network's ends are
:meth:`telethermal.sim.network.SimNetwork.end`."""

from __future__ import annotations

from collections import deque

from telethermal.teleop.session import Send
from telethermal.wire.messages import Message


class InstantEnd:
    """One side's end of the instant wire."""

    def __init__(self, inbox: deque, outbox: deque):
        self._in, self._out = inbox, outbox

    def send(self, s: Send) -> bool:
        self._out.append(s.message)
        return True

    def due(self, now_s: float) -> list[Message]:
        out = list(self._in)
        self._in.clear()
        return out


def instant_pair() -> tuple[InstantEnd, InstantEnd]:
    """(the slave's end, the master's end) of one wire."""
    to_slave, to_master = deque(), deque()
    return InstantEnd(to_slave, to_master), InstantEnd(to_master, to_slave)
