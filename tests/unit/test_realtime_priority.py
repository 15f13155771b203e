"""The display loop's SCHED_FIFO: granted and restored for a block, a
refusal said and not fatal; the real-clock text names both rows' targets."""

from __future__ import annotations

import os

import pytest

from telethermal.bench.clock_text import real_clock_sentences
from telethermal.control import loop
from telethermal.control.loop import WORLD_PAUSED, realtime, set_realtime

pytestmark = pytest.mark.skipif(not hasattr(os, "sched_setscheduler"),
                                reason="no scheduling policies here")


def test_a_block_runs_at_fifo_and_the_threads_policy_is_restored_after():
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    with realtime(loop.DEPLOYED_PRIORITY) as (granted, refused):
        assert bool(granted) != bool(refused)
        if granted:       # root or CAP_SYS_NICE (CI runs as root)
            assert granted == loop.DEPLOYED_PRIORITY
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
            assert os.sched_getparam(0).sched_priority == loop.DEPLOYED_PRIORITY
        else:
            assert os.sched_getscheduler(0) == before[0]
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before


def test_a_refusal_is_returned_not_raised_and_nothing_is_restored(monkeypatch):
    calls = []

    def refuse(pid, policy, param):
        calls.append(policy)
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    assert "not permitted" in set_realtime(20)
    with realtime(20) as (granted, refused):
        assert granted == 0 and "not permitted" in refused
    assert calls == [os.SCHED_FIFO, os.SCHED_FIFO]          # no restore after a refusal
    assert set_realtime(0) == "" and len(calls) == 2         # 0: not asked, nothing called


def _row(misses: int, priority=None) -> dict:
    r = {"rate_hz": 500.0, "clock": WORLD_PAUSED, "period_p50_us": 2000.0,
         "period_p99_us": 2100.0, "period_max_us": 5000.0, "deadline_misses": misses,
         "steps": 6800, "stalls": 0, "busy_p99_us": 700.0, "period_target_us": 2000.0}
    return r if priority is None else {**r, "realtime_priority": priority}


def test_the_text_sets_both_rows_against_the_target_and_skips_a_refused_fifo():
    report = {"default_rate_hz": 500.0, "real_clock": [_row(12)],
              "real_clock_deployed": [_row(3, 20)]}
    text = "\n".join(real_clock_sentences(report))
    # 12 of 6800 = 0.176 %: missed; 3 of 6800 = 0.044 %: met.
    assert "at normal priority: 12 of 6800 deadlines missed (0.176 %, target 0.1 %: MISSED)" \
        in text
    assert "as deployed (SCHED_FIFO): 3 of 6800 deadlines missed (0.044 %, target 0.1 %: met)" \
        in text
    assert "as deployed: SCHED_FIFO priority 20" in text
    report["real_clock_deployed"] = [{**_row(0, 0), "realtime_refused": "[Errno 1] no"}]
    text = "\n".join(real_clock_sentences(report))     # not granted: no target line
    assert "SCHED_FIFO not granted ([Errno 1] no)" in text
    assert "as deployed (SCHED_FIFO):" not in text


def test_a_restore_the_system_refuses_is_warned_not_raised(monkeypatch):
    calls = []

    def grant_then_refuse(pid, policy, param):
        calls.append(policy)
        if len(calls) > 1:
            raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", grant_then_refuse)
    with pytest.warns(RuntimeWarning, match="not restored"):
        with realtime(20) as (granted, refused):
            assert granted == 20 and refused == ""
    assert len(calls) == 2


def test_a_sessions_clock_is_named_by_its_enum_or_the_older_spellings():
    from telethermal.control.loop import SessionClock, session_clock

    assert session_clock(False) is SessionClock.SIMULATED
    assert session_clock(True) is SessionClock.REAL
    assert session_clock("master") is SessionClock.WORLD_PAUSED
    for clock in SessionClock:
        assert session_clock(clock) is clock and session_clock(clock.value) is clock
    assert SessionClock.WORLD_PAUSED == WORLD_PAUSED     # what summaries have said
    for bad in ("fast", 0, 1, 1.0, None):
        with pytest.raises(ValueError, match="realtime must be a SessionClock"):
            session_clock(bad)


def test_a_row_says_how_many_touches_of_what_length_it_pooled():
    one = {**_row(0), "sessions": 1, "contact_s": 0.5}
    four = {**_row(2), "sessions": 4, "contact_s": 3.0}
    text = "\n".join(real_clock_sentences({"real_clock": [one, four]}))
    assert "0 deadline misses of 6800 (1 touch of 0.5 s)" in text
    assert "2 deadline misses of 6800 (4 touches of 3 s)" in text
    assert "touch" not in "\n".join(real_clock_sentences({"real_clock": [_row(1)]}))



def test_a_row_too_short_for_the_target_is_not_judged_against_it():
    # 1 of 450 is 0.22 %: one miss says nothing of a 0.1 % rate.
    short = {**_row(1, 20), "steps": 450}
    text = "\n".join(real_clock_sentences({"default_rate_hz": 500.0,
                                            "real_clock_deployed": [short]}))
    assert "1 of 450 deadlines missed (0.222 %, target 0.1 %: too few periods to judge)" \
        in text
