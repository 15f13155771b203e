"""Closed means free: close a listener and wait until its TCP ports can be bound
again (libzmq closes sockets in its I/O thread, after ``close()``)."""

from __future__ import annotations

import errno
import logging
import socket
import time

log = logging.getLogger(__name__)

#: :func:`wait_released`'s longest wait for a closed listener's port.
RELEASE_WAIT_S = 2.0


def free_ports(n: int) -> list[int]:
    """``n`` TCP ports on 127.0.0.1 free now (the OS's choice: bound, read
    and closed; free until someone else takes them)."""
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
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
