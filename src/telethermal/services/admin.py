"""A local control socket for the simulation harness (the demo, the tests,
a person at a terminal): place an object under the slave pad, make the
simulated operator touch the master, read status and results, stop.

It is not part of the wire protocol between master and slave: a REP socket
bound on loopback only, msgpack requests ``{"cmd": ..., ...}`` and replies
``{"ok": bool, ...}``.
"""

from __future__ import annotations

import logging
import time

import msgpack
import numpy as np
import zmq

from telethermal.errors import TelethermalError, TransportError
from telethermal.ports import close_listeners
from telethermal.services.requests import check_request
from telethermal.wire.loglimit import LogLimiter

log = logging.getLogger(__name__)


def _plain(value):
    """numpy values to msgpack-able ones."""
    if isinstance(value, np.ndarray):
        if value.dtype == object:
            return [None if v is None else str(v) for v in value]
        return [float(v) for v in value]
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


class ErrorCount:
    """A service's unexpected errors (one message's, one touch's, one
    request's): counted in ``counters["internal_errors"]`` and logged with
    the traceback, at most a few lines per 10 s per kind; the service goes on."""

    def __init__(self, counters: dict, logger: logging.Logger):
        self.counters = counters
        self.counters.setdefault("internal_errors", 0)
        self._limiter = LogLimiter(logger)

    def __call__(self, what: str, exc: BaseException) -> None:
        self.counters["internal_errors"] += 1
        self._limiter.warn(what, time.monotonic(), "%s: unexpected %s: %s", what,
                           type(exc).__name__, exc, exc_info=exc)


def admin_address(where) -> str:
    """A port number (127.0.0.1), or an ``ipc://`` path (a Unix socket: local
    by nature, and reachable from another network namespace of this host)."""
    if isinstance(where, int):
        return f"tcp://127.0.0.1:{where}"
    if isinstance(where, str) and where.startswith("ipc://"):
        return where
    raise TransportError(f"admin address must be a port or an ipc:// path, got {where!r}")


class AdminServer:
    def __init__(self, where, context: zmq.Context | None = None):
        self.ctx = context or zmq.Context.instance()
        self.sock = self.ctx.socket(zmq.REP)
        self.sock.linger = 0
        address = admin_address(where)
        try:
            if where == 0:
                self.port = self.sock.bind_to_random_port("tcp://127.0.0.1")
            else:
                self.sock.bind(address)
                self.port = where
        except zmq.ZMQError as exc:
            self.sock.close()
            raise TransportError(f"admin socket {address}: {exc}") from exc
        self.pending = False
        #: Requests refused (a bad field, an unknown command, a handler's
        #: error) and requests that met an unexpected error (logged).
        self.counters = {"refused": 0, "internal_errors": 0}
        self._internal_error = ErrorCount(self.counters, log)

    def receive(self) -> dict | None:
        """A request, if one is waiting (never blocks)."""
        if self.pending:
            return None
        try:
            data = self.sock.recv(flags=zmq.NOBLOCK)
        except zmq.Again:
            return None
        self.pending = True
        try:
            request = msgpack.unpackb(data, raw=False)
            if not isinstance(request, dict) or not isinstance(request.get("cmd"), str):
                raise ValueError("a request is a map with a 'cmd' string")
            return request
        except (ValueError, msgpack.exceptions.ExtraData, msgpack.exceptions.FormatError,
                TypeError) as exc:
            self.counters["refused"] += 1
            self.reply(ok=False, error=f"bad request: {str(exc)[:200]}")
            return None

    def handle(self, request: dict, service, handlers: dict, schema: dict | None = None) -> None:
        """Run one request: its fields checked against ``schema`` (a table of
        ``services/requests.py``; None: not checked), then
        ``handlers[cmd](fields)`` returns the reply's fields, or None when the
        reply comes later (a touch); "status" and "stop" are served for every
        service. A refused request is answered ``ok: false`` with the reason;
        an unexpected error is logged with its traceback (rate-limited),
        counted and answered, and the service goes on."""
        cmd = request["cmd"]
        try:
            if schema is not None:
                request = check_request(request, schema)
            if cmd == "status":
                self.reply(ok=True, **service.status())
            elif cmd == "stop":
                service.stop_requested = True
                self.reply(ok=True)
            elif cmd in handlers:
                payload = handlers[cmd](request)
                if payload is not None:
                    self.reply(**{"ok": True, **payload})
            else:
                self.reply(ok=False, error=f"unknown command {cmd!r}; commands: "
                                           f"{', '.join(['status', 'stop', *handlers])}")
        except (TelethermalError, KeyError, ValueError, TypeError) as exc:
            self.counters["refused"] += 1
            key = exc.args[0] if isinstance(exc, KeyError) and exc.args else None
            if not isinstance(exc, TelethermalError) and isinstance(key, str) \
                    and key not in request:          # a field the request left out
                why = f"needs {key[:64]}=... (a key=value argument)"
            else:
                why = str(exc)[:400]
            self.reply(ok=False, error=f"{cmd[:64]}: {why}")
        except Exception as exc:                # a bug: one request's, not the service's
            self._internal_error(f"admin {cmd[:64]!r}", exc)
            if self.pending:
                self.reply(ok=False, error=f"{cmd[:64]}: internal error ({type(exc).__name__}: "
                                           f"{str(exc)[:200]}); logged, the service goes on")

    def reply(self, **payload) -> None:
        self.sock.send(msgpack.packb(_plain(payload), use_bin_type=True))
        self.pending = False

    def close(self):
        # Closed means free, as the endpoint's (an ipc:// path has no port).
        close_listeners([self.sock], "127.0.0.1", [self.port] if isinstance(self.port, int)
                        else [])


def call(port, cmd: str, timeout_s: float = 10.0, context=None, **args) -> dict:
    """Send one admin request (to a port on 127.0.0.1 or an ipc:// path)
    and wait for the reply."""
    ctx = context or zmq.Context.instance()
    sock = ctx.socket(zmq.REQ)
    sock.linger = 0
    sock.connect(admin_address(port))
    try:
        sock.send(msgpack.packb({"cmd": cmd, **args}, use_bin_type=True))
        if not sock.poll(timeout_s * 1000):
            raise TransportError(f"admin {cmd!r} on port {port}: no reply in {timeout_s} s")
        return msgpack.unpackb(sock.recv(), raw=False)
    finally:
        sock.close(linger=0)


def open_service_sockets(role: str, config, clock) -> tuple:
    """A service's transport endpoint on ``clock`` (its
    :class:`~telethermal.control.loop.RealClock`, of the config's
    ``time_scale``) and its admin socket; if the admin socket cannot be
    opened, the endpoint is closed again (nothing leaks)."""
    from telethermal.wire.transport import Endpoint

    endpoint = Endpoint(role, config.transport, clock=clock.monotonic, time_scale=clock.scale)
    try:
        return endpoint, AdminServer(config.admin_ipc or config.admin_port)
    except TelethermalError:
        endpoint.close()
        raise
