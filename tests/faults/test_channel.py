"""The fault channel on simulated time: closed forms and counting bounds."""

import math

import numpy as np
import pytest

from telethermal.sim.channel import Channel, Direction, FaultProfileError


def channel(**kw):
    return Channel(Direction(**kw), np.random.default_rng(1))


def test_a_fixed_delay_is_exact():
    ch = channel(delay_s=0.2)
    assert ch.send(10.0, 100) == [10.2]
    assert ch.send(10.5, 100) == [10.7]


def test_loss_is_binomial():
    # 20 % loss over 20000 messages: within 5 standard deviations of 4000.
    ch = channel(loss=0.2)
    delivered = sum(len(ch.send(i * 1e-3, 10)) for i in range(20000))
    sd = math.sqrt(20000 * 0.2 * 0.8)
    assert abs((20000 - delivered) - 4000) < 5 * sd
    assert ch.counters["lost"] == 20000 - delivered


def test_a_partition_drops_everything_inside_its_window_only():
    ch = channel(partitions=((1.0, 2.0),))
    got = {t: ch.send(t, 10) for t in (0.5, 1.0, 2.99, 3.0, 4.0)}
    assert got[0.5] == [0.5] and got[1.0] == [] and got[2.99] == []
    assert got[3.0] == [3.0] and got[4.0] == [4.0]
    assert ch.counters["partitioned"] == 2


def test_bandwidth_serialises_messages():
    # 1000 B messages on a 100 kB/s link, all sent at t = 0: they leave 10 ms apart.
    ch = channel(bandwidth_bytes_s=1e5, delay_s=0.05)
    times = [ch.send(0.0, 1000)[0] for _ in range(5)]
    np.testing.assert_allclose(times, 0.05 + 0.01 * np.arange(1, 6), rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind, mean", [("uniform", 0.02), ("exponential", 0.02),
                                        ("pareto", 0.02), ("normal", 0.02 * math.sqrt(2 / math.pi))])
def test_jitter_distributions_have_their_mean(kind, mean):
    # Mean of 20000 draws within 5 standard errors (sample sd as the estimate).
    ch = channel(jitter=kind, jitter_s=0.02)
    extra = np.array([ch.send(0.0, 0)[0] for _ in range(20000)])
    assert abs(extra.mean() - mean) < 5 * extra.std() / math.sqrt(len(extra))
    assert extra.min() >= 0.0                                   # never early


def test_jitter_reorders_and_duplicates_are_counted():
    ch = channel(jitter="uniform", jitter_s=0.01, duplicate=0.1)
    sends = [(k * 1e-3, ch.send(k * 1e-3, 10)) for k in range(2000)]
    arrivals = [t for _, ts in sends for t in ts[:1]]
    assert any(b < a for a, b in zip(arrivals, arrivals[1:]))      # reordered
    assert ch.counters["duplicated"] == sum(len(ts) == 2 for _, ts in sends) > 0
    assert all(t >= s for s, ts in sends for t in ts)


@pytest.mark.parametrize("kw, match", [({"loss": 1.5}, "loss"), ({"delay_s": -1}, "delay_s"),
                                       ({"jitter": "gauss"}, "jitter"),
                                       ({"bandwidth_bytes_s": 0}, "bandwidth"),
                                       ({"partitions": ((1.0, -2.0),)}, "partition")])
def test_bad_profiles_name_the_key(kw, match):
    with pytest.raises(FaultProfileError, match=match):
        Direction(**kw)
