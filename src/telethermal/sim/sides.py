"""The two services on the simulated clock: the same session rules
(:mod:`telethermal.teleop.session`) the networked services run, with the
simulated pad in place of the slave's devices and the display built by the
services' own factory (:func:`~telethermal.teleop.display_setup.build_display`).
Every simulated touch (the in-process run, the simulated network) drives
these two over a link (the in-process wire, :mod:`telethermal.sim.links`;
the simulated network's end, :meth:`telethermal.sim.network.SimNetwork.end`)
in one loop (:mod:`telethermal.sim.loop`)."""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

from telethermal.ident.anytime import Estimate
from telethermal.render.sampled import SampledGenerator
from telethermal.teleop.display_setup import build_display
from telethermal.teleop.link import SlaveLink
from telethermal.teleop.links import Link
from telethermal.teleop.master import MasterStep, SlaveNews
from telethermal.teleop.memory import ObjectMemory
from telethermal.teleop.session import (ContactRequest, EstimateRoute, MasterSession,
                                        PRE_CONTACT_S, Send, SlaveSession)
from telethermal.wire.messages import ContactEvent, Message


class SimSlaveService:
    """The slave service on the simulated clock: the same
    :class:`~telethermal.teleop.session.SlaveSession` the service runs, its
    pad going down when the master's touch arrives. Measurement batches are
    left out (nothing on the master reads them)."""

    def __init__(self, pad, curves: dict,
                 estimates: EstimateRoute | str = EstimateRoute.STREAM,
                 object_id: str | None = None, memory: ObjectMemory | None = None,
                 rate_hz: float = 1000.0):
        self.session = SlaveSession(curves, rate_hz, memory, estimates, measurements=False)
        self.session.place(pad, object_id)
        self.pad = pad
        self._out: list[Send] = []
        self.touch_t0: float | None = None     # when the pad went down (kept after the lift)

    def announcement(self, now: float) -> ContactEvent:
        """The object announcement (the service sends it on ``place``)."""
        return self.session.announcement(now).message

    def on_message(self, m: Message, now: float) -> None:
        if not isinstance(m, ContactEvent):
            return
        request, out, _ = self.session.on_contact_event(m, now)
        if request == ContactRequest.TOUCH:
            self.touch_t0 = now
        self._out += out

    def step(self, now: float, link: Link) -> None:
        """Read the pad up to ``now``; what the rules say goes on ``link``."""
        out, self._out = self._out + self.session.step(now), []
        for s in out:
            # Made from samples read by ``now``, so sent by then: an event's
            # time from the pad's clock can round a hair past it (a message
            # on the simulated network had waited a period for that).
            link.send(s if s.t_s <= now else replace(s, t_s=now))

    def lift(self, now: float) -> None:
        """The session ends with the pad still down (the master's lift had
        not arrived): the pad leaves the object, the memory learns."""
        self.session.lift(now)


class SimMasterService:
    """The master service on the simulated clock: the same
    :class:`~telethermal.teleop.session.MasterSession` the service runs, one
    clock with the slave (offset 0), and the display, idled for what the
    slave announced (at ``-PRE_CONTACT_S``, placed long before), stepped on
    the session's news each period.

    ``oracle``: the material the display is told at its own onset instead
    (no network; the floor of any compensation). ``news_filter(news, t)``:
    what the display reads instead of the session's news (a bench's
    baseline target); None: the news as is. ``calibration``, ``idle_scene``
    and ``model``: as :func:`~telethermal.teleop.display_setup.build_display`."""

    def __init__(self, scene, config, curves: dict, classes, announcement: ContactEvent,
                 finger_c: float, oracle: str | None = None,
                 news_filter: Callable[[SlaveNews, float], SlaveNews] | None = None,
                 calibration=None, idle_scene=None, model: dict | None = None):
        generator = SampledGenerator(curves)
        self.session = MasterSession(SlaveLink(generator=generator, classes=tuple(classes)))
        self.session.on_message(announcement, -PRE_CONTACT_S)
        self.finger_c, self.oracle, self.news_filter = finger_c, oracle, news_filter
        self.classes = tuple(classes)
        # The display has idled for what the announcement said (as the
        # services do); the oracle, knowing the material, for that material:
        # the floor of a repeated touch pre-conditions as the repeated touch does.
        self.display, self.idle_c = build_display(scene, config, finger_c, self.session.link,
                                                  calibration=calibration,
                                                  idle_scene=idle_scene,
                                                  expected_material=oracle, model=model)
        self.onset_s: float | None = None       # the display's last onset
        self.last_news: SlaveNews | None = None     # what the display read last period

    def on_message(self, m: Message, now: float) -> None:
        """One message from the slave, as it arrives."""
        self.session.on_message(m, now, 0.0)

    def news(self, now: float) -> SlaveNews:
        if self.oracle is None:
            news = self.session.news(now, True)
        else:
            c, est = self.classes, None
            if self.onset_s is not None:
                est = Estimate(0.0, tuple(float(n == self.oracle) for n in c), self.oracle,
                               1.0, True, "oracle")
            news = SlaveNews(self.session.link.object_temp_c, est, c,
                             expected_material=self.oracle)
        return news if self.news_filter is None else self.news_filter(news, now)

    def period(self, t: float, dt: float, sensors) -> tuple[MasterStep, list[Send]]:
        """One display period on ``sensors``: (its step, what goes to the slave)."""
        self.last_news = self.news(t)
        step = self.display.step(t, dt, sensors, self.last_news)
        if step.contact is not None and step.contact.touching:
            self.onset_s = step.contact.t_s
        return step, self.session.period(step, 0.0, sensors.force_n, self.finger_c)

    def close_contact(self, t: float) -> list[Send]:
        """The session is over: a contact still open is lifted."""
        return self.session.close_contact(t, None)
