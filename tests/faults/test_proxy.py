"""The fault proxy between two transport endpoints: what the lossless
stream promises (nothing lost or reordered without being counted and
recovered) under loss, duplication, jitter and a partition."""

import dataclasses
import time

import pytest

from telethermal.sim.channel import Direction, FaultProfileError
from telethermal.sim.proxy import FaultProfile, FaultProxy, Link, load_profile
from telethermal.ports import free_ports
from telethermal.wire.transport import Endpoint, TransportConfig

PLAIN = TransportConfig(security="plain", control_port=0, stream_port=0, heartbeat_s=0.02,
                        dead_after_s=0.5)


def run_until(endpoints, proxy, done, seconds):
    got = {id(e): [] for e in endpoints}
    end = time.monotonic() + seconds
    while time.monotonic() < end and not done():
        proxy.step(0.001)
        for e in endpoints:
            got[id(e)] += e.poll(0.0)
    return [got[id(e)] for e in endpoints]


@pytest.fixture
def faulty_link(request):
    direction = request.param
    slave = Endpoint("slave", PLAIN)
    control, stream = free_ports(2)
    link = Link(control_port=control, stream_port=stream, slave_control_port=slave.ports[0],
                slave_stream_port=slave.ports[1], seed=3)
    proxy = FaultProxy(FaultProfile(link, direction, direction))
    master = Endpoint("master", dataclasses.replace(PLAIN, control_port=control,
                                                    stream_port=stream))
    run_until([slave, master], proxy, lambda: slave.peer_alive and master.peer_alive, 10.0)
    yield slave, master, proxy
    for e in (slave, master, proxy):
        e.close()


def contact(i):
    return dict(contact_id=i, touching=True, t_s=float(i), force_n=10.0)


LOSSY = Direction(delay_s=0.002, jitter="uniform", jitter_s=0.002, loss=0.1, duplicate=0.05,
                  reorder=0.05, reorder_hold_s=0.01)


@pytest.mark.parametrize("faulty_link", [LOSSY], indirect=True)
def test_loss_duplication_and_reordering_are_counted_and_recovered(faulty_link):
    slave, master, proxy = faulty_link
    for i in range(1, 151):
        master.send("contact_event", **contact(i))
        slave.send("contact_event", **contact(1000 + i))
    s_got, m_got = run_until([slave, master], proxy,
                             lambda: master.unacked == 0 and slave.unacked == 0, 30.0)
    assert [m["contact_id"] for m in s_got if m["kind"] == "contact_event"] == list(range(1, 151))
    assert [m["contact_id"] for m in m_got if m["kind"] == "contact_event"] == \
        list(range(1001, 1151))
    c = proxy.counters
    assert c["master_to_slave"]["lost"] > 0 and c["master_to_slave"]["duplicated"] > 0
    # What the network did, the receivers saw and repaired.
    assert slave.counters["gaps"] > 0 and slave.counters["recovered"] > 0
    assert slave.counters["duplicates"] > 0 and master.counters["resent"] > 0


@pytest.mark.parametrize("faulty_link", [Direction(partitions=((1.0, 1.5),))], indirect=True)
def test_after_a_partition_everything_sent_during_it_arrives(faulty_link):
    slave, master, proxy = faulty_link
    # Into the blackhole: sent once the proxy's own clock is inside the
    # partition (not after a fixed wait; a hang guard of 30 s).
    run_until([slave, master], proxy, lambda: proxy.m2s.partitioned(proxy.clock()), 30.0)
    assert proxy.m2s.partitioned(proxy.clock()), "the partition was over before the link"
    for i in range(1, 21):
        master.send("contact_event", **contact(i))
    s_got, _ = run_until([slave, master], proxy, lambda: master.unacked == 0, 30.0)
    assert [m["contact_id"] for m in s_got if m["kind"] == "contact_event"] == list(range(1, 21))
    assert proxy.counters["master_to_slave"]["partitioned"] > 0
    assert master.counters["heartbeats_missed"] >= 1          # the silence was noticed


def test_profiles_from_files_with_overrides(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text('[link]\nseed = 4\n[both]\ndelay_s = 0.1\n[slave_to_master]\nloss = 0.05\n'
                    'partitions = [[2.0, 1.0]]\n')
    p = load_profile(path, {"master_to_slave.jitter": "normal",
                            "master_to_slave.jitter_s": 0.02})
    assert p.master_to_slave.delay_s == 0.1 and p.slave_to_master.loss == 0.05
    assert p.master_to_slave.jitter == "normal" and p.slave_to_master.partitions == ((2.0, 1.0),)
    path.write_text('[both]\nlatency = 3\n')
    with pytest.raises(FaultProfileError, match="unknown key 'latency'"):
        load_profile(path)
    path.write_text('[both]\nloss = 2\n')
    with pytest.raises(FaultProfileError, match="master_to_slave.*loss"):
        load_profile(path)
    # A port no socket takes, from the file or from --set: refused when the
    # profile loads (it had raised OverflowError at the bind, then hung).
    path.write_text('[link]\nseed = 4\n')
    with pytest.raises(FaultProfileError, match=r"\[link\]: control_port = 99999: a port"):
        load_profile(path, {"link.control_port": 99999})
