"""The fixed-rate loop runner on the simulated clock (exact) and, for
structure only, on the real clock (no wall-clock figure is asserted)."""

import numpy as np
import pytest

from telethermal.control.loop import (SPIN_FRACTION, FixedRateLoop, RealClock, SimClock,
                                      WorldPausedClock, combined_summary)
from telethermal.errors import ControlError


def test_on_the_simulated_clock_every_step_is_on_its_deadline():
    seen = []
    stats = FixedRateLoop(0.01, SimClock()).run(lambda t, dt: seen.append((t, dt)), 100)
    assert [round(t, 12) for t, _ in seen] == [round(0.01 * k, 12) for k in range(100)]
    assert all(abs(dt - 0.01) < 1e-12 for _, dt in seen)
    s = stats.summary()
    assert s["steps"] == 100 and s["deadline_misses"] == 0 and s["overruns"] == 0
    assert s["lateness_max_us"] == 0.0 and abs(s["period_p99_us"] - 1e4) < 1e-6


def test_an_overrun_skips_missed_deadlines_and_reports_the_true_step():
    # Step 5 "takes" 2.5 periods: deadlines 6 and 7 are missed, not made up
    # in a burst; step 8 starts on its own deadline and is told dt = 3 periods.
    clock = SimClock()
    seen = []

    def step(t, dt):
        seen.append((round(t / 0.01, 9), round(dt / 0.01, 9)))
        if len(seen) == 6:
            clock.advance(0.025)

    stats = FixedRateLoop(0.01, clock).run(step, 10)
    starts = [k for k, _ in seen]
    assert starts == [0, 1, 2, 3, 4, 5, 8, 9, 10, 11]
    assert seen[6][1] == 3.0 and seen[7][1] == 1.0
    s = stats.summary()
    assert s["deadline_misses"] == 2 and s["overruns"] == 1


def test_a_step_that_restarts_the_deadlines_sets_its_overrun_aside():
    # The same step 5 taking 2.5 periods, but asking for the deadlines to
    # restart (a service setting up a touch): the 2 deadlines that passed are
    # set aside, none missed; the next step starts when step 5 ended, told
    # dt = 1 period (as a first step), and the grid runs from there.
    clock = SimClock()
    seen = []
    loop = FixedRateLoop(0.01, clock)

    def step(t, dt):
        seen.append((round(t / 0.01, 9), round(dt / 0.01, 9)))
        if len(seen) == 6:
            clock.advance(0.025)
            loop.restart_deadlines()

    stats = loop.run(step, 10)
    assert [k for k, _ in seen] == [0, 1, 2, 3, 4, 5, 7.5, 8.5, 9.5, 10.5]
    assert [d for _, d in seen] == [1.0] * 10
    s = stats.summary()
    assert s["deadline_misses"] == 0 and s["deadlines_set_aside"] == 2
    assert s["lateness_max_us"] == 0.0
    # The pause still shows in the periods (2.5 periods from step 5 to 6).
    assert s["period_max_us"] == pytest.approx(2.5e4)


def test_a_restart_asked_for_in_one_step_does_not_carry_to_the_next():
    clock = SimClock()
    loop = FixedRateLoop(0.01, clock)
    n = [0]

    def step(t, dt):
        n[0] += 1
        if n[0] == 2:
            loop.restart_deadlines()            # a quick set-up: nothing passed
        if n[0] == 4:
            clock.advance(0.025)                # an overrun: missed as ever

    s = loop.run(step, 6).summary()
    assert s["deadlines_set_aside"] == 0 and s["deadline_misses"] == 2


def test_a_summary_taken_inside_a_step_pairs_its_steps_with_their_busy_times():
    # A service reports a touch from inside its last step: the last 3 steps'
    # starts are kept, but only 2 of them have finished. Step k "takes"
    # (k + 1) ms; inside step 5 the last 3 are steps 3, 4 and 5 (running).
    clock = SimClock()
    loop = FixedRateLoop(0.01, clock)
    seen = {}

    ask = {"last": 3}

    def step(t, dt):
        k = loop.stats.count - 1
        if k == 5:
            seen.update(loop.stats.summary(last=ask["last"]))
        clock.advance((k + 1) * 1e-3)

    loop.run(step, 7)
    assert seen["steps"] == 3
    assert seen["busy_mean_us"] == pytest.approx(4500.0)       # steps 3 and 4, not 2
    assert loop.stats.summary(last=3)["busy_mean_us"] == pytest.approx(6000.0)   # 4, 5, 6
    # The same with only 3 steps kept and more asked for: the starts kept are
    # steps 3-5, so the busy times are 3 and 4 again (kept: 2, 3 and 4).
    seen.clear()
    ask["last"] = 10
    loop.run(step, 7, keep_last=3)
    assert seen["steps"] == 3 and seen["busy_mean_us"] == pytest.approx(4500.0)


def test_a_step_that_ends_exactly_on_the_next_deadline_misses_nothing():
    clock = SimClock()
    stats = FixedRateLoop(0.01, clock).run(lambda t, dt: clock.advance(0.01), 5)
    assert stats.summary()["deadline_misses"] == 0


def test_a_step_can_stop_the_loop():
    stats = FixedRateLoop(0.01, SimClock()).run(lambda t, dt: t < 0.045, 100)
    assert stats.summary()["steps"] == 6


@pytest.mark.parametrize("period", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_periods_are_refused(period):
    with pytest.raises(ControlError, match="period"):
        FixedRateLoop(period)


def test_the_simulated_clock_cannot_go_back():
    with pytest.raises(ControlError):
        SimClock().advance(-1.0)


def test_real_clock_structure():
    # Structure only: 30 steps happen in order, lateness is never negative.
    stats = FixedRateLoop(0.002, RealClock()).run(lambda t, dt: None, 30)
    s = stats.summary()
    assert s["steps"] == 30
    assert min(stats.lateness_s) >= 0.0
    assert all(b > a for a, b in zip(stats.starts_s, stats.starts_s[1:]))


def test_the_world_paused_clock_does_not_count_the_worlds_time():
    # Inequalities that hold whatever the machine's load: time.sleep lasts
    # at least what it is asked, and the clock moves by at most the real
    # time outside the world's spans.
    import time

    clock = WorldPausedClock()
    before_real, before = time.perf_counter(), clock.now()
    with clock.world():
        time.sleep(0.01)
    assert clock.paused_s >= 0.01
    assert clock.now() - before <= (time.perf_counter() - before_real) - 0.01
    with pytest.raises(RuntimeError):
        with clock.world():
            raise RuntimeError("the world failed")
    assert clock.paused_s >= 0.01                 # still counted, the span closed
    stats = FixedRateLoop(0.002, clock).run(lambda t, dt: None, 5)
    assert stats.summary()["steps"] == 5 and min(stats.lateness_s) >= 0.0


def test_the_loop_counts_the_garbage_collections_inside_it():
    # A full collection forced in a step is counted in generation 2 (with
    # its length); the loop leaves no callback behind.
    import gc
    before = len(gc.callbacks)
    stats = FixedRateLoop(0.01, SimClock()).run(
        lambda t, dt: gc.collect() if t == 0.0 else None, 3)
    s = stats.summary()
    assert s["gc_collections"][2] >= 1 and s["gc_max_us"] > 0.0
    assert len(gc.callbacks) == before


def test_runs_pooled_as_one_never_count_the_gap_between_them():
    # Two runs of 50 steps at 10 ms on one simulated clock, an hour apart,
    # the second with one overrun of 2.5 periods: the pooled summary has
    # 100 steps, both runs' misses, and no period spanning the two (each
    # run's times start at its own start: joined, they would make a
    # negative period): 98 periods, 97 of 10 ms and one of 30 ms.
    clock = SimClock()
    a = FixedRateLoop(0.01, clock).run(lambda t, dt: None, 50)
    clock.advance(3600.0)

    def slow_once(t, dt, n=[0]):
        n[0] += 1
        if n[0] == 10:
            clock.advance(0.025)

    b = FixedRateLoop(0.01, clock).run(slow_once, 50)
    pooled = combined_summary([a, b])
    assert pooled["steps"] == 100
    assert pooled["deadline_misses"] == a.missed_deadlines + b.missed_deadlines == 2
    assert pooled["period_max_us"] == pytest.approx(3e4)        # the overrun, not the hour
    expected = np.array([1e4] * 97 + [3e4])
    assert pooled["period_p99_us"] == pytest.approx(np.percentile(expected, 99))
    assert pooled["period_p50_us"] == pytest.approx(1e4)
    assert pooled["overruns"] == 1
    assert combined_summary([a]) == a.summary()
    with pytest.raises(ControlError, match="one period"):
        combined_summary([a, FixedRateLoop(0.02, SimClock()).run(lambda t, dt: None, 3)])
    with pytest.raises(ControlError):
        combined_summary([])


def test_the_clock_for_a_period_spins_a_fixed_share_of_it():
    assert RealClock.for_period(1e-3).spin_s == pytest.approx(SPIN_FRACTION * 1e-3)
    assert WorldPausedClock.for_period(5e-3).spin_s == pytest.approx(SPIN_FRACTION * 5e-3)
    assert isinstance(WorldPausedClock.for_period(5e-3), WorldPausedClock)
    with pytest.raises(ControlError, match="spin_s"):
        RealClock(float("nan"))
