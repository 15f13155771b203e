"""Issue 29's decision figures and the commitment schedule: what a touch's
live decision told the operator, the rates over sessions with their
intervals, and the first window the held-out touches support committing at."""

import numpy as np

from telethermal.bench.identify_live import (OUTCOMES, gaps_to_limit, live_counts,
                                             live_summary, outcome, pooled_accuracy)
from telethermal.ident.anytime import Decision
from telethermal.ident.base import commit_from_index
from telethermal.ident.label import Reason


def test_every_touch_has_exactly_one_outcome():
    d = [Decision("wood", 0.995, 0.1, Reason.CONFIDENT),
         Decision("plexiglass|rubber", 0.99, 0.08, Reason.CONFIDENT_GROUP, 0.08),
         Decision("unknown", 0.6, None, Reason.NOT_CONFIDENT),
         Decision("rubber", 0.99, 0.44, Reason.CONFIDENT, 0.06),
         Decision("aluminium|steel", 0.99, 0.1, Reason.CONFIDENT_GROUP, 0.1)]
    truth = ["wood", "rubber", "marble", "plexiglass", "wood"]
    assert [outcome(x, t) for x, t in zip(d, truth)] == \
        ["named", "pair", "unknown", "wrong", "wrong"]
    counts = live_counts(d, truth)
    assert counts["counts"] == {"named": 1, "pair": 1, "unknown": 1, "wrong": 2}
    assert counts["times_s"] == [0.1, 0.08, 0.06, 0.1]       # first commitments
    s = live_summary([counts, counts])
    assert s["touches"] == 10 and abs(sum(s[f"{o}_rate"] for o in OUTCOMES) - 1) < 1e-12
    lo, hi = s["wrong_rate_ci"]
    assert lo < s["wrong_rate"] == 0.4 < hi
    assert s["per_session"] == [counts["counts"]] * 2


def test_pooled_accuracy_counts_touches_not_means_of_means():
    a = {"accuracy_7": {"0.25": 0.5}, "n_touches": 10}
    b = {"accuracy_7": {"0.25": 1.0}, "n_touches": 30}
    acc, ci = pooled_accuracy([a, b], "accuracy_7")
    assert acc == {"0.25": 35 / 40} and ci["0.25"][0] < 35 / 40 < ci["0.25"][1]
    lim = {"accuracy_7": {"0.25": 1.0, "1": 1.0}}
    assert gaps_to_limit({"m": {"table1": {"accuracy_7": {"0.25": 0.96, "1": 1.0}}}}, lim) == \
        {"m": {"0.25": 4.0, "1": 0.0}}


def _posts(paths):
    """(n_windows, N, 3) from per-touch lists of per-window posteriors."""
    return np.stack([np.asarray(p, dtype=float) for p in paths], axis=1)


def test_commitment_starts_past_every_window_a_held_out_touch_was_committed_wrongly():
    sure_a, sure_b = [0.995, 0.003, 0.002], [0.003, 0.995, 0.002]
    vague = [0.4, 0.35, 0.25]
    pair_ab = [0.6, 0.395, 0.005]
    # Touch 0 (class a) is wrongly sure of b at window 1, right from window 3.
    t0 = [vague, sure_b, vague, sure_a, sure_a]
    t1 = [sure_a, sure_a, sure_a, sure_a, sure_a]
    assert commit_from_index(_posts([t0, t1]), np.array([0, 0]), 0.99) == 2
    # Clean from the first window: 0.
    assert commit_from_index(_posts([t1, t1]), np.array([0, 0]), 0.99) == 0
    # A pair without the truth is wrong; a pair holding it then refined to
    # the wrong member is wrong at the refinement's window.
    t2 = [pair_ab, pair_ab, sure_b, sure_a, sure_a]
    assert commit_from_index(_posts([t2]), np.array([2]), 0.99) == 5    # never the truth
    assert commit_from_index(_posts([t2]), np.array([0]), 0.99) == 3
    # Never clean: no window (the model then commits at none).
    t3 = [sure_b] * 5
    assert commit_from_index(_posts([t3]), np.array([0]), 0.99) == 5
