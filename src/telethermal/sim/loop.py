"""One simulated touch's loop, whatever the link: each period the slave
reads what has reached it and steps its pad, the master reads what has
reached it, its display reads the pad's sensors, steps, and drives the
module, and what the master says goes on its link. The in-process run
(:func:`~telethermal.sim.inprocess.run_session`) and the simulated network
(:func:`~telethermal.sim.network.run_network_touch`) both run this loop,
on :mod:`telethermal.sim.sides`, over their link
(:class:`~telethermal.teleop.links.Link`)."""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field, replace
from typing import Callable

from telethermal.control.loop import FixedRateLoop, LoopStats, SimClock
from telethermal.sim.sides import SimMasterService, SimSlaveService
from telethermal.teleop.links import Link
from telethermal.teleop.session import PRE_CONTACT_S


@dataclass
class LoopRun:
    """What the loop measured: its record, the master's own share of each
    period (s: its news, display step and messages, on the real clock; not
    the simulated plants and slave sharing its thread), and the session
    time of its last period."""

    stats: LoopStats | None = None
    master_busy_s: list = field(default_factory=list)
    #: The session time of the period going on (its start), then of the last.
    t_end_s: float = 0.0


def run_touch_loop(touch, display, slave: SimSlaveService, master: SimMasterService,
                   slave_end: Link, master_end: Link, rate_hz: float, clock=None,
                   world: Callable = contextlib.nullcontext,
                   on_period: Callable | None = None, run: LoopRun | None = None) -> LoopRun:
    """The touch (``touch``: its :class:`~telethermal.sim.touch.DisplayTouch`,
    which says when it is over; ``display``: the devices the master reads
    and drives around it) at ``rate_hz`` on ``clock`` (a
    :class:`~telethermal.control.loop.SimClock` by default). ``world()``:
    a context around the work of what is not the master (the slave, the
    plant), so a world-paused clock leaves it out (the simulated network's
    work, done as the master reads and sends, is charged to the master).
    ``on_period(t, dt, sensors, news, step)``: after each period (a
    recording). ``run``: the record to fill (its ``t_end_s`` is the clock of
    devices opened before the loop), a new one by default."""
    run = run if run is not None else LoopRun()

    def one_period(t_loop: float, dt: float) -> bool:
        if touch.done:
            return False
        # Simulated time follows the loop: exact on the simulated clock, the
        # real elapsed time on the real one.
        t = run.t_end_s = t_loop - PRE_CONTACT_S
        with world():
            for m in slave_end.due(t):
                slave.on_message(m, t)
            slave.step(t, slave_end)
        for m in master_end.due(t):     # the master's session reads it: the master's work
            master.on_message(m, t)
        with world():
            sensors = display.read(t)
        started = time.perf_counter()           # reported on the real clock only
        step, sends = master.period(t, dt, sensors)
        for s in sends:         # sent now (the rule's time is the onset's, a debounce back)
            master_end.send(replace(s, t_s=t))
        run.master_busy_s.append(time.perf_counter() - started)
        with world():
            display.apply(t, step, dt, sensors.force_n)
        if on_period is not None:
            on_period(t, dt, sensors, master.last_news, step)
        return True

    run.stats = FixedRateLoop(1.0 / rate_hz, clock or SimClock()).run(one_period, touch.n_total)
    return run


def close_session(t: float, slave: SimSlaveService, master: SimMasterService,
                  slave_end: Link, master_end: Link) -> None:
    """The session is over: a contact still open is lifted on both sides
    at ``t``, by message where the link delivers at once (the master's lift
    reaches the slave, whose last words reach the master); a slave the lift
    has not reached (a delay, a loss) lifts its pad itself."""
    for s in master.close_contact(t):
        master_end.send(s)
    for m in slave_end.due(t):
        slave.on_message(m, t)
    slave.step(t, slave_end)
    for m in master_end.due(t):
        master.on_message(m, t)
    slave.lift(t)
