"""Closed means free: a slave's or an admin socket's port can be bound again
the moment close() returns (libzmq closes listeners in its I/O thread, after
close(); a slave restarted at once on its ports was refused "Address already
in use", 2 of 300 times, measured, and once in CI)."""

import socket

import zmq

from telethermal.services.admin import AdminServer
from telethermal.ports import wait_released
from telethermal.wire.transport import Endpoint, TransportConfig


def _bindable(port: int) -> bool:
    # As libzmq binds a listener: SO_REUSEADDR, then listen.
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(("127.0.0.1", port))
            probe.listen()
            return True
        except OSError:
            return False


def test_wait_released_waits_for_a_listener_and_names_a_port_still_taken():
    ctx = zmq.Context.instance()
    sock = ctx.socket(zmq.ROUTER)
    sock.linger = 0
    port = sock.bind_to_random_port("tcp://127.0.0.1")
    try:
        assert wait_released("127.0.0.1", [port], timeout_s=0.05) == [port]
    finally:
        sock.close(linger=0)
    assert wait_released("127.0.0.1", [port]) == []
    assert _bindable(port)


def test_a_slave_endpoints_ports_are_free_when_close_returns():
    taken = []
    for _ in range(100):
        endpoint = Endpoint("slave", TransportConfig(security="plain", control_port=0,
                                                     stream_port=0))
        ports = list(endpoint.sockets.ports)
        endpoint.close()
        taken += [p for p in ports if not _bindable(p)]
    assert taken == []


def test_an_admin_sockets_port_is_free_when_close_returns():
    taken = []
    for _ in range(100):
        admin = AdminServer(0)
        admin.close()
        if not _bindable(admin.port):
            taken.append(admin.port)
    assert taken == []


def test_a_view_publishers_and_a_fault_proxys_ports_are_free_when_close_returns():
    from telethermal.sim.channel import Direction
    from telethermal.sim.proxy import FaultProfile, FaultProxy, Link
    from telethermal.ports import free_ports
    from telethermal.view.stream import ViewPublisher

    taken = []
    for _ in range(50):
        view = ViewPublisher(0, conductance_w_m2k=1000.0)
        view.close()
        taken += [view.port] if not _bindable(view.port) else []
    control, stream, slave_control, slave_stream = free_ports(4)
    link = Link(control_port=control, stream_port=stream, slave_control_port=slave_control,
                slave_stream_port=slave_stream, seed=3)
    for _ in range(50):
        proxy = FaultProxy(FaultProfile(link, Direction(), Direction()))
        proxy.close()
        taken += [p for p in (control, stream) if not _bindable(p)]
    assert taken == []


def test_a_name_is_not_waited_on_and_a_second_close_does_not_wait(caplog):
    # An interface name (libzmq binds "eth0") is not resolved: nothing waited.
    assert wait_released("lo", [1]) == []
    # Closed once, the port taken by another listener since: closing again
    # neither waits for that listener nor warns about it.
    admin = AdminServer(0)
    admin.close()
    with socket.socket() as other:
        other.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        other.bind(("127.0.0.1", admin.port))
        other.listen()
        with caplog.at_level("WARNING", logger="telethermal.ports"):
            admin.close()
    assert "still taken" not in caplog.text
