"""A message-level ZeroMQ proxy that puts a faulty network between a real
master and a real slave (``telethermal faults --profile F``).

The master connects to the proxy as if it were the slave; the proxy
connects to the slave. Every message of either stream passes one
:class:`~telethermal.sim.channel.Channel` per direction, which decides
whether, when and how often it arrives. Delivery runs on this process's
clock; nothing is ever delivered early.

Plain sockets only: a proxy that reads messages would have to hold both
sides' CURVE keys to sit in an encrypted link, which is what an attacker
does; the fault tests run on loopback (or inside network namespaces).
"""

from __future__ import annotations

import heapq
import itertools
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zmq

from telethermal.errors import TransportError
from telethermal.sim.channel import Channel, Direction, FaultProfileError
from telethermal.tomltables import read_toml, table_values
from telethermal.ports import close_listeners, port_problem

log = logging.getLogger("telethermal.faults")


@dataclass(frozen=True)
class Link:
    listen_host: str = "127.0.0.1"
    control_port: int = 5660
    stream_port: int = 5661
    slave_host: str = "127.0.0.1"
    slave_control_port: int = 5560
    slave_stream_port: int = 5561
    seed: int = 0

    def __post_init__(self):
        for name in ("control_port", "stream_port", "slave_control_port", "slave_stream_port"):
            why = port_problem(getattr(self, name), "the system picks one")
            if why:
                raise FaultProfileError(f"{name} = {getattr(self, name)!r}: {why}")


@dataclass(frozen=True)
class FaultProfile:
    link: Link = field(default_factory=Link)
    master_to_slave: Direction = field(default_factory=Direction)
    slave_to_master: Direction = field(default_factory=Direction)


def _table(cls, data: dict, where: str):
    values = table_values(cls, data, where, FaultProfileError)
    if "partitions" in values:
        values["partitions"] = tuple(tuple(float(x) for x in w) for w in values["partitions"])
    try:
        return cls(**values)
    except (TypeError, ValueError, FaultProfileError) as exc:
        raise FaultProfileError(f"{where}: {exc}") from exc


def load_profile(path: str | Path, overrides: dict | None = None) -> FaultProfile:
    """Read a profile file; ``overrides`` {"master_to_slave.delay_s": 0.2, ...}."""
    path = Path(path)
    data = read_toml(path, "fault profile", FaultProfileError)
    unknown = set(data) - {"link", "master_to_slave", "slave_to_master", "both"}
    if unknown:
        raise FaultProfileError(f"{path}: unknown section(s) {', '.join(sorted(unknown))}")
    both = data.get("both", {})
    sections = {"link": data.get("link", {}),
                "master_to_slave": {**both, **data.get("master_to_slave", {})},
                "slave_to_master": {**both, **data.get("slave_to_master", {})}}
    for key, value in (overrides or {}).items():
        section, _, name = key.partition(".")
        targets = ["master_to_slave", "slave_to_master"] if section == "both" else [section]
        for t in targets:
            if t not in sections or not name:
                raise FaultProfileError(f"override {key!r}: use <section>.<key>")
            sections[t][name] = value
    return FaultProfile(_table(Link, sections["link"], f"{path} [link]"),
                        _table(Direction, sections["master_to_slave"], f"{path} [master_to_slave]"),
                        _table(Direction, sections["slave_to_master"], f"{path} [slave_to_master]"))


class FaultProxy:
    def __init__(self, profile: FaultProfile, context: zmq.Context | None = None,
                 clock=time.monotonic):
        self.profile, self.clock = profile, clock
        link = profile.link
        self.ctx = context or zmq.Context.instance()
        rng = np.random.default_rng(link.seed)
        now = self.t0_s = clock()      # partitions are timed from here
        self.m2s = Channel(profile.master_to_slave, np.random.default_rng(rng.integers(2**63)), now)
        self.s2m = Channel(profile.slave_to_master, np.random.default_rng(rng.integers(2**63)), now)
        self.s2m_stream = Channel(profile.slave_to_master,
                                  np.random.default_rng(rng.integers(2**63)), now)
        self._queue: list = []
        self._order = itertools.count()
        self._master_id: bytes | None = None
        socks = []
        try:
            self.front = self._sock(zmq.ROUTER, socks)
            self.front.bind(f"tcp://{link.listen_host}:{link.control_port}")
            self.front_stream = self._sock(zmq.PUB, socks)
            self.front_stream.bind(f"tcp://{link.listen_host}:{link.stream_port}")
            self.back = self._sock(zmq.DEALER, socks)
            self.back.connect(f"tcp://{link.slave_host}:{link.slave_control_port}")
            self.back_stream = self._sock(zmq.SUB, socks)
            self.back_stream.setsockopt(zmq.SUBSCRIBE, b"")
            self.back_stream.connect(f"tcp://{link.slave_host}:{link.slave_stream_port}")
        except zmq.ZMQError as exc:
            for s in socks:
                s.close(linger=0)
            raise TransportError(f"fault proxy: {exc}") from exc
        self._socks = socks
        self.poller = zmq.Poller()
        for s in (self.front, self.back, self.back_stream):
            self.poller.register(s, zmq.POLLIN)

    def _sock(self, kind, socks):
        s = self.ctx.socket(kind)
        s.linger = 0
        socks.append(s)
        return s

    @property
    def counters(self) -> dict:
        return {"master_to_slave": dict(self.m2s.counters),
                "slave_to_master": dict(self.s2m.counters),
                "slave_to_master_stream": dict(self.s2m_stream.counters)}

    def _schedule(self, channel: Channel, now: float, target: str, data: bytes) -> None:
        for at in channel.send(now, len(data)):
            heapq.heappush(self._queue, (at, next(self._order), target, data))

    def step(self, timeout_s: float) -> None:
        """Move messages for at most ``timeout_s``: receive, then deliver what is due."""
        wait = timeout_s
        if self._queue:
            wait = min(wait, max(0.0, self._queue[0][0] - self.clock()))
        events = dict(self.poller.poll(wait * 1000))
        now = self.clock()
        if self.front in events:
            while True:
                try:
                    identity, data = self.front.recv_multipart(zmq.NOBLOCK)[-2:]
                except zmq.Again:
                    break
                self._master_id = identity
                self._schedule(self.m2s, now, "back", data)
        for sock, channel, target in ((self.back, self.s2m, "front"),
                                      (self.back_stream, self.s2m_stream, "front_stream")):
            while sock in events:
                try:
                    data = sock.recv(zmq.NOBLOCK)
                except zmq.Again:
                    break
                self._schedule(channel, now, target, data)
        now = self.clock()
        while self._queue and self._queue[0][0] <= now:
            _, _, target, data = heapq.heappop(self._queue)
            try:
                if target == "back":
                    self.back.send(data, zmq.NOBLOCK)
                elif target == "front" and self._master_id is not None:
                    self.front.send_multipart([self._master_id, data], zmq.NOBLOCK)
                elif target == "front_stream":
                    self.front_stream.send(data, zmq.NOBLOCK)
            except zmq.Again:
                pass                              # the peer is gone: lost, as on a real link

    def run(self, should_stop=lambda: False) -> None:
        while not should_stop():
            self.step(0.01)

    def close(self) -> None:
        link = self.profile.link                   # closed means free, as the slave's
        close_listeners(self._socks, link.listen_host, [link.control_port, link.stream_port])
