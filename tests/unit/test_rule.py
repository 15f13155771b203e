"""The anytime rule's one copy (ident/rule.py) and its three drivers:
decide (the bench, recordings), StreamingIdentifier (the slave, sample by
sample) and commit_from_index (the calibration's schedule) must agree on
every posterior path, not just the hand-made ones of test_decisions.py."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.ident.anytime import StreamingIdentifier, decide
from telethermal.ident.base import commit_from_index
from telethermal.ident.rule import AnytimeRule, Runs
from test_decisions import _Fixed  # the stand-in identifier, one copy

CLASSES = ("a", "b", "c", "d")


class _Model(_Fixed):
    """test_decisions' stand-in identifier (windows every 0.1 s at 10 Hz),
    with "unlike every class" and the calibration's schedule given per
    window, and a trained force range."""

    def __init__(self, path, unlike, commit_from, confirm, force_range=None):
        super().__init__(path, CLASSES[:np.shape(path)[1]])
        self.unlike, self.commit_from = list(unlike), commit_from
        self.threshold, self.confirm_windows = 0.9, confirm
        self.force_range_n_ = force_range

    def outside_classes(self, x, i):
        return np.array([self.unlike[i]])

    def may_commit(self, i):
        return i >= self.commit_from


def _row(draw, n_classes):
    # Rows that often pass 0.9 alone or as a pair, and often do not.
    kind = draw(st.sampled_from(["one", "pair", "flat"]))
    k = draw(st.integers(0, n_classes - 1))
    j = (k + 1 + draw(st.integers(0, n_classes - 2))) % n_classes
    p = np.full(n_classes, 1.0)
    p[k] += {"one": 200.0, "pair": 10.0, "flat": 0.5}[kind]
    p[j] += {"one": 0.0, "pair": 8.0, "flat": 0.5}[kind]
    return (p / p.sum()).tolist()


@st.composite
def touches(draw):
    n_classes = draw(st.integers(3, 4))
    n = draw(st.integers(1, 12))
    path = [_row(draw, n_classes) for _ in range(n)]
    unlike = draw(st.lists(st.booleans(), min_size=n, max_size=n))
    commit_from = draw(st.integers(0, 3))
    confirm = draw(st.integers(1, 3))
    forces = draw(st.lists(st.sampled_from([5.0, 10.0, 20.0]), min_size=n + 1, max_size=n + 1))
    return path, unlike, commit_from, confirm, forces


@settings(max_examples=300, deadline=None)
@given(touches())
def test_decide_and_the_slave_stream_agree_on_every_path(case):
    path, unlike, commit_from, confirm, forces = case
    model = _Model(path, unlike, commit_from, confirm,
                   force_range=[[8.0, 12.0]] * len(path))
    d = decide(model, np.zeros((len(path) + 1, 1)), 10.0, np.asarray(forces))
    stream = StreamingIdentifier(model, 10.0)
    out = [e for e in (stream.push([0.0], f) for f in forces) if e is not None]
    last = out[-1]
    # The stream's last estimate is the decision: committed to the same
    # label at the same window, or left "unknown" for the same reason.
    assert last.decided
    assert str(last.label) == str(d.label)
    assert last.reason == d.reason
    if d.time_s is not None and d.reason in ("confident", "confident group"):
        first = next(e for e in out if e.decided and e.label == d.label)
        assert abs(first.t_s - d.time_s) < 1e-9


@settings(max_examples=300, deadline=None)
@given(touches(), st.integers(0, 3))
def test_the_schedule_flags_exactly_the_paths_the_slave_tells_wrongly(case, truth):
    """commit_from_index on one touch returns 0 (commit from the first
    window) exactly when the slave's stream, allowed to commit from there,
    tells the operator nothing that excludes the truth (a pair without it,
    or another material), and decide ends where the stream ends."""
    path, _, _, confirm, _ = case
    truth = truth % len(path[0])
    model = _Model(path, [False] * len(path), 0, confirm)
    stream = StreamingIdentifier(model, 10.0)
    told = [e.label for e in (stream.push([0.0]) for _ in range(len(path) + 1))
            if e is not None and e.decided and e.reason in ("confident", "confident group")]
    post = np.asarray(path)[:, None, :]
    clean = commit_from_index(post, np.array([truth]), model.threshold, confirm) == 0
    assert clean == all(label.holds(CLASSES[truth]) for label in told)
    d = decide(model, np.zeros((len(path) + 1, 1)), 10.0)
    assert str(d.label) == (str(told[-1]) if told else "unknown")


def test_runs_need_the_same_class_in_a_row():
    runs = Runs(2)
    assert not runs.single(1, True) and not runs.single(2, True)   # another class restarts
    assert runs.single(2, True)
    runs.reset()
    assert not runs.single(2, True)


def test_a_confident_window_unlike_every_class_is_not_final():
    rule = AnytimeRule(0.9, 1)
    p = np.array([0.95, 0.03, 0.02])
    assert rule.step(0, p, unlike=lambda: True) is None and rule.unlike
    assert rule.step(1, p, unlike=lambda: False) == ("class", 0) and not rule.unlike


def test_force_outside_and_the_schedule_break_the_runs():
    rule = AnytimeRule(0.9, 2)
    p = np.array([0.95, 0.03, 0.02])
    assert rule.step(0, p) is None
    assert rule.step(1, p, force_outside=True) is None and rule.force_outside
    assert rule.step(2, p) is None                 # the run restarted
    assert rule.step(3, p, may_commit=False) is None
    assert rule.step(4, p) is None and rule.step(5, p) == ("class", 0)
