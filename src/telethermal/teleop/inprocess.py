"""The in-process session's wire: both sides' session rules
(:mod:`telethermal.teleop.session`) joined with no delay and no loss, as
:func:`telethermal.teleop.run.run_session` drives them (split out of
``run.py``). A bench may show the master other news than the slave's
(``news_filter``: the oracle's or the closed set's target, ``bench
unseen``); the slave, its touch and the display are the same.
"""

from __future__ import annotations

import math
from typing import Callable

from telethermal.devices.readings import PadSensors
from telethermal.physics.scene import Scene
from telethermal.render.sampled import SampledGenerator, sample_curves
from telethermal.teleop.display_setup import build_display
from telethermal.teleop.link import SlaveLink
from telethermal.teleop.master import DisplayConfig, MasterDisplay, SlaveNews
from telethermal.teleop.memory import ObjectMemory
from telethermal.teleop.session import ContactRequest, MasterSession, SlaveSession
from telethermal.teleop.slave import Slave
from telethermal.wire.messages import Message

#: The session's time before the finger's contact (s): the slave's
#: announcement reaches the master then, the display idles from then.
PRE_CONTACT_S = 0.2


class InProcessWire:
    """Both sides' session rules (:mod:`telethermal.teleop.session`) joined
    by a wire with no delay and no loss, for the in-process run: each
    period the slave reads what the master sent and sends what its rules
    say, which the master reads before its display step (``master_step``,
    on the display made by ``set_up_display``). ``news_filter(news, t)``:
    what the master reads instead of the slave's news (a bench's baseline
    target; the slave and its messages unchanged); None: the news as is."""

    def __init__(self, pad: Slave, generator, identifier, rate_hz: float, object_id: str,
                 memory: ObjectMemory | None = None,
                 news_filter: Callable[[SlaveNews, float], SlaveNews] | None = None):
        curves = self.curves = sample_curves(generator, [c for c in identifier.classes_
                                                         if c in generator.materials])
        self.slave = SlaveSession(curves, rate_hz, memory=memory, measurements=False)
        self.slave.place(pad, object_id)
        self.master = MasterSession(SlaveLink(generator=SampledGenerator(curves),
                                              classes=tuple(pad.classes)))
        self.master.on_message(self.slave.announcement(-PRE_CONTACT_S).message, -PRE_CONTACT_S)
        self._to_slave: list[Message] = []
        self._to_master: list[Message] = []
        self.slave_t0_s: float | None = None
        self.display: MasterDisplay | None = None
        self.idle_c = math.nan
        self.finger_c = math.nan
        self.news_filter = news_filter

    def set_up_display(self, scene: Scene, config: DisplayConfig, finger_c: float,
                       idle_scene: Scene | None = None, calibration=None) -> MasterDisplay:
        """The master's display, idled before this touch at its standby: the
        object's temperature the master heard, pre-conditioned for what the
        slave announced it expects (object memory) or, for an unknown
        object, by the idle policy of ``idle_scene`` (:func:`build_display`,
        as the services build it)."""
        self.display, self.idle_c = build_display(scene, config, finger_c, self.master.link,
                                                  calibration=calibration,
                                                  idle_scene=idle_scene)
        self.finger_c = finger_c
        return self.display

    def to_master(self, m: Message, t: float) -> None:
        """One message from the slave reaches the master (no delay, one clock)."""
        self.master.on_message(m, t, 0.0)

    def slave_period(self, t: float, deliver: bool = True) -> None:
        """The slave's period; what it sends reaches the master now or, not
        ``deliver``, at :meth:`deliver` (the master's work when timed apart)."""
        out = []
        for m in self._to_slave:
            request, sends, _ = self.slave.on_contact_event(m, t)
            if request == ContactRequest.TOUCH:
                self.slave_t0_s = t
            out += sends
        self._to_slave = []
        self._to_master += [send.message for send in out + self.slave.step(t)]
        if deliver:
            self.deliver(t)

    def deliver(self, t: float) -> None:
        pending, self._to_master = self._to_master, []
        for m in pending:
            self.to_master(m, t)

    def master_step(self, t: float, dt: float, sensors: PadSensors):
        """One display period on ``sensors`` with what the slave has said:
        returns the news it read and its step; what it tells the slave
        goes on the wire."""
        news = self.master.news(t, True)
        if self.news_filter is not None:
            news = self.news_filter(news, t)
        step = self.display.step(t, dt, sensors, news)
        self._to_slave += [s.message for s in self.master.period(step, 0.0, sensors.force_n,
                                                                 self.finger_c)]
        return news, step

    def end(self, t_end: float) -> None:
        """The session is over: a contact still open is lifted on both sides."""
        self._to_slave += [s.message for s in self.master.close_contact(t_end, None)]
        self.slave_period(t_end)
