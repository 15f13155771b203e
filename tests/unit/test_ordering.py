"""The lossless stream's receiving rules (PROTOCOL.md section 4) and the
rate limit on warnings, without sockets or clocks."""

import logging

from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.wire.loglimit import LogLimiter
from telethermal.wire.ordering import MAX_BUFFERED, OrderedReceiver
from telethermal.wire.transport import COUNTERS


def receiver():
    return OrderedReceiver(dict.fromkeys(COUNTERS, 0))


def msg(seq):
    return {"seq": seq}


def test_in_order_out_of_order_duplicate_and_void():
    r = receiver()
    assert r.push(1, msg(1), 0.0) == [msg(1)]
    assert r.push(3, msg(3), 0.0) == [] and r.gap_since_s == 0.0
    assert r.push(2, None, 0.5) == [msg(3)]            # a void seq: used up, nothing delivered
    assert r.expected == 4 and r.gap_since_s is None
    assert r.push(3, msg(3), 1.0) == []
    assert r.counters["duplicates"] == 1 and r.counters["recovered"] == 1


def test_a_seq_out_of_the_window_is_dropped_not_buffered():
    r = receiver()
    assert r.push(1 + MAX_BUFFERED, msg(0), 0.0) == [] and not r.buffer
    assert r.push(2 ** 64 - 1, msg(0), 0.0) == [] and r.counters["out_of_window"] == 2
    assert r.push(MAX_BUFFERED, msg(0), 0.0) == [] and r.buffer      # the last in the window


def test_skipping_a_gap_delivers_the_successors_and_counts_the_missing():
    r = receiver()
    r.push(4, msg(4), 0.0)
    r.push(5, msg(5), 0.0)
    r.push(8, msg(8), 0.0)
    assert r.skip_gap(3.0) == [msg(4), msg(5)]
    assert r.counters["skipped"] == 3 and r.expected == 6
    assert r.gap_since_s == 3.0                        # the next gap (6, 7) is timed anew
    assert r.skip_gap(9.0) == [msg(8)] and r.counters["skipped"] == 5 and not r.buffer


@settings(max_examples=200, deadline=None)
@given(st.permutations(list(range(1, 30))), st.sets(st.integers(1, 29), max_size=5))
def test_any_order_delivers_everything_once_in_order(order, voids):
    r = receiver()
    out = []
    for seq in order + order[:5]:                      # and a few duplicates
        out += r.push(seq, None if seq in voids else msg(seq), 0.0)
    assert out == [msg(s) for s in range(1, 30) if s not in voids]
    assert r.counters["duplicates"] == 5 and not r.buffer


def test_warnings_are_limited_per_key(caplog):
    limiter = LogLimiter(logging.getLogger("t"), burst=3, period_s=10.0)
    with caplog.at_level(logging.WARNING):
        written = [limiter.warn("invalid", t * 0.01, "bad %d", t) for t in range(2000)]
        limiter.warn("unknown_kind", 0.0, "other key")
    # 3 at once, then one 10 s after the third (the next would be due at
    # 20.02 s, after the last at 19.99 s): 4 lines for 2000 messages.
    assert sum(written) == 4 and len(caplog.records) == 5
    assert "not logged in the last 10 s" in caplog.records[3].getMessage()
