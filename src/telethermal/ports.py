"""Closed means free: close a listener and wait until its TCP ports can be bound
again (libzmq closes sockets in its I/O thread, after ``close()``)."""

from __future__ import annotations

import errno
import logging
import random
import socket
import time

log = logging.getLogger(__name__)


def port_problem(value, zero_means: str | None = None) -> str | None:
    """Why ``value`` is not a TCP port (1-65535; 0 too where ``zero_means``
    says what 0 does), or None: the one check of a configured or typed port."""
    low = 0 if zero_means else 1
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= 65535:
        return "a port is 1-65535" + (f" (0: {zero_means})" if zero_means else "")
    return None


#: :func:`wait_released`'s longest wait for a closed listener's port.
RELEASE_WAIT_S = 2.0


#: The lowest port :func:`free_ports` hands out (above the registered
#: services most machines run).
LOWEST_PORT = 10000
#: The kernel's range for ports it picks itself (Linux's file; its default
#: where the file cannot be read).
EPHEMERAL_RANGE_FILE = "/proc/sys/net/ipv4/ip_local_port_range"
DEFAULT_EPHEMERAL = (32768, 60999)


def kernel_ports(n: int) -> list[int]:
    """``n`` distinct TCP ports on 127.0.0.1 of the kernel's choice (from
    its ephemeral range), each held until all are drawn."""
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def ephemeral_range(path: str = EPHEMERAL_RANGE_FILE) -> tuple[int, int]:
    """The ports the kernel picks for ``bind(port 0)`` and for a
    connection's own end: ``(first, last)``, both included."""
    try:
        with open(path) as f:
            first, last = (int(v) for v in f.read().split())
        return first, last
    except (OSError, ValueError):
        return DEFAULT_EPHEMERAL


def free_ports(n: int) -> list[int]:
    """``n`` distinct TCP ports on 127.0.0.1, free now: drawn at random
    outside the kernel's ephemeral range and each tried with a bind (free
    until someone else binds them).

    Outside that range because a port the kernel picks is a port it may
    pick again: the source port of any outgoing connection, or another
    program's ``bind(0)``, could take it between this call and the service's
    bind (a service refused "Address already in use" so, once in a CI run,
    its port taken meanwhile). Where the ephemeral range leaves no room, the
    kernel's own choice is taken."""
    first, last = ephemeral_range()
    candidates = [p for p in range(LOWEST_PORT, 65536) if not first <= p <= last]
    if len(candidates) < 1000:
        log.warning("the kernel's ephemeral range %d-%d leaves %d ports above %d: free ports "
                    "may come from it, where another program can take them first", first,
                    last, len(candidates), LOWEST_PORT)
    rng = random.Random()                   # seeded from the OS: each process its own draw
    rng.shuffle(candidates)
    candidates += [0] * n                   # the kernel's choice, the last resort
    socks: list[socket.socket] = []
    try:
        for port in candidates:
            if len(socks) == n:
                break
            s = socket.socket()
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                s.close()
                continue
            socks.append(s)
        if len(socks) < n:
            raise OSError(errno.EADDRINUSE, f"no {n} free TCP ports on 127.0.0.1")
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def wait_released(host: str, ports, timeout_s: float = RELEASE_WAIT_S) -> list[int]:
    """Wait until each TCP ``port`` on ``host`` can be bound again; returns
    the ports still taken after ``timeout_s`` (logged, never raised).

    libzmq closes a socket in its I/O thread, after ``close()`` returned: a
    listener's port stays taken for a moment, and a service started again
    on it at once was refused "Address already in use" (2 of 300 immediate
    rebinds, measured). A probe bound with SO_REUSEADDR, as libzmq binds,
    succeeds once the listener is gone (connections in TIME_WAIT do not
    count) and fails while it still listens."""
    host = "0.0.0.0" if host in ("*", "") else host
    deadline = time.monotonic() + timeout_s
    taken = []
    for port in ports:
        if not port:
            continue
        try:
            # Numeric only: an interface name (libzmq binds "eth0") would be
            # a DNS query here, unbounded by the wait; it is not waited on.
            family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                        flags=socket.AI_NUMERICHOST)[0][0]
        except (OSError, ValueError):
            continue                                # nothing a probe can bind: not waited on
        while True:
            try:
                with socket.socket(family, socket.SOCK_STREAM) as probe:
                    probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                    probe.bind((host, port))
                break
            except OSError as exc:
                if exc.errno != errno.EADDRINUSE or time.monotonic() >= deadline:
                    if exc.errno == errno.EADDRINUSE:
                        taken.append(port)
                    break
            time.sleep(0.002)
    if taken:
        log.warning("ports %s on %s still taken %.1f s after their sockets closed", taken, host,
                    timeout_s)
    return taken


def close_listeners(socks, host: str, ports) -> None:
    """Close ZeroMQ ``socks`` (linger 0), then wait until the TCP ``ports``
    they bound on ``host`` can be bound again (:func:`wait_released`).
    Once: when every socket is closed already, nothing is closed or waited
    on (a port reused since is not this owner's)."""
    if all(s.closed for s in socks):
        return
    for s in socks:
        s.close(linger=0)
    wait_released(host, ports)
